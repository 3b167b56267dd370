"""What a run reports: the progress line (one line per interval, simulated time with its unit, no time left before
a rate is measured, plain lines when the stream is not a terminal and one line redrawn with \\r when it is), and the
summary after a resume, which pairs this session's steps with this session's wall time and gives the run's totals
over all its sessions."""
from __future__ import annotations

import io

import pytest

from simtools import build_small_scene


def test_progress_is_one_plain_line_per_interval_off_a_terminal():
    from taichimyxo.runtime.status_line import Progress, duration
    assert [duration(s) for s in (3.61, 65, 3900, 6 * 3600)] == ["3.6 s", "1 min 05 s", "1 h 05 min", "6 h 00 min"]
    log = io.StringIO()
    bar = Progress("S3", total_steps=10_800_000, dt=0.002, start_step=0, stream=log, interval_s=3600)
    bar.update(0, force=True)
    for step in range(1, 100):
        bar.update(step * 1000)                                        # within the interval: nothing
    bar.close(1_950_000)
    lines = log.getvalue().split("\n")
    assert len(lines) == 3 and lines[-1] == "" and "\r" not in log.getvalue()
    assert lines[0] == "S3: 0.0 s of 6 h 00 min simulated (0 %), starting ..."     # no time left before a rate
    assert lines[1].startswith("S3: 1 h 05 min of 6 h 00 min simulated (18 %), ")
    assert lines[1].count("steps/s") == 1

    class Tty(io.StringIO):
        def isatty(self):
            return True
    tty = Tty()
    bar = Progress("S3", 100, 1.0, 0, stream=tty)
    bar.update(0, force=True)
    bar.close(100)
    assert tty.getvalue().startswith("\rS3: ") and tty.getvalue().count("\r") == 2 and tty.getvalue().endswith("\n")


def test_summary_after_resume_pairs_this_sessions_steps_with_its_wall_time(ti_cpu, tmp_path, capsys):
    from taichimyxo.interface.cli import _print_summary
    from taichimyxo.runtime.scene_run import run_scene
    sc = build_small_scene(4, run={"hours": 0.001, "dt_ms": 1.0})               # 3600 steps
    out = tmp_path / "out"
    first = run_scene(sc, out_dir=out, stop_after_steps=1000, progress=False)
    assert (first["steps"], first["steps_this_session"], first["sessions"]) == (1000, 1000, 1)
    rest = run_scene(sc, out_dir=out, resume=True, progress=False)
    assert rest["completed"] and rest["steps"] == 3600 and rest["steps_this_session"] == 2600
    assert rest["sessions"] == 2
    assert rest["wall_seconds_total"] == pytest.approx(first["wall_seconds"] + rest["wall_seconds"])
    assert rest["particle_steps_per_second"] == pytest.approx(2600 * sc.n_cells * sc.N / rest["wall_seconds"])
    _print_summary(rest, str(out))
    line = capsys.readouterr().out.splitlines()[0]
    assert f", 2600 steps (2.6 s simulated) in {rest['wall_seconds']:.1f} s wall" in line
    assert "; run total over 2 sessions: 3600 steps, 3.6 s simulated" in line


def test_a_session_killed_before_its_summary_still_counts_its_wall_time(ti_cpu, tmp_path):
    """A session killed outright writes no summary; the run resumes from its last checkpoint, which stores the run's
    wall-time totals up to that state, so the resumed run's totals (and the figures' cost estimates made from them)
    still count that session's time."""
    import numpy as np

    from taichimyxo.runtime.scene_run import run_scene
    sc = build_small_scene(4, run={"hours": 0.001, "dt_ms": 1.0})               # 3600 steps
    out = tmp_path / "out"
    first = run_scene(sc, out_dir=out, stop_after_steps=1000, progress=False)
    (ckpt,) = out.glob("*.ckpt.npz")
    stored = np.load(ckpt)
    assert int(stored["sessions"]) == 1
    assert float(stored["wall_seconds_total"]) == pytest.approx(first["wall_seconds"])
    assert float(np.sum(stored["wall_seconds_by_hour"])) > 0
    for summary in out.glob("*.json"):
        summary.unlink()                                                        # killed: no summary
    rest = run_scene(sc, out_dir=out, resume=True, progress=False)
    assert rest["completed"] and rest["sessions"] == 2
    assert rest["wall_seconds_total"] == pytest.approx(first["wall_seconds"] + rest["wall_seconds"])


def test_summary_splits_the_wall_time_by_simulated_hour_over_sessions(make_sim, tmp_path):
    """wall_seconds_by_hour: the wall time each simulated hour cost, added over the sessions of a resumed run."""
    from taichimyxo.io.writers import Summary
    from taichimyxo.runtime.run_loop import drive
    sim = make_sim(build_small_scene(4, run={"hours": 0.001, "dt_ms": 1.0}))
    sim.set_state(sim.state.positions(), sim.state.ke.to_numpy(), step=3_599_000)      # 1 s before hour 1
    path = tmp_path / "s.json"
    first = Summary(path)
    drive(sim, 2000, [first], catch_signals=False, chunk_steps=400, stop_after_steps=600)      # interrupted
    by_hour = first.summary["wall_seconds_by_hour"]
    assert len(by_hour) == 1 and by_hour[0] > 0                   # the chunks that began in hour 0
    rest = Summary(path, resumed=True)
    drive(sim, 900, [rest], catch_signals=False, chunk_steps=400)     # 3599.6 s -> 3600.5 s: chunks in both hours
    total = rest.summary["wall_seconds_by_hour"]
    assert len(total) == 2 and all(w > 0 for w in total) and total[0] > by_hour[0]
    assert sum(total) <= first.summary["wall_seconds"] + rest.summary["wall_seconds"] + 1e-3


def test_a_checkpoint_resumed_through_the_api_carries_its_sessions(make_sim, tmp_path):
    """A script that resumes a run itself (Simulation.load_checkpoint, then a Checkpoint writer with no `before`)
    still counts the earlier sessions: the totals come from the checkpoint the simulation was loaded from."""
    import numpy as np

    from taichimyxo.io.writers import Checkpoint, Summary, read_checkpoint
    from taichimyxo.runtime.run_loop import drive
    sc = build_small_scene(4, run={"hours": 0.001, "dt_ms": 1.0})
    sim = make_sim(sc)
    path = tmp_path / "run.ckpt.npz"
    first = Summary(tmp_path / "first.json")
    drive(sim, 2000, [Checkpoint(path), first], catch_signals=False, chunk_steps=400, stop_after_steps=600)
    assert int(np.load(path)["sessions"]) == 1
    sim.load_checkpoint(read_checkpoint(path, sc))
    second = Summary(tmp_path / "second.json")
    drive(sim, 2000, [Checkpoint(path), second], catch_signals=False, chunk_steps=400, stop_after_steps=600)
    stored = np.load(path)
    assert int(stored["sessions"]) == 2 and second.summary["sessions"] == 2
    assert float(stored["wall_seconds_total"]) == pytest.approx(
        first.summary["wall_seconds"] + second.summary["wall_seconds"])
    assert second.summary["wall_seconds_total"] == pytest.approx(float(stored["wall_seconds_total"]))
