"""A tool a biophysicist can trust: the edges of the input space, the install, the commands the README
shows, --resume and --preview, broken invariants and the progress line.

- Inputs the start cannot place, or that would not fit in memory, are refused in one line before placing starts;
  random placement is bounded and shows progress when the start is dense.
- A wheel's layout (package data) has the scenes and the stability limits.
- --version, `scene --show`, aligned `keys`, `videos --only` with any listed scene, benchmark output folders.
- `--resume` with fewer hours than done is refused and keeps the checkpoint; --preview leaves values set with --set
  alone and says what it scaled.
- A run whose state breaks an invariant stops in one line (invariant, step, time), keeps its files, exits 3.
- One progress line, simulated time with units, plain lines when stderr is not a terminal; after a resume the summary
  pairs this session's steps with this session's wall time."""
from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from simtools import build_small_scene
from taichimyxo.scene import Scene, SceneError, available_scenes, defaults

REPO = Path(__file__).resolve().parent.parent
SMALL = ["--set", "domain.width_um=20", "--set", "domain.height_um=20"]


def cli(*args, cwd=None):
    env = dict(os.environ, TAICHIMYXO_THREADS="2")
    return subprocess.run([sys.executable, "-m", "taichimyxo", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or REPO, env=env, timeout=600)


def error_line(p, code=2):
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == code, (p.returncode, p.stderr, p.stdout)
    assert "Traceback" not in p.stderr + p.stdout, p.stderr
    errors = [ln for ln in lines if ln.startswith("taichimyxo: error: ")]
    assert len(errors) == 1, p.stderr
    return errors[0]


def unvalidated_scene(box: float, cells: int, **over) -> Scene:
    """A Scene that skips Scene.validate (to hand the placement inputs validation would refuse)."""
    raw = defaults()
    raw["domain"].update(width_um=box, height_um=box)
    raw["population"]["cells"] = cells
    for sec, vals in over.items():
        raw[sec].update(vals)
    return Scene(raw=raw)


# ------------------------------------------------------------------------------------------------ placement
def _one_try_at_a_time(scene):
    """The random start as it was first written: one try per loop, 7 x 7 sub-segments per pair (the reference the
    batched placement must reproduce exactly)."""
    import math

    from taichimyxo import rng
    from taichimyxo.geometry import closest_points, min_image
    from taichimyxo.init import straight_cell
    n, N, l0, W = scene.n_cells, scene.N, scene.rest_length, scene.width
    box = np.array(scene.box)
    draws = rng.Stream(scene.seed, rng.STREAM_PLACE)
    pos, centres = np.zeros((n, N, 2)), np.zeros((n, 2))
    placed = 0
    while placed < n:
        r = draws.next(3)
        c, ang = r[:2] * box, r[2] * 2 * math.pi
        cell = straight_cell(c, ang, N, l0)
        if placed:
            shift = min_image(centres[:placed] - c, box) - (centres[:placed] - c)
            others = pos[:placed] + shift[:, None, :]
            d = closest_points(cell[:-1][None, :, None], cell[1:][None, :, None], others[:, None, :-1],
                               others[:, None, 1:])[4]
            if np.any(d < W):
                continue
        pos[placed], centres[placed] = cell, c
        placed += 1
    return pos


@pytest.mark.parametrize("box,cells,seed", [(30.0, 60, 2), (40.0, 200, 7), (12.0, 3, 5)])
def test_batched_random_placement_places_the_same_cells(box, cells, seed):
    from taichimyxo.init import random_start
    sc = build_small_scene(cells, box=(box, box), run={"seed": seed})
    assert np.array_equal(random_start(sc)[0], _one_try_at_a_time(sc))


def test_random_placement_gives_up_within_its_budget():
    """0.6 of the area cannot be placed at random: the placement stops after its budget of tries, not never."""
    from taichimyxo.init import PlacementError, random_start
    sc = unvalidated_scene(30.0, 216)                                   # area fraction 0.6
    seen = []
    with pytest.raises(PlacementError, match="gave up after 20800 tries"):
        random_start(sc, max_tries_per_cell=50, progress=lambda placed, n, tries: seen.append(tries))
    assert seen and seen[-1] <= 50 * 216 + 10_000


def test_random_start_above_what_it_places_is_refused_before_placing(tmp_path):
    """The issue's 490 cells in 50 x 50 µm (area fraction 0.49): one line at once, not a silent hang."""
    line = error_line(cli("scene", "S1", "--no-movie", "--out", tmp_path / "o", "--set", "domain.width_um=50",
                          "--set", "domain.height_um=50", "--set", "population.cells=490"))
    assert "population.cells = 490 covers 0.49" in line and "'random' start can place at most 0.40" in line
    assert not (tmp_path / "o").exists()


def test_preview_leaves_set_values_alone_and_says_what_it_scaled(tmp_path):
    """The issue's `--preview --set population.cells=7800`: the cells the user set are not scaled; the error says
    what --preview did scale, and from what."""
    line = error_line(cli("scene", "S1", "--preview", "--no-movie", "--out", tmp_path / "o",
                          "--set", "population.cells=7800"))
    assert "population.cells = 7800" in line
    assert "--preview scaled domain.width_um from 200 to 50, domain.height_um from 200 to 50" in line
    sc = Scene.load("S1", {"population": {"cells": 100}, "domain": {"width_um": 80.0}}, preview=True)
    assert (sc.n_cells, sc.box) == (100, (80.0, 50.0))
    assert set(sc.preview_scaled) >= {"domain.height_um", "run.hours"} and "domain.width_um" not in sc.preview_scaled


def test_dense_feasible_start_shows_placement_progress(tmp_path):
    """126 cells in 30 x 30 µm (area fraction 0.35): placed, with progress on stderr, and the run's progress is
    plain lines (stderr is a pipe here), simulated time with its unit."""
    out = tmp_path / "o"
    p = cli("scene", "S1", "--no-movie", "--out", out, "--set", "domain.width_um=30", "--set", "domain.height_um=30",
            "--set", "population.cells=126", "--hours", "0.0002")
    assert p.returncode == 0, p.stderr
    assert "taichimyxo: placing 126 cells at random (area fraction 0.35)" in p.stderr
    assert "taichimyxo: placed 126 of 126 cells" in p.stderr
    assert "\r" not in p.stderr
    progress = [ln for ln in p.stderr.splitlines() if ln.startswith("S1: ")]
    # a run this short ends within its first chunk, which compiles the kernels: no rate is measured, so no ETA
    assert progress and all(" simulated (" in ln and (ln.endswith(" left") or " ..." in ln) for ln in progress)
    assert not any(ln.endswith(" left") for ln in progress)
    assert progress[-1].startswith("S1: 0.7 s of 0.7 s simulated (100 %)")


# ------------------------------------------------------------------------------------------------ memory
def test_a_domain_beyond_memory_is_refused_in_one_line(tmp_path):
    """The issue's 10^6 µm domain (5 x 10^10 cells) died in numpy ('Unable to allocate 5.82 TiB')."""
    line = error_line(cli("scene", "S1", "--no-movie", "--out", tmp_path / "o", "--set", "domain.width_um=1e6",
                          "--set", "domain.height_um=1e6"))
    assert "50000000000 cells in 1e+06 x 1e+06 µm" in line
    assert "Taichi can index" in line or "need about" in line
    assert not (tmp_path / "o").exists()


def test_memory_estimate_names_the_parts_and_compares_with_what_is_available():
    from taichimyxo.resources import check_resources, estimate
    sc = build_small_scene(0, box=(2000.0, 2000.0), slime={"enabled": True})
    est = estimate(sc)
    assert est["total"] > est["fields"] > est["neighbour_list"] > 0 and est["slime_grid"] > 0
    with pytest.raises(SceneError, match=r"need about .* \(neighbour list .*, slime grid .*\); this machine has "
                                         r"1 GiB available"):
        check_resources(sc, available=1024 ** 3)
    assert check_resources(sc, available=10 * est["total"])["total"] == est["total"]


@pytest.mark.parametrize("over", [
    {},
    {"guiding": {"kind": "adhesion"}, "output": {"strain": True}},
    {"reversals": {"enabled": True, "suppression": True}, "guiding": {"kind": "active"}, "slime": {"enabled": True}},
    {"run": {"integrator": "imex", "precision": "f64"}, "guiding": {"kind": "passive"}},
    {"run": {"mass_pg": 1.0, "precision": "f32"}},
], ids=["plain", "adhesion-strain", "reversals-slime", "imex", "mass-f32"])
def test_field_estimate_matches_what_the_simulation_allocates(make_sim, over):
    from taichimyxo.resources import field_sizes
    sc = build_small_scene(4, **over)
    sim = make_sim(sc)
    allocated = sim.allocated_fields()
    estimated = {k: b for k, (_, b) in field_sizes(sc).items()}
    assert estimated == allocated


# ------------------------------------------------------------------------------------------------ install
def test_the_wheel_layout_has_the_scenes_and_the_limits(tmp_path):
    """Lay the package out as pyproject.toml tells setuptools to (package-dir, package-data) and run it from
    outside the clone: `list` shows every scene, and the step limits come from the shipped stability_limits.json."""
    conf = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    site = tmp_path / "site"
    for pkg in conf["packages"]:
        src = REPO / conf["package-dir"][pkg]
        dst = site / pkg.replace(".", "/")
        dst.mkdir(parents=True)
        patterns = ["*.py"] + conf.get("package-data", {}).get(pkg, [])
        for pat in patterns:
            for f in src.glob(pat):
                shutil.copy(f, dst / f.name)
    assert (site / "taichimyxo/stability_limits.json").is_file()
    env = dict(os.environ, PYTHONPATH=str(site))
    code = ("import taichimyxo, taichimyxo.scene as s, taichimyxo.stability as st; print(taichimyxo.__file__); "
            "print(s.SCENES_DIR); print(st._LIMITS_FILE.is_file())")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env,
                       timeout=600)
    assert p.returncode == 0, p.stderr
    file_, scenes_dir, limits = p.stdout.split()
    assert file_.startswith(str(site)) and scenes_dir == str(site / "taichimyxo" / "scenes") and limits == "True"
    p = subprocess.run([sys.executable, "-m", "taichimyxo", "list"], capture_output=True, text=True, cwd=tmp_path,
                       env=env, timeout=600)
    assert p.returncode == 0, p.stderr
    assert [ln.split()[0] for ln in p.stdout.splitlines()] == available_scenes()


