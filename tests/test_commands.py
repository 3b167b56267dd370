"""Small commands of the command line: `--version`, `scene --show` (prints the resolved scene as TOML, with the
cell count it resolves to, and runs nothing), `keys` in aligned columns, and `videos --only` accepting every listed
scene and refusing an unknown one in one line that lists the available scenes."""
from __future__ import annotations

import tomllib

import pytest

from simtools import cli
from taichimyxo.io.scene import Scene, SceneError, available_scenes


def test_version():
    from taichimyxo import __version__
    p = cli("--version")
    assert p.returncode == 0 and p.stdout.strip() == f"taichimyxo {__version__}"


def test_show_prints_the_resolved_scene_and_runs_nothing(tmp_path):
    out = tmp_path / "never"
    p = cli("scene", "S3", "--preview", "--show", "--out", out, "--set", "cell.k_a_N_m=1e-16")
    assert p.returncode == 0, p.stderr
    assert not out.exists() and "[Taichi]" not in p.stdout
    shown = Scene.from_dict(tomllib.loads(p.stdout))
    assert shown.raw == Scene.load("S3", {"cell": {"k_a_N_m": 1e-16}}, preview=True).raw
    assert "cells = 0" in p.stdout and f"resolves to {shown.n_cells} cells" in p.stdout      # the count, not 0


def test_keys_prints_aligned_columns():
    from taichimyxo.io.scene import SCHEMA
    p = cli("keys")
    lines = p.stdout.splitlines()
    assert len(lines) == 1 + sum(len(v) for v in SCHEMA.values())
    default_col = lines[0].index("default")
    meaning_col = lines[0].index("meaning")
    for ln in lines[1:]:
        assert ln[default_col - 1] == " " and ln[default_col] != " ", ln
        assert ln[meaning_col - 2:meaning_col] == "  " and ln[meaning_col] != " ", ln


def test_videos_only_accepts_every_listed_scene(tmp_path, monkeypatch):
    from taichimyxo.io import videos
    calls = []
    monkeypatch.setattr(videos.subprocess, "call", lambda cmd: calls.append(cmd) or 0)
    names = [n for n in available_scenes() if not n.startswith("S") or "Fig" in n or n == "S3"]
    assert "S2FigA" in names
    assert videos.regenerate(preview=True, only=",".join(names), out_dir=str(tmp_path)) == 0
    assert [c[c.index("scene") + 1] for c in calls] == names
    with pytest.raises(SceneError, match="unknown scene S99; available: S1, S2, S2FigA"):
        videos.regenerate(only="S99", out_dir=str(tmp_path))
