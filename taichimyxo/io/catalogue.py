"""Where the scene files are, and finding one by name or path."""
from __future__ import annotations

import os
import re
from pathlib import Path

from .schema import SceneError, did_you_mean


def scenes_dir() -> Path:
    """Where the scene files are: inside the package in an installed wheel (pyproject.toml maps scenes/ to
    taichimyxo/scenes), at the top of the clone otherwise (also for an editable install)."""
    here = Path(__file__).resolve().parents[1]        # the package
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
        raise SceneError(f"unknown scene {name_or_path!r}{did_you_mean(name_or_path, available_scenes())}; available: "
                         f"{', '.join(available_scenes())}")
    return cand


def sweeps_dir() -> Path:
    """Where the sweep files are: inside the package in a wheel (pyproject.toml maps sweeps/ to taichimyxo/sweeps),
    at the top of the clone otherwise."""
    here = Path(__file__).resolve().parents[1]        # the package
    for d in (here / "sweeps", here.parent / "sweeps"):
        if d.is_dir() and any(d.glob("*.toml")):
            return d
    return here / "sweeps"


def available_sweeps() -> list[str]:
    d = sweeps_dir()
    return sorted(p.stem for p in d.glob("*.toml")) if d.is_dir() else []


def resolve_sweep(name_or_path) -> Path:
    """A sweep file by path, or by name among the shipped ones (`sweep example`); a path that exists wins."""
    p = Path(name_or_path)
    if p.is_file() or p.suffix == ".toml" or os.sep in str(name_or_path):
        return p
    cand = sweeps_dir() / f"{name_or_path}.toml"
    if cand.is_file():
        return cand
    raise SceneError(f"unknown sweep {str(name_or_path)!r}{did_you_mean(str(name_or_path), available_sweeps())}; "
                     f"shipped: {', '.join(available_sweeps())} (or give a .toml path)")