# ------------------------------------------------------------------------------------------------ commands
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
    from taichimyxo.scene import SCHEMA
    p = cli("keys")
    lines = p.stdout.splitlines()
    assert len(lines) == 1 + sum(len(v) for v in SCHEMA.values())
    default_col = lines[0].index("default")
    meaning_col = lines[0].index("meaning")
    for ln in lines[1:]:
        assert ln[default_col - 1] == " " and ln[default_col] != " ", ln
        assert ln[meaning_col - 2:meaning_col] == "  " and ln[meaning_col] != " ", ln


def test_videos_only_accepts_every_listed_scene(tmp_path, monkeypatch):
    from taichimyxo import videos
    calls = []
    monkeypatch.setattr(videos.subprocess, "call", lambda cmd: calls.append(cmd) or 0)
    names = [n for n in available_scenes() if not n.startswith("S") or "Fig" in n or n == "S3"]
    assert "S2FigA" in names
    assert videos.regenerate(preview=True, only=",".join(names), out_dir=str(tmp_path)) == 0
    assert [c[c.index("scene") + 1] for c in calls] == names
    with pytest.raises(SceneError, match="unknown scene S99; available: S1, S2, S2FigA"):
        videos.regenerate(only="S99", out_dir=str(tmp_path))


def _benchmark(name: str):
    """A script of benchmarks/ as a module (they import their neighbour benchlib: benchmarks/ goes on the path)."""
    import importlib
    if str(REPO / "benchmarks") not in sys.path:
        sys.path.insert(0, str(REPO / "benchmarks"))
    return importlib.import_module(name)


