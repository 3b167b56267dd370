"""Where the scene files are, and finding one by name or path."""
from __future__ import annotations

import os
import re
from pathlib import Path

from .schema import SceneError


def scenes_dir() -> Path:
    """Where the scene files are: inside the package in an installed wheel (pyproject.toml maps scenes/ to
    taichimyxo/scenes), at the top of the clone otherwise (also for an editable install)."""
    here = Path(__file__).resolve().parent
    for d in (here / "scenes", here.parent / "scenes"):
        if d.is_dir() and any(d.glob("*.toml")):
            return d
    return here / "scenes"


SCENES_DIR = scenes_dir()



def available_scenes() -> list[str]:
    if not SCENES_DIR.is_dir():
        return []
    return sorted((p.stem for p in SCENES_DIR.glob("*.toml")), key=scene_sort_key)


def scene_sort_key(name: str):
    m = re.match(r"S(\d+)(.*)", name)
    return (0, int(m.group(1)), m.group(2)) if m else (1, 0, name)


def resolve_path(name_or_path: str) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".toml" or os.sep in name_or_path:
        if not p.is_file():
            raise SceneError(f"scene file {name_or_path} not found")
        return p
    cand = SCENES_DIR / f"{name_or_path}.toml"
    if not cand.is_file():
        raise SceneError(f"unknown scene {name_or_path!r}; available: {', '.join(available_scenes())}")
    return cand
