"""Broken invariants: a run whose state breaks one (forced past the step limit with --force) stops in one line that
names the invariant, the step and the time, keeps its trajectory and checkpoint, records "failed" in its summary and
exits 3; and writers.check_frame names what broke (particle speed above the physical bound, segment lengths out of
range, non-finite positions)."""
from __future__ import annotations

import json

import numpy as np

from simtools import build_small_scene, cli, error_line

SMALL = ["--set", "domain.width_um=20", "--set", "domain.height_um=20"]


def test_forced_garbage_stops_naming_the_invariant_and_keeps_the_files(tmp_path):
    """The issue's `--set run.dt_ms=100 --force` exited 0, 'completed'."""
    out = tmp_path / "out"
    p = cli("scene", "S1", "--out", out, "--no-movie", "--quiet", *SMALL, "--set", "run.dt_ms=100", "--force",
            "--hours", "0.1")
    line = error_line(p, code=3)
    assert "S1 stopped at step " in line and "segment lengths" in line and "l0 outside 1 +- 0.5 l0" in line
    assert "(t = " in line and "checkpoint S1.ckpt.npz is written" in line
    d = json.loads((out / "S1.json").read_text())
    assert d["status"] == "failed" and not d["completed"] and "segment lengths" in d["invariant_broken"]
    assert f"stopped at step {d['steps']} " in line
    from taichimyxo.io.trajectory import count_frames, read_frames
    n = count_frames(str(out / "S1.gsd"))
    assert n >= 1 and all(np.isfinite(f.positions).all() for f in read_frames(str(out / "S1.gsd")))
    assert int(np.load(out / "S1.ckpt.npz")["step"]) == d["steps"]


def test_invariant_checks_name_what_broke():
    from taichimyxo.io.frame import Frame
    from taichimyxo.io.writers import check_frame
    sc = build_small_scene(1)
    pos = np.zeros((1, sc.N, 2))
    pos[0, :, 0] = np.arange(sc.N) * sc.rest_length
    fr = Frame(time_s=1.0, step=1, box=sc.box, width_um=sc.width, positions=pos, engine_direction=np.ones(1),
               particle_speed=np.full((1, sc.N), 4.0, np.float32))
    assert check_frame(fr, sc, 5.0, True) is None
    fr.particle_speed[0, 3] = 21.0                                     # 5.25 v_b
    assert "particle speed 5.25 v_b above the physical bound 5 v_b" in check_frame(fr, sc, 5.0, True)
    assert check_frame(fr, sc, 5.0, False) is None                     # speeds over a short window are not checked
    fr.positions[0, -1, 0] += 0.6 * sc.rest_length
    assert "segment lengths 1.00..1.60 l0" in check_frame(fr, sc, 5.0, True)
    fr.positions[0, 2, 1] = np.nan
    assert check_frame(fr, sc, 5.0, True) == "non-finite positions"


def test_particle_speed_bound_allows_the_largest_force_one_particle_can_take():
    """Bounds.for_scene: 5 v_b plus the largest force on one particle over its normal drag. Every scene has
    contacts, which can pass a whole cell's engine force onto one particle (21 v_b at the paper's values: dense
    non-guided S11 exceeds 5 v_b physically, the same at an eighth of the step); guiding pulls up to F_max^g
    (37 v_b); the cell centre bound stays 5 v_b."""
    import pytest

    from taichimyxo.physics.invariants import Bounds
    plain = build_small_scene(2)
    guided = build_small_scene(2, guiding={"kind": "active"})
    per_force = 1.0 / (plain.zeta_n * plain.v_b)
    assert Bounds.for_scene(plain).speed_factor == pytest.approx(5.0 + plain.engine_force * per_force)
    assert Bounds.for_scene(plain).speed_factor == pytest.approx(21.0, abs=0.5)
    assert Bounds.for_scene(guided).speed_factor == pytest.approx(5.0 + guided.guiding_f_max * per_force)
    assert Bounds.for_scene(guided).speed_factor == pytest.approx(37.0, abs=0.5)
    assert Bounds.for_scene(plain).centre_speed_factor == Bounds.for_scene(guided).centre_speed_factor == 5.0