def test_benchmarks_default_to_a_results_folder_in_the_current_directory(tmp_path, capsys):
    """Benchmarks are scripts of the clone (benchmarks/), not a command of the installed tool; each writes into
    benchmarks-results/ in the current directory unless --out names a folder, and the stability sweep writes the
    limits it measured there too, never into the package's stability_limits.json."""
    import inspect

    from taichimyxo.cli import _build_parser
    with pytest.raises(SystemExit):
        _build_parser().parse_args(["bench", "stability"])
    for name in ("throughput", "accuracy", "stability_sweep"):
        mod = _benchmark(name)
        assert mod.build_parser().parse_args([]).out == "benchmarks-results", name
        assert inspect.signature(mod.main).parameters["out_dir"].default == "benchmarks-results", name
    sweep = _benchmark("stability_sweep")
    assert "write_limits" not in inspect.signature(sweep.main).parameters
    with pytest.raises(SystemExit):
        sweep.build_parser().parse_args(["--write-limits"])
    package_limits = REPO / "taichimyxo" / "stability_limits.json"
    before = package_limits.read_bytes()
    path = sweep.write_limits(tmp_path, {"explicit": {"1e-17/0.01": 5.0}})
    assert path == tmp_path / "stability_limits.json" and package_limits.read_bytes() == before
    written = json.loads(path.read_text())
    assert written["explicit"]["1e-17/0.01"] == 5.0 and written["defaults"]["explicit"]["1e-17/0.01"] == 2.0


