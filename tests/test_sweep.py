"""Ensembles and parameter sweeps from one file (taichimyxo.sweep), the local executor and `videos --jobs`.

- A sweep file expands into grid points x seeds with readable names, short keys and self-contained run folders;
  scale keeps the density; sweeps/stiffness.toml is exactly the S2 Fig / S3 Fig scenes at half scale.
- Bad files (unknown key, empty list, a value out of range at one point, a missing executor) are refused in one line
  naming the key and the point, exit 2, before anything is written.
- Outcomes come from the analysis's last quarter; the table and a plot per swept key from the run folders.
- Real runs (slow): 2 points x 1 seed with --jobs 2 give run folders, the CSV and the plot; a second sweep of the
  same file runs nothing; a point that breaks an invariant fails alone, and an interrupted point resumes
  with --resume.
All real runs share one small configuration (S1 on 20 x 20 µm, 3.6 simulated s), so its kernels compile once."""
from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import pytest

from taichimyxo.interface.cli import main
from taichimyxo.io.scene import Scene

REPO = Path(__file__).resolve().parent.parent

# the one configuration the real runs use: S1 (20 cells at the paper's density) on 20 x 20 µm, frames every 0.6 s
SMALL = """
scene = "S1"
box_um = [20, 20]
hours = 0.001
{extra}
[set]
output.frame_interval_min = 0.01
[grid]
{grid}
"""


def sweep_file(tmp_path, grid: str, extra: str = "", name: str = "s.toml") -> Path:
    f = tmp_path / name
    f.write_text(SMALL.format(grid=grid, extra=extra))
    return f


