"""Rollback (taichimyxo/runtime/run_loop.py, docs/model.md "Numerics"): a chunk that breaks an invariant is redone from
the in-memory copy taken before it, with each scene step split into 2 (then 4, 8) steps; the scene's step resumes after.

Forced breaches: two overlapping cells pushed apart at 20 ms, beyond the explicit stability limit (the checker's own
case in test_stability.py), recover; at 400 ms even an eighth of the step breaks, so the run stops there with the
state of the last good copy. Reversal clocks count scene steps through a split, and a run with rollbacks stopped and
resumed from its checkpoint equals the uninterrupted one bit for bit.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np

from simtools import L0, cell
from taichimyxo.io.writers import InvariantCheck, check_positions, read_checkpoint, write_checkpoint
from taichimyxo.runtime.run_loop import MAX_SPLIT, drive

N = 8


def _jam(small_scene, make_sim, dt_ms, **sections):
    """The same overlapping pair as test_stability's checker case, at dt_ms."""
    sc = small_scene(2, run={"dt_ms": dt_ms}, **sections)
    pos = np.stack([cell((10, 10), 0.0, N, L0), cell((10, 10.15), math.degrees(0.1), N, L0)])
    return make_sim(sc, pos, np.array([1, -1], np.int8))


def test_a_breach_beyond_the_stability_limit_is_rolled_back_and_the_run_keeps_its_invariants(small_scene, make_sim):
    sim = _jam(small_scene, make_sim, 20.0)
    run = drive(sim, 300, [InvariantCheck()], chunk_steps=50, catch_signals=False)
    assert run.completed, run.broken
    assert sim.step_count == 300 and math.isclose(sim.time, 300 * 0.020)
    assert sim.rollbacks, "the 20 ms jam broke no invariant: the test forces nothing"
    for step, t, split in sim.rollbacks:
        assert step % 50 == 0 and math.isclose(t, step * 0.020) and split in (2, 4, MAX_SPLIT)
    assert check_positions(sim.positions(), sim.scene) is None


def test_without_rollback_the_same_breach_stops_the_run(small_scene, make_sim):
    sim = _jam(small_scene, make_sim, 20.0)
    run = drive(sim, 300, [InvariantCheck()], chunk_steps=50, catch_signals=False, rollback=False)
    assert run.status == "failed" and run.broken and not run.gave_up
    assert sim.rollbacks == []


def test_a_breach_at_every_split_gives_up_at_the_last_good_state(small_scene, make_sim):
    sim = _jam(small_scene, make_sim, 400.0)
    run = drive(sim, 40, [InvariantCheck()], chunk_steps=10, catch_signals=False)
    assert run.status == "failed" and run.gave_up
    assert "rolled back" in run.broken
    steps = {s for s, _, _ in sim.rollbacks}
    assert len(steps) == 1 and [k for _, _, k in sim.rollbacks] == [2, 4, MAX_SPLIT]
    assert sim.step_count == steps.pop()          # back at the copy taken before the chunk that broke
    assert check_positions(sim.positions(), sim.scene) is None


def test_a_split_scene_step_advances_the_reversal_clocks_by_one(small_scene, make_sim):
    sc = small_scene(2, box=(40.0, 40.0), reversals={"enabled": True, "period_min": 5.0})
    sim = make_sim(sc, np.stack([cell((10, 10), 0.0, N, L0), cell((10, 30), 90.0, N, L0)]), np.array([1, 1]))
    rev = sim.model.reversals
    clock0, period0 = rev.rev_clock.to_numpy(), rev.rev_period.to_numpy()
    n = 40
    assert np.all(clock0 + n < period0), "a reversal within the test's steps would hide the clock's count"
    sim.advance_split(n, 4)
    assert sim.step_count == n
    assert np.array_equal(rev.rev_clock.to_numpy(), clock0 + n)
    sim.advance(n)
    assert np.array_equal(rev.rev_clock.to_numpy(), clock0 + 2 * n)


def test_a_run_with_rollbacks_resumed_from_its_checkpoint_equals_the_uninterrupted_one(small_scene, make_sim,
                                                                                     tmp_path):
    sim = _jam(small_scene, make_sim, 20.0, reversals={"enabled": True, "period_min": 0.5})
    start = sim.get_checkpoint()
    drive(sim, 300, [InvariantCheck()], chunk_steps=50, catch_signals=False)
    whole, rollbacks = sim.get_checkpoint(), list(sim.rollbacks)
    assert rollbacks

    sim.load_checkpoint(start)
    assert sim.rollbacks == []
    drive(sim, 150, [InvariantCheck()], chunk_steps=50, catch_signals=False)
    write_checkpoint(sim, tmp_path / "c.npz")
    sim.load_checkpoint(start)                      # forget everything the first half did, then resume from disk
    sim.load_checkpoint(read_checkpoint(tmp_path / "c.npz", sim.scene))
    drive(sim, 150, [InvariantCheck()], chunk_steps=50, catch_signals=False)
    resumed = sim.get_checkpoint()
    assert sim.rollbacks == rollbacks
    for key, value in whole.items():
        assert np.array_equal(resumed[key], value), key


def test_cli_gives_up_with_exit_3_and_keeps_what_it_wrote(tmp_path):
    """Through the CLI: a jam at 20 times its stability limit (--force) breaks at every split; one line, exit 3, the
    trajectory and the checkpoint are kept and the summary lists the rollbacks."""
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "taichimyxo", "scene", "S11", "--force", "--quiet", "--no-movie", "--out", str(out),
           "--set", "run.dt_ms=400", "--set", "run.hours=0.02", "--set", "population.cells=60",
           "--set", "domain.width_um=30", "--set", "domain.height_um=30"]
    env = {**os.environ, "TAICHIMYXO_THREADS": "1"}
    p = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    assert p.returncode == 3, p.stderr[-2000:]
    assert "rolled back" in p.stderr
    summary = json.loads((out / "S11.json").read_text())
    assert summary["status"] == "failed" and summary["gave_up"]
    assert [r["split"] for r in summary["rollbacks"]][-3:] == [2, 4, MAX_SPLIT]
    assert (out / "S11.gsd").is_file() and (out / summary["files"]["checkpoint"]).is_file()
