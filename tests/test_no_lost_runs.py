"""No command destroys a run's work without being told to.

Every way a run can end leaves its files in the output folder; running the same command again, without a flag, never
overwrites them: an unfinished run (a checkpoint, or a trajectory without a finished summary) is refused in one line
naming --resume and --overwrite, a run stopped by a broken invariant names --overwrite, a finished run of the same
scene is complete (exit 0, nothing changed) and one of other parameters is refused. What each ending leaves on disk:
finished (summary "completed"), Ctrl-C and SIGTERM and a Slurm time limit (the executor signals the run: checkpoint,
trajectory, summary "interrupted"), kill -9 (a trajectory, a checkpoint only if one was written on the clock),
invariant broken (checkpoint, trajectory, summary "failed"). The real signals are sent in
tests/test_interrupt.py::test_real_signal_closes_files_checkpoints_and_resumes_bit_for_bit; here each state is laid
out on disk and the command run against it (no simulation starts), and one real run goes through --resume,
"already complete" and --overwrite."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simtools import error_line
from taichimyxo.io.frame import Frame
from taichimyxo.io.scene import Scene
from taichimyxo.io.trajectory import TrajectoryWriter

REPO = Path(__file__).resolve().parent.parent
SETS = {"domain": {"width_um": 20.0, "height_um": 20.0}, "run": {"dt_ms": 2.0}}      # 600 steps: 1.2 s
ARGS = ["scene", "S1", "--no-movie", "--quiet", "--set", "domain.width_um=20", "--set", "domain.height_um=20",
        "--set", "run.dt_ms=2", "--hours", "0.001"]


def cli(*args, cwd=None):
    env = dict(os.environ, TAICHIMYXO_THREADS="2")
    return subprocess.run([sys.executable, "-m", "taichimyxo", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or REPO, env=env, timeout=900)


def scene() -> Scene:
    return Scene.load("S1", SETS).with_overrides({"run": {"hours": 0.001}})


def write_trajectory(path: Path, frames: int = 3) -> None:
    sc = scene()
    rng = np.random.default_rng(0)
    with TrajectoryWriter(str(path), {**sc.to_dict(), "_fingerprint": sc.fingerprint()}) as w:
        for i in range(frames):
            pos = rng.uniform(2, 18, (4, 1, 2)) + np.arange(sc.N)[None, :, None] * np.array([sc.rest_length, 0.0])
            w.append(Frame(time_s=0.6 * i, step=300 * i, box=sc.box, width_um=sc.width, positions=pos,
                           engine_direction=np.ones(4, np.int8), particle_speed=np.ones((4, sc.N), np.float32)))


def lay_out(out: Path, ending: str) -> dict:
    """The files `ending` leaves in `out` (taichimyxo.runtime.scene_run's outputs; the summary as writers.Summary writes
    it); returns their bytes."""
    sc = scene()
    out.mkdir(parents=True)
    write_trajectory(out / "S1.gsd")
    summary = {"scene": "S1", "fingerprint": sc.fingerprint(), "steps": 600, "simulated_seconds": 1.2}
    if ending == "finished":
        summary.update(status="completed", completed=True, steps=sc.steps, simulated_seconds=3.6)
    elif ending in ("ctrl-c", "sigterm", "slurm time limit"):
        summary.update(status="interrupted", completed=False)
    elif ending == "invariant broken":
        summary.update(status="failed", completed=False, invariant_broken="segment lengths 0.10..3.00 l0")
    if not ending.startswith("kill -9"):                   # a killed process writes no summary
        (out / "S1.json").write_text(json.dumps(summary))
    if ending not in ("finished", "kill -9 before a checkpoint"):
        np.savez(out / "S1.ckpt.npz", step=np.array(600), fingerprint=np.array(sc.fingerprint()))
    return {p.name: p.read_bytes() for p in out.iterdir()}


def unchanged(out: Path, before: dict) -> None:
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def one_error_line(p) -> str:
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 2, (p.returncode, p.stderr)
    assert len(lines) == 1 and lines[0].startswith("taichimyxo: error: "), p.stderr
    assert "[Taichi]" not in p.stdout, "a simulation started"
    return lines[0]


UNFINISHED = ["ctrl-c", "sigterm", "slurm time limit", "kill -9 before a checkpoint", "kill -9 after a checkpoint"]


@pytest.mark.parametrize("ending", UNFINISHED)
def test_an_unfinished_run_is_refused_naming_resume_and_overwrite(tmp_path, ending):
    out = tmp_path / "out"
    before = lay_out(out, ending)
    line = one_error_line(cli(*ARGS, "--out", out))
    assert "unfinished run of S1" in line and "--resume" in line and "--overwrite" in line, line
    assert "trajectory S1.gsd of 3 frames" in line, line
    if ending != "kill -9 before a checkpoint":
        assert "checkpoint S1.ckpt.npz at 1.2 s simulated" in line, line
    unchanged(out, before)


def test_killed_before_a_checkpoint_cannot_resume_and_says_to_overwrite(tmp_path):
    out = tmp_path / "out"
    before = lay_out(out, "kill -9 before a checkpoint")
    line = one_error_line(cli(*ARGS, "--out", out, "--resume"))
    assert "no checkpoint" in line and "--overwrite" in line, line
    unchanged(out, before)


def test_a_run_stopped_by_a_broken_invariant_is_refused_naming_overwrite(tmp_path):
    out = tmp_path / "out"
    before = lay_out(out, "invariant broken")
    line = one_error_line(cli(*ARGS, "--out", out))
    assert "broken invariant" in line and "segment lengths" in line and "--overwrite" in line, line
    unchanged(out, before)


@pytest.mark.parametrize("flags", [[], ["--resume"]], ids=["again", "resume"])
def test_a_finished_run_is_already_complete_and_nothing_changes(tmp_path, flags):
    out = tmp_path / "out"
    before = lay_out(out, "finished")
    p = cli(*ARGS, "--out", out, *flags)
    assert p.returncode == 0, p.stderr
    assert "S1: already complete in" in p.stdout and "--overwrite" in p.stdout, p.stdout
    assert "[Taichi]" not in p.stdout
    unchanged(out, before)


def test_a_finished_run_of_other_parameters_is_refused(tmp_path):
    out = tmp_path / "out"
    before = lay_out(out, "finished")
    line = one_error_line(cli(*ARGS, "--out", out, "--set", "guiding.kind=active"))
    assert "finished run of S1 with other parameters" in line and "--overwrite" in line, line
    unchanged(out, before)


def test_resume_and_overwrite_together_and_resume_of_nothing(tmp_path):
    out = tmp_path / "out"
    before = lay_out(out, "ctrl-c")
    assert "give one" in one_error_line(cli(*ARGS, "--out", out, "--resume", "--overwrite"))
    unchanged(out, before)
    nothing = tmp_path / "nothing"
    assert "no run of S1" in one_error_line(cli(*ARGS, "--out", nothing, "--resume"))
    assert not nothing.exists()                     # no empty folder left behind


def test_the_checks_read_what_each_ending_leaves():
    from taichimyxo.io.outdir import plan_run
    sc = scene()

    def plan(tmp, ending, **kw):
        out = Path(tmp) / ending.replace(" ", "_")
        lay_out(out, ending)
        return plan_run(sc, out, **kw)
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        assert plan(tmp, "finished") == "complete"
        for i, ending in enumerate(["ctrl-c", "sigterm", "slurm time limit", "kill -9 after a checkpoint",
                                    "invariant broken"]):
            assert plan(tmp + f"/r{i}", ending, resume=True) == "resume"
            assert plan(tmp + f"/o{i}", ending, overwrite=True) == "overwrite"
        assert plan_run(sc, Path(tmp) / "empty") == "new"


# ------------------------------------------------------------------------------------------------ sweeps
SWEEP = """
scene = "S1"
box_um = [20, 20]
hours = 0.001
[grid]
run.dt_ms = [1, 2]
"""


def test_a_sweep_with_unfinished_runs_is_refused_until_told(tmp_path, capsys):
    from taichimyxo.interface.cli import main
    from taichimyxo.sweep import plan
    from taichimyxo.sweep.orchestrator import check_earlier_runs
    from taichimyxo.sweep.rundir import prepare, state
    f = tmp_path / "s.toml"
    f.write_text(SWEEP)
    root = tmp_path / "o"
    sw, pts, _ = plan(f, root)
    d = prepare(pts[0], root, sw)
    write_trajectory(d / f"{pts[0].name}.gsd")            # killed before its first checkpoint
    assert state(d) == "interrupted"
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    assert main(["sweep", str(f), "--out", str(root)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("taichimyxo: error: ") and "1 unfinished run" in err and "--resume" in err and \
        "--overwrite" in err and "\n" not in err, err
    assert main(["sweep", str(f), "--out", str(root), "--resume", "--overwrite"]) == 2
    assert "give one" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before
    listing = [(p, p.run_dir(root), state(p.run_dir(root))) for p in pts]
    assert check_earlier_runs(listing, root, resume=True, overwrite=False) == listing
    assert [st for _, _, st in check_earlier_runs(listing, root, resume=False, overwrite=True)] == ["new", "new"]
    assert not d.exists()                                  # --overwrite: the run starts again from nothing


# ------------------------------------------------------------------------------------------------ a real run
@pytest.mark.slow
def test_interrupted_then_resumed_then_complete_then_overwritten(ti_cpu, tmp_path):
    from taichimyxo.runtime.scene_run import run_scene
    out = tmp_path / "out"
    sc = scene()
    part = run_scene(sc, out_dir=str(out), stop_after_steps=700, progress=False)
    assert part["status"] == "interrupted"
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    line = one_error_line(cli(*ARGS, "--out", out))
    assert "unfinished run" in line and "--resume" in line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    p = cli(*ARGS, "--out", out, "--resume")
    assert p.returncode == 0, p.stderr
    done = json.loads((out / "S1.json").read_text())
    assert done["completed"] and done["sessions"] == 2 and not (out / "S1.ckpt.npz").exists()
    assert done["scene_values"]["run"]["dt_ms"] == pytest.approx(done["dt_s"] * 1e3)    # the step used, not 0
    finished = {p.name: p.read_bytes() for p in out.iterdir()}
    for flags in ([], ["--resume"]):
        p = cli(*ARGS, "--out", out, *flags)
        assert p.returncode == 0 and "already complete" in p.stdout, p.stderr
        assert {p.name: p.read_bytes() for p in out.iterdir()} == finished
    p = cli(*ARGS, "--out", out, "--overwrite")
    assert p.returncode == 0, p.stderr
    again = json.loads((out / "S1.json").read_text())
    assert again["completed"] and again["sessions"] == 1 and again["steps"] == done["steps"]


# ------------------------------------------------------------------------------------------------ --resume
SMALL = ["--set", "domain.width_um=20", "--set", "domain.height_um=20"]


def test_resume_with_fewer_hours_than_done_is_refused_and_keeps_the_checkpoint(ti_cpu, tmp_path):
    from taichimyxo.runtime.scene_run import run_scene
    sc = Scene.load("S1", {"domain": {"width_um": 20.0, "height_um": 20.0}, "run": {"dt_ms": 1.0, "hours": 0.01},
                           "output": {"movie": False}})
    out = tmp_path / "out"
    part = run_scene(sc, out_dir=out, stop_after_steps=1500, progress=False)
    assert part["status"] == "interrupted"
    before = {f.name: f.read_bytes() for f in out.iterdir()}
    line = error_line(cli("scene", "S1", "--out", out, "--no-movie", "--resume", *SMALL, "--set", "run.dt_ms=1",
                          "--hours", "0.0002"))
    assert "has already simulated 1.5 s (1500 steps)" in line and "the checkpoint is kept" in line
    assert {f.name: f.read_bytes() for f in out.iterdir()} == before