def error_line(capsys, rc) -> str:
    out = capsys.readouterr()
    assert rc == 2, (rc, out.err)
    lines = [ln for ln in out.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("taichimyxo: error: "), out.err
    return lines[0]


# ------------------------------------------------------------------------------------------------ the file
def test_grid_times_seeds_gives_named_keyed_points(tmp_path):
    from taichimyxo.sweep import load_sweep
    base = tmp_path / "base.toml"
    base.write_text("[population]\ncells = 40\n[domain]\nwidth_um = 40.0\nheight_um = 20.0\n")
    f = tmp_path / "grid.toml"
    f.write_text('scene = "base.toml"\nseeds = [3, 5]\nhours = 0.5\nscale = 0.5\n'
                 '[grid]\ncell.k_a_N_m = [1e-17, 1e-15]\n"guiding.kind" = ["none", "active"]\n'
                 '[set]\noutput.frame_interval_min = 2\n[outputs]\nmovie = true\n')
    sw = load_sweep(f)
    pts = sw.points()
    assert len(pts) == 2 * 2 * 2 and sw.swept_keys == ["cell.k_a_N_m", "guiding.kind"]
    p = pts[1]
    assert p.name == "cell.k_a_N_m=1e-17_guiding.kind=none_seed=5"
    assert p.overrides == {"cell.k_a_N_m": 1e-17, "guiding.kind": "none"} and p.seed == 5
    sc = p.scene
    assert (sc.box, sc.n_cells, sc.hours, sc.seed, sc.movie) == ((20.0, 10.0), 10, 0.5, 5, True)  # cells with area
    assert sc.raw["output"]["frame_interval_min"] == 2 and sc.name == p.name
    assert len({q.key for q in pts}) == len(pts) and len(p.key) == 10
    assert p.run_dir("out") == Path("out") / "runs" / f"{p.name}-{p.key}"
    assert load_sweep(f).points()[1].key == p.key                          # the same file, the same folders
    # the folder's scene.toml is the point's scene: loading it back gives the same key
    from taichimyxo.sweep.rundir import prepare
    from taichimyxo.sweep.spec import scene_key
    d = prepare(p, tmp_path / "out", sw)
    assert scene_key(Scene.load(str(d / "scene.toml"))) == p.key
    assert json.loads((d / "point.json").read_text())["overrides"] == p.overrides


def test_stiffness_sweep_is_the_s2_and_s3_fig_series_at_half_scale():
    from taichimyxo.sweep import load_sweep
    pts = load_sweep(REPO / "sweeps" / "stiffness.toml").points()
    assert len(pts) == 4 * 2 * 3 and sorted({p.seed for p in pts}) == [1, 2, 3]
    assert sorted({p.overrides["scene"] for p in pts}) == [f"S{f}Fig{x}" for f in (2, 3) for x in "ABCD"]
    for p in pts:
        ref = Scene.load(p.overrides["scene"], {"domain": {"width_um": 100.0, "height_um": 100.0},
                                                "run": {"seed": p.seed}, "output": {"movie": False}})
        assert ref.hours == 6.0
        assert p.scene.fingerprint() == ref.fingerprint(), p.name               # each run is the scene itself
        assert p.scene.n_cells == 500                                          # the paper's density on 100 x 100


def test_every_shipped_sweep_file_loads_and_its_points_are_valid_scenes():
    """A sweep file is read only when someone runs it, often hours later: each must load, and each point must be a
    validated scene with the seeds and duration the file names."""
    from taichimyxo.sweep import load_sweep
    files = sorted((REPO / "sweeps").rglob("*.toml"))
    assert len(files) >= 10
    for f in files:
        sw = load_sweep(f)
        pts = sw.points()
        assert pts, f.name
        for p in pts:
            assert p.scene.n_cells > 0 and p.scene.hours > 0, (f.name, p.name)


def test_a_grid_of_scenes_runs_each_scene_with_its_own_values(tmp_path, capsys):
    """[grid] scene sweeps base scenes: Fig 2's runs are S1-S4 themselves at the figure's scale, S1, S3 and S4 at
    their own 4 ms step and S2 at 3 ms, so each run is the scene (the same fingerprint) a video can be rendered from."""
    from taichimyxo.sweep import load_sweep
    f = tmp_path / "fig2.toml"
    f.write_text((REPO / "sweeps" / "figures" / "Fig2.toml").read_text().replace("seeds = 1", "seeds = 1\nscale = 0.5"))
    pts = load_sweep(f).points()
    assert [p.name for p in pts] == [f"scene=S{i}_seed=1" for i in range(1, 5)]
    for i, p in enumerate(pts, 1):
        ref = Scene.load(f"S{i}", {"domain": {"width_um": 100.0, "height_um": 100.0}})
        assert p.scene.fingerprint() == ref.fingerprint(), p.name
    assert [p.scene.dt for p in pts] == [0.004, 0.003, 0.004, 0.004]
    bad = tmp_path / "bad.toml"
    bad.write_text('hours = 0.001\n[grid]\nscene = ["S1", "S99"]\n')
    line = error_line(capsys, main(["sweep", str(bad), "--out", str(tmp_path / "o")]))
    assert "scene = 'S99'" in line and not (tmp_path / "o").exists()
    bad.write_text('scene = "S1"\nhours = 0.001\n[grid]\nscene = ["S1", "S3"]\n')
    assert "scene and [grid] scene both given" in error_line(capsys, main(["sweep", str(bad)]))
    line = error_line(capsys, main(["sweep", str(f), "--runs", "scene=S9*", "--out", str(tmp_path / "o")]))
    assert "sweep --runs 'scene=S9*': matches none of the runs (scene=S1_seed=1, " in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("grid,extra,says", [
    ("cell.k_a_nm = [1e-17]", "", "[grid] cell.k_a_nm: unknown key"),
    ("cell.k_a_N_m = []", "", "[grid] cell.k_a_N_m = []: an empty list gives no points"),
    ("cell.k_a_N_m = [1e-17, -1e-16]", "", "point cell.k_a_N_m=-1e-16_seed=1: cell.k_a_N_m = -1e-16: must be "
                                           "positive"),
    ("run.dt_ms = [1, 100]", "", "point run.dt_ms=100_seed=1: run.dt_ms = 100 exceeds the stability limit"),
    ("cell.k_a_N_m = 1e-17", "", "[grid] cell.k_a_N_m = 1e-17: expected a list of values"),
    ("run.seed = [1, 2]", "", "[grid] run.seed: give the seeds with `seeds = N`"),
    ("guiding.kind = [\"none\"]", "seeds = 0", "seeds = 0: give a count of at least 1"),
    ("guiding.kind = [\"none\"]", "colour = 1", "unknown key 'colour'"),
])
def test_bad_sweep_files_are_refused_in_one_line_before_anything_runs(tmp_path, capsys, grid, extra, says):
    f = sweep_file(tmp_path, grid, extra)
    out = tmp_path / "out"
    line = error_line(capsys, main(["sweep", str(f), "--out", str(out)]))
    assert says in line and str(f) in line, line
    assert not out.exists()


def test_a_missing_executor_is_one_line(tmp_path, capsys, monkeypatch):
    from taichimyxo.sweep import orchestrator as driver
    monkeypatch.setitem(driver.EXECUTORS, "slurm", "taichimyxo.sweep.no_such_executor")
    f = sweep_file(tmp_path, "guiding.kind = [\"none\"]")
    line = error_line(capsys, main(["sweep", str(f), "--executor", "slurm", "--out", str(tmp_path / "o")]))
    assert "--executor slurm: taichimyxo.sweep.no_such_executor is not part of this installation" in line
    assert not (tmp_path / "o").exists()


def test_dry_run_lists_points_and_folders_and_writes_nothing(tmp_path, capsys):
    f = sweep_file(tmp_path, "cell.k_a_N_m = [1e-17, 1e-16]", "seeds = 2")
    assert main(["sweep", str(f), "--dry-run", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("s: 4 runs (2 grid points of cell.k_a_N_m x 2 seeds), 3.6 s simulated each")
    assert len(out) == 5 and all(ln.split()[0] == "new" for ln in out[1:])
    assert "cell.k_a_N_m=1e-16_seed=2" in out[4] and str(tmp_path / "o" / "runs") in out[4]
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------------------------------------ collection
def _analysis(n_frames=8, v_b=4.0):
    """An analysis summary as taichimyxo.analysis writes it: frames every minute, aggregates in the last 4."""
    t = list(map(float, range(n_frames)))
    ts = dict(time_min=t, n_aggregates=[0, 0, 0, 0, 1, 1, 2, 2], fraction_in_aggregates=[0, 0, 0, 0, .1, .1, .3, .5],
              speed_p95_um_per_min=[None, 4, 4, 4, 8, 8, 8, 12], free_cell_speed_um_per_min=[None] + [4.0] * 7)
    tracks = [{"series": dict(time_min=[4, 5, 6, 7], n_cells=[10, 12, 14, 20], radius_um=[2, 2, 3, 5],
                              edge_speed_um_per_min=[8, 8, 8, 16])},
              {"series": dict(time_min=[6, 7], n_cells=[6, 10], radius_um=[1, 3], edge_speed_um_per_min=[8, 8])}]
    return {"timeseries": ts, "tracks": tracks, "meta": {"v_b_um_per_min": v_b}}


def test_outcomes_are_means_over_the_last_quarter_of_frames():
    from taichimyxo.sweep import outcomes
    oc = outcomes(_analysis())
    # last quarter of 8 frames: t = 6, 7
    assert oc["from_min"] == 6.0 and oc["frames"] == 2
    assert oc["n_aggregates"] == 2 and oc["fraction_in_aggregates"] == pytest.approx(0.4)
    assert oc["aggregate_cells"] == pytest.approx((14 + 20 + 6 + 10) / 4)
    assert oc["aggregate_radius_um"] == pytest.approx((3 + 5 + 1 + 3) / 4)
    assert oc["edge_speed_vb"] == pytest.approx((8 + 16 + 8 + 8) / 4 / 4)
    assert oc["speed_p95_vb"] == pytest.approx(10 / 4) and oc["free_cell_speed_vb"] == pytest.approx(1.0)
    empty = _analysis()
    empty["tracks"] = []
    assert outcomes(empty)["aggregate_cells"] is None and outcomes(empty)["edge_speed_vb"] is None


def test_collect_writes_a_row_per_run_and_a_plot_per_swept_key(tmp_path):
    from taichimyxo.sweep import collect, load_sweep
    from taichimyxo.sweep.rundir import prepare, write_json_atomic
    f = sweep_file(tmp_path, "cell.k_a_N_m = [1e-18, 1e-17, 1e-15]\nguiding.kind = [\"none\", \"active\"]",
                   "seeds = 2")
    sw = load_sweep(f)
    pts = sw.points()
    root = tmp_path / "o"
    for i, p in enumerate(pts[:-1]):             # the last point has not run
        d = prepare(p, root, sw)
        size = 10.0 * (p.overrides["guiding.kind"] == "active") * (1 + p.seed)
        write_json_atomic(d / "result.json", {"status": "completed" if i else "failed", "simulated_seconds": 3.6,
                                              "wall_seconds": 1.5, "error": None if i else "stopped at step 9: x",
                                              "outcomes": {"aggregate_cells": size, "n_aggregates": 1.0}})
    res = collect(sw, root)
    with open(res["csv"]) as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 12 and [r["status"] for r in rows].count("completed") == 10
    assert rows[0]["status"] == "failed" and rows[0]["error"] == "stopped at step 9: x"
    assert rows[-1]["status"] == "not run" and rows[-1]["aggregate_cells"] == ""
    assert set(rows[0]) >= {"cell.k_a_N_m", "guiding.kind", "seed", "simulated_s", "wall_s", "n_aggregates",
                            "aggregate_cells", "aggregate_radius_um", "fraction_in_aggregates", "edge_speed_vb",
                            "speed_p95_vb"}
    assert rows[3]["guiding.kind"] == "active" and float(rows[3]["aggregate_cells"]) == 30.0      # seed 2
    assert [Path(p).name for p in res["plots"]] == ["sweep.cell.k_a_N_m.png", "sweep.guiding.kind.png"]
    assert all(Path(p).stat().st_size > 10_000 for p in res["plots"])


def test_progress_counts_runs_and_estimates_the_time_left():
    import io

    from taichimyxo.sweep.progress import SweepProgress
    s = io.StringIO()
    pr = SweepProgress("sw", total=5, skipped=1, jobs=2, stream=s)
    assert "time left: after the first run" in pr.line()
    pr.started("a")
    pr.started("b")
    pr.running["a"] -= 100.0                       # a started 100 s ago
    pr.finished("a", {"status": "completed", "name": "a"})
    pr.finished("b", {"status": "failed", "name": "b", "error": "boom"})
    assert pr.line().startswith("sw: 2 of 5 done (1 before), 0 running, 1 failed, 2 waiting")
    assert pr.eta_seconds() == pytest.approx(100.0, rel=0.05)       # 2 waiting x 100 s on 2 jobs
    assert "sw: failed b: boom" in s.getvalue()


# ------------------------------------------------------------------------------------------------ videos --jobs
def test_videos_in_parallel_go_through_the_executor_and_s8_waits_for_s3s_trajectory(tmp_path, monkeypatch):
    from taichimyxo.io import videos
    from taichimyxo.sweep import orchestrator as driver
    waves = []

    class Fake:
        @staticmethod
        def execute(run_dirs, jobs, options, progress):
            waves.append(([Path(d).name for d in run_dirs], jobs))
            return {d: {"status": "completed", "name": Path(d).name, "run_dir": d} for d in run_dirs}

    monkeypatch.setattr(driver, "executor_module", lambda name: Fake)
    # S8 is S3's run coloured by strain: the second of the two (in the order given) renders the first's trajectory
    assert videos.regenerate(preview=True, only="S3,S8,S1", out_dir=str(tmp_path), jobs=2) == 0
    assert waves == [(["S3-preview", "S1-preview"], 2), (["S8-preview"], 2)]
    point = json.loads((tmp_path / ".jobs" / "S8-preview" / "point.json").read_text())
    assert point == {"name": "S8-preview", "out": "../..", "arch": "cpu", "reuse": True, "analysis": None}
    assert Scene.load(str(tmp_path / ".jobs" / "S8-preview" / "scene.toml")).color == "strain"


@pytest.mark.skipif(not Path("/proc/self/autogroup").exists(), reason="no session scheduling groups (autogroup)")
def test_a_niced_sweep_starts_its_runs_at_its_own_niceness():
    """Runs start in sessions of their own; where Linux schedules each session as a group (autogroup) that group
    is at nice 0, and `nice -n 19 python -m taichimyxo sweep ...` would not lower the runs' priority. The executor
    gives each run's group the sweep's niceness."""
    import subprocess
    import sys
    code = ("import os, subprocess; from pathlib import Path; from taichimyxo.sweep.local import keep_priority\n"
            "mine = os.nice(7)\n"
            "p = subprocess.Popen(['sleep', '30'], start_new_session=True)\n"
            "keep_priority(p.pid)\n"
            "print(mine, Path(f'/proc/{p.pid}/autogroup').read_text().split()[-1]); p.kill()\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    mine, group = out.stdout.split()
    # 7 above whatever niceness the suite runs at (capped at 19 by the kernel): the sweep's own, not 0
    assert group == mine and int(mine) == min(19, os.nice(0) + 7)


def test_local_executor_keeps_jobs_runs_going(tmp_path, monkeypatch):
    """--jobs N: N worker processes run at once (never more), the next starts as soon as one ends. Workers are
    stand-ins that end after a fixed number of polls, so this is about the executor's order, not about clocks (the
    real-run test below runs real workers)."""
    import subprocess

    from taichimyxo.sweep import local

    running, most, launched = [], [0], []

    class Worker:
        def __init__(self, cmd, **kw):
            self.run_dir, self.polls, self.pid = cmd[3], 0, 0
            running.append(self)
            launched.append(self.run_dir)
            most[0] = max(most[0], len(running))

        def poll(self):
            self.polls += 1
            if self.polls < 3:
                return None
            if self in running:
                running.remove(self)
            return 0

        def wait(self):
            return self.poll()

    class Quiet:
        def started(self, d): pass
        def finished(self, d, r): pass
        def note(self, t): pass
        def tick(self): pass

    monkeypatch.setattr(subprocess, "Popen", Worker)
    monkeypatch.setattr(local.time, "sleep", lambda s: None)
    dirs = []
    for i in range(5):
        (tmp_path / f"r{i}").mkdir()
        dirs.append(str(tmp_path / f"r{i}"))
    res = local.execute(dirs, jobs=2, options={}, progress=Quiet())
    assert launched == dirs and set(res) == set(dirs)
    assert most[0] == 2                                   # two at once, never three


# ------------------------------------------------------------------------------------------------ real runs
def _csv(root):
    with open(root / "sweep.csv") as fh:
        return {r["name"]: r for r in csv.DictReader(fh)}


@pytest.mark.slow
def test_local_sweep_runs_points_in_parallel_and_a_rerun_skips_them(tmp_path, capsys):
    f = sweep_file(tmp_path, "run.dt_ms = [1, 2]")
    root = tmp_path / "o"
    assert main(["sweep", str(f), "--jobs", "2", "--out", str(root), "--runs", "run.dt_ms=2_*"]) == 0
    out = capsys.readouterr()                                  # --runs: part of the sweep now, the rest later
    assert "s: 1 completed, 0 done before, 0 failed" in out.out and "s: 1 of 1 done" in out.err
    assert main(["sweep", str(f), "--jobs", "2", "--out", str(root)]) == 0
    out = capsys.readouterr()
    assert "s: 1 completed, 1 done before, 0 failed" in out.out and "s: 2 of 2 done" in out.err
    runs = sorted((root / "runs").iterdir())
    assert [d.name.rsplit("-", 1)[0] for d in runs] == ["run.dt_ms=1_seed=1", "run.dt_ms=2_seed=1"]
    for d in runs:
        name = d.name.rsplit("-", 1)[0]
        for f_ in ("scene.toml", "point.json", f"{name}.gsd", f"{name}.json", f"{name}.analysis.json", "run.log"):
            assert (d / f_).is_file(), (d, f_)
        assert not (d / f"{name}.mp4").exists()
        r = json.loads((d / "result.json").read_text())
        assert r["status"] == "completed" and r["simulated_seconds"] == pytest.approx(3.6)
        assert r["cells"] == 20 and r["outcomes"]["free_cell_speed_vb"] > 0.5
    rows = _csv(root)
    assert {r["status"] for r in rows.values()} == {"completed"} and rows["run.dt_ms=2_seed=1"]["steps"] == "1800"
    assert float(rows["run.dt_ms=1_seed=1"]["speed_p95_vb"]) > 0.5
    assert (root / "sweep.run.dt_ms.png").stat().st_size > 10_000
    before = {d.name: (d / "result.json").stat().st_mtime_ns for d in runs}
    assert main(["sweep", str(f), "--jobs", "2", "--out", str(root)]) == 0
    assert "s: 0 completed, 2 done before, 0 failed" in capsys.readouterr().out
    assert {d.name: (d / "result.json").stat().st_mtime_ns for d in runs} == before


@pytest.mark.slow
def test_a_run_another_process_is_running_is_left_to_it(tmp_path, capsys):
    """Running the same sweep again while its first command still runs a point (a rerun to "resume", a requeued
    job) never runs that folder twice at once: the folder is locked by the process running it; the second command
    lists it as running, leaves it, and refuses --overwrite; once the lock is gone the run goes on."""
    from taichimyxo.sweep.rundir import hold, state
    from taichimyxo.sweep.runner import run_point
    f = sweep_file(tmp_path, "run.dt_ms = [1, 2]")
    root = tmp_path / "o"
    assert main(["sweep", str(f), "--out", str(root), "--runs", "run.dt_ms=1_*"]) == 0
    capsys.readouterr()
    busy = next(d for d in (root / "runs").iterdir() if d.name.startswith("run.dt_ms=2_"))
    lock = hold(busy)                                          # as the first command's worker holds it
    assert lock is not None and state(busy) == "running"
    assert run_point(str(busy))["status"] == "running elsewhere"
    assert main(["sweep", str(f), "--out", str(root), "--dry-run"]) == 0
    assert "running     run.dt_ms=2_seed=1" in capsys.readouterr().out
    assert main(["sweep", str(f), "--out", str(root)]) == 0
    assert "s: 0 completed, 1 done before, 0 failed, 1 running in another process" in capsys.readouterr().out
    assert "running now in another process (run.dt_ms=2_seed=1); --overwrite only once" in error_line(
        capsys, main(["sweep", str(f), "--out", str(root), "--overwrite"]))
    assert not (busy / "result.json").exists()
    lock.close()                                               # the first command ended
    assert state(busy) == "new" and main(["sweep", str(f), "--out", str(root)]) == 0
    assert "s: 1 completed, 1 done before, 0 failed" in capsys.readouterr().out


def test_a_failing_point_fails_alone_and_an_interrupted_one_resumes(tmp_path, capsys):
    """run.dt_ms = 100 (force: past the stability limit) breaks an invariant at its first frame; the dt = 1 point
    was interrupted after 1000 steps before the sweep and resumes from its checkpoint."""
    from taichimyxo.runtime.scene_run import run_scene
    from taichimyxo.sweep import plan
    from taichimyxo.sweep.rundir import prepare
    f = sweep_file(tmp_path, "run.dt_ms = [1, 100]", "force = true")
    root = tmp_path / "o"
    sw, pts, _ = plan(f, root)
    ok = pts[0]
    d = prepare(ok, root, sw)
    assert run_scene(ok.scene, out_dir=str(d), stop_after_steps=1000, progress=False)["status"] == "interrupted"
    assert main(["sweep", str(f), "--dry-run", "--out", str(root)]) == 0
    assert "interrupted run.dt_ms=1_seed=1" in capsys.readouterr().out
    assert main(["sweep", str(f), "--jobs", "2", "--out", str(root)]) == 2      # nothing continues unasked
    assert "--resume" in capsys.readouterr().err
    rc = main(["sweep", str(f), "--jobs", "2", "--out", str(root), "--resume"])
    out = capsys.readouterr()
    assert rc == 1, out
    assert "s: 1 completed, 0 done before, 1 failed" in out.out
    assert "failed run.dt_ms=100_seed=1: stopped at step" in out.out and "segment lengths" in out.out
    good = json.loads((d / "result.json").read_text())
    assert good["status"] == "completed" and good["sessions"] == 2 and good["steps"] == 3600
    rows = _csv(root)
    assert rows["run.dt_ms=1_seed=1"]["status"] == "completed" and rows["run.dt_ms=1_seed=1"]["n_aggregates"] != ""
    assert rows["run.dt_ms=100_seed=1"]["status"] == "failed" and "segment lengths" in rows["run.dt_ms=100_seed=1"][
        "error"]
    assert os.path.getsize(root / "sweep.csv") > 0


@pytest.mark.slow
def test_ctrl_c_keeps_finished_runs_and_checkpoints_the_running_ones(tmp_path):
    """Ctrl-C to the sweep while one run has finished and another is running: exit 130, the finished run's files and
    result intact, the running one closed with a checkpoint (the next sweep resumes it), the table says which."""
    import signal
    import subprocess
    import sys
    import time
    # the long run must outlast the wait for its progress line (written every 30 s to a log): 0.05 h finished in
    # 21.7 s once the step got faster, before the interrupt; 0.5 h runs minutes, and is interrupted at its line
    f = sweep_file(tmp_path, "run.hours = [0.001, 0.5]")
    f.write_text(f.read_text().replace("hours = 0.001\n", ""))
    root = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "taichimyxo", "sweep", str(f), "--jobs", "2", "--out", str(root)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    short = lambda: next((root / "runs").glob("run.hours=0.001_*"), None)      # noqa: E731
    long_ = lambda: next((root / "runs").glob("run.hours=0.5_*"), None)        # noqa: E731
    give_up = time.monotonic() + 900.0          # a safety net sized for a loaded machine (the short run is 3.6 s)
    while time.monotonic() < give_up:
        if short() and (short() / "result.json").is_file() and long_() and \
                "simulated (" in (long_() / "run.log").read_text(errors="replace"):
            break
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    # the running run stops after its current chunk, which may wait for the step kernel's compile: a wide net. (This
    # test used to fail when the suite itself ran as a background job of a script: the sweep inherited SIGINT
    # ignored and never stopped; the CLI now restores Ctrl-C, cli._catch_ctrl_c.)
    out, err = proc.communicate(timeout=900)
    assert proc.returncode == 130, (out, err)
    assert "1 completed, 0 done before, 0 failed, 1 interrupted or not started" in out, out
    assert json.loads((short() / "result.json").read_text())["status"] == "completed"
    name = long_().name.rsplit("-", 1)[0]
    assert (long_() / f"{name}.ckpt.npz").is_file() and not (long_() / "result.json").exists()
    assert json.loads((long_() / f"{name}.json").read_text())["status"] == "interrupted"
    rows = _csv(root)
    assert rows[short().name.rsplit("-", 1)[0]]["status"] == "completed" and rows[name]["status"] == "interrupted"


def test_a_key_added_later_leaves_earlier_runs_keys_at_its_neutral_value():
    """schema.ADDED_KEYS: at the value that reproduces the behaviour before it, a new key is not in the trajectory
    hash (a run, a sweep point or a checkpoint made before it keeps its key); at any other value it is."""
    from taichimyxo.io.schema import ADDED_KEYS, SCHEMA
    from taichimyxo.sweep.spec import scene_key
    base = Scene.load("S15")
    for dotted, before in ADDED_KEYS.items():
        sec, key = dotted.split(".")
        assert key in SCHEMA[sec]
        assert key not in base.trajectory_values()[sec]
        other = next(v for v in SCHEMA[sec][key][2] if v != before)
        changed = Scene.load("S15", {sec: {key: other}})
        assert changed.trajectory_values()[sec][key] == other
        assert scene_key(changed) != scene_key(base) and changed.fingerprint() != base.fingerprint()
    stated: dict = {}
    for dotted, before in ADDED_KEYS.items():
        sec, key = dotted.split(".")
        stated.setdefault(sec, {})[key] = before
    assert scene_key(Scene.load("S15", stated)) == scene_key(base)         # stated at the neutral value: the same


def test_grids_are_a_union_of_products_and_a_shared_point_runs_once(tmp_path, capsys):
    """[[grid]] tables (sweeps/decisions.toml): each a product, the file's points their union; a point that resolves
    to an earlier grid's scene (the default reading of each decision) is listed once, under its first name; sweep.csv
    gives every run its resolved value of the keys its own grid does not sweep."""
    from taichimyxo.sweep import load_sweep
    from taichimyxo.sweep.collect import rows
    f = tmp_path / "union.toml"
    f.write_text('seeds = 2\nhours = 0.1\nbox_um = [20, 20]\n'
                 '[[grid]]\nscene = ["S3"]\ncell.drag_ratio_normal = [0.5, 1.0]\nguiding.self = [true, false]\n'
                 '[[grid]]\nscene = ["S3", "S4"]\nguiding.pull_on = ["head_particle", "head_segment"]\n')
    sw = load_sweep(f)
    pts = sw.points()
    names = [p.name for p in pts]
    # 4 x 2 seeds, then S3's head_particle points are the matrix's (0.5, true): 2 new S3 and 4 S4 points x 2 seeds
    assert len(pts) == 8 + 2 + 4 and len({p.key for p in pts}) == len(pts)
    assert "scene=S3_guiding.pull_on=head_particle_seed=1" not in names
    assert "scene=S3_cell.drag_ratio_normal=0.5_guiding.self=true_seed=1" in names
    assert "scene=S4_guiding.pull_on=head_particle_seed=2" in names
    assert sw.swept_keys == ["scene", "cell.drag_ratio_normal", "guiding.self", "guiding.pull_on"]
    row = next(r for r in rows(pts, tmp_path, sw.swept_keys)
               if r["name"] == "scene=S4_guiding.pull_on=head_segment_seed=1")
    assert (row["cell.drag_ratio_normal"], row["guiding.self"], row["guiding.pull_on"]) == (0.5, True, "head_segment")
    # within one grid a duplicate is still refused; grids must all name their scenes or none
    f.write_text('seeds = 1\n[[grid]]\nscene = ["S3"]\n[[grid]]\ncell.k_a_N_m = [1e-17]\n')
    assert main(["sweep", str(f), "--dry-run"]) == 2
    assert "some grids name their scenes" in capsys.readouterr().err