def test_accuracy_outcomes_compares_seeds_run_on_different_days_as_one_ensemble(tmp_path, capsys):
    """The outcome check reads the runs of an earlier accuracy_outcomes.csv (--rows) as well as sweep folders, so a
    reference extended by new seeds is compared as one ensemble; a run listed twice counts once."""
    mod = _benchmark("accuracy_outcomes")
    head = ("setting,seed,simulated_h,wall_s,steps,wall_s_per_sim_h,n_aggregates,aggregate_cells,"
            "fraction_in_aggregates,edge_speed_vb,speed_p95_vb")
    ref, big = '"{""run.dt_ms"": 2}"', '"{""run.dt_ms"": 4}"'

    def row(setting, seed, frac):
        return f"{setting},{seed},1.0,100.0,1800000,100.0,20,14,{frac},1.6,1.9"
    first = tmp_path / "first.csv"
    first.write_text("\n".join([head, row(ref, 1, 0.60), row(ref, 2, 0.58), row(big, 1, 0.50)]) + "\n")
    later = tmp_path / "later.csv"
    later.write_text("\n".join([head, row(ref, 3, 0.45), row(ref, 1, 0.99), row(big, 2, 0.52)]) + "\n")
    out = tmp_path / "out"
    assert mod.main(["--rows", str(first), "--rows", str(later), "--out", str(out)]) == 0
    cmp = {(c["setting"], c["outcome"]): c for c in mod.compare(mod.read_rows(out / "accuracy_outcomes.csv"),
                                                                 '{"run.dt_ms": 2}')}
    frac = cmp[('{"run.dt_ms": 2}', "fraction_in_aggregates")]
    assert frac["values"] == [0.60, 0.58, 0.45]            # seed 1 from the first file, once
    four = cmp[('{"run.dt_ms": 4}', "fraction_in_aggregates")]
    assert four["seeds"] == 2 and four["agrees"] is True    # mean 0.51 within the reference's 0.45-0.60
    assert "agrees with the reference on every outcome" in (out / "accuracy_outcomes.md").read_text()
    assert mod.main(["--rows", str(tmp_path / "missing.csv")]) == 2
    assert "no such file" in capsys.readouterr().out


# ------------------------------------------------------------------------------------------------ resume, invariants
def test_resume_with_fewer_hours_than_done_is_refused_and_keeps_the_checkpoint(ti_cpu, tmp_path):
    from taichimyxo.scene_run import run_scene
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
    from taichimyxo.trajectory import count_frames, read_frames
    n = count_frames(str(out / "S1.gsd"))
    assert n >= 1 and all(np.isfinite(f.positions).all() for f in read_frames(str(out / "S1.gsd")))
    assert int(np.load(out / "S1.ckpt.npz")["step"]) == d["steps"]


def test_invariant_checks_name_what_broke():
    from taichimyxo.frame import Frame
    from taichimyxo.writers import check_frame
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


# ------------------------------------------------------------------------------------------------ progress, summary
def test_progress_is_one_plain_line_per_interval_off_a_terminal():
    from taichimyxo.progress import Progress, duration
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
    from taichimyxo.cli import _print_summary
    from taichimyxo.scene_run import run_scene
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
