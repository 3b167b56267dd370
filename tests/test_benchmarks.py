"""The benchmark scripts of the clone (benchmarks/): they are not a command of the installed tool; each writes into
benchmarks-results/ in the current directory unless --out names a folder, and the stability sweep writes the limits
it measured there too, never into the package's stability_limits.json; accuracy_outcomes compares the seeds of
earlier CSVs (--rows) and of sweep folders as one ensemble, a run listed twice counting once."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


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

    from taichimyxo.interface.cli import _build_parser
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
    package_limits = REPO / "taichimyxo" / "physics" / "stability_limits.json"
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


def test_accuracy_outcomes_compares_within_each_group(tmp_path):
    """--group KEY judges each value of KEY (a scene, a stiffness) against its own reference: a setting that agrees
    with its own scene's 2 ms runs is not compared with another scene's; an outcome a run was not measured by (older
    rows without cluster_cells) is left unjudged rather than failed."""
    mod = _benchmark("accuracy_outcomes")
    head = ("setting,seed,simulated_h,wall_s,steps,wall_s_per_sim_h,n_aggregates,aggregate_cells,"
            "fraction_in_aggregates,edge_speed_vb,speed_p95_vb")

    def row(scene, dt, seed, n):
        setting = '"{""run.dt_ms"": %s, ""scene"": ""%s""}"' % (dt, scene)
        return f"{setting},{seed},1.0,100.0,1800000,100.0,{n},14,0.5,1.6,1.9"
    rows = tmp_path / "rows.csv"
    rows.write_text("\n".join([head] + [row("S1", 2, s, n) for s, n in ((1, 0.1), (2, 0.3))]
                              + [row("S1", 4, s, n) for s, n in ((1, 0.2), (2, 0.2))]
                              + [row("S3", 2, s, n) for s, n in ((1, 18), (2, 22))]
                              + [row("S3", 4, s, n) for s, n in ((1, 19), (2, 21))]) + "\n")
    out = tmp_path / "out"
    assert mod.main(["--rows", str(rows), "--group", "scene", "--out", str(out)]) == 0
    md = (out / "accuracy_outcomes.md").read_text()
    assert md.count("Reference:") == 2
    assert md.count("agrees with the reference on every outcome") == 2          # each within its own scene's range
    assert "cluster_cells" not in md
    assert mod.main(["--rows", str(rows), "--out", str(out)]) == 0              # one reference: S1 2 ms for all
    assert "outside the reference's seed range on n_aggregates" in (out / "accuracy_outcomes.md").read_text()


def test_accuracy_outcomes_leaves_an_outcome_measured_in_few_seeds_unjudged(tmp_path):
    """Non-guided runs form rotating aggregates in one seed of six: the edge speed of aggregates that hardly exist
    has a 'range' of one value and is not judged (whether aggregates form is, by n_aggregates), while an outcome
    every seed measures still fails when the setting lies outside the range."""
    mod = _benchmark("accuracy_outcomes")
    head = "setting,seed,simulated_h,wall_s,steps,wall_s_per_sim_h,n_aggregates,edge_speed_vb,speed_p95_vb"

    def row(dt, seed, n, edge, p95):
        return f'"{{""run.dt_ms"": {dt}}}",{seed},1.0,100.0,1800000,100.0,{n},{edge},{p95}'
    rows = tmp_path / "rows.csv"
    ref = [row(2, s, 0.1 if s == 1 else 0, 1.02 if s == 1 else "", 1.05 + 0.01 * s) for s in range(1, 7)]
    big = [row(4, s, 0.1 if s < 3 else 0, 1.1 if s < 3 else "", 1.2) for s in range(1, 7)]
    rows.write_text("\n".join([head] + ref + big) + "\n")
    out = tmp_path / "out"
    assert mod.main(["--rows", str(rows), "--out", str(out)]) == 0
    cmp = {c["outcome"]: c for c in mod.compare(mod.read_rows(rows), '{"run.dt_ms": 2}') if '4' in c["setting"]}
    assert cmp["edge_speed_vb"]["agrees"] is None and cmp["edge_speed_vb"]["rare"]
    assert cmp["n_aggregates"]["agrees"] is True and cmp["speed_p95_vb"]["agrees"] is False
    md = (out / "accuracy_outcomes.md").read_text()
    assert "outside the reference's seed range on speed_p95_vb (not judged, measured in at most half the seeds: " \
           "edge_speed_vb)" in md


def test_the_suite_lists_every_benchmark_of_the_folder_and_refuses_an_unknown_one(capsys):
    """benchmarks/suite.py is the one entry point: every script in benchmarks/ is listed (or named as a part that
    is not a benchmark), and an unknown name is one line with exit status 2."""
    suite = _benchmark("suite")
    scripts = {p.stem for p in (REPO / "benchmarks").iterdir() if p.suffix in (".py", ".sh")}
    unlisted = scripts - suite.NOT_BENCHMARKS - set(suite.BENCHMARKS)
    assert not unlisted, unlisted
    assert suite.main([]) == 0
    out = capsys.readouterr().out
    assert all(f"  {n} " in out for n in suite.present())
    assert suite.main(["no_such_benchmark"]) == 2
    assert "unknown benchmark 'no_such_benchmark'" in capsys.readouterr().err


def test_accuracy_cost_reads_each_step_verdict_from_an_outcome_check(tmp_path):
    """The verdicts of benchmarks/accuracy_cost.py are accuracy_outcomes' comparison of an outcome check's runs: the
    smallest explicit step is the reference, a step whose seed mean leaves the reference's seed range on an outcome
    differs, one within it on every outcome agrees, and a setting with other keys (a controller) is no point."""
    import csv
    cost = _benchmark("accuracy_cost")
    edge = {'{"run.dt_ms": 2}': [1.5, 1.6, 1.7], '{"run.dt_ms": 3}': [1.55, 1.6, 1.65],
            '{"run.dt_ms": 5}': [2.0, 2.1, 2.2], '{"run.dt_ms": 8, "run.integrator": "imex-explicit"}': [1.6, 1.6, 1.6],
            '{"run.step_control": "error", "run.step_tolerance_um": 0.001}': [3.0, 3.0, 3.0]}
    path = tmp_path / "outcomes.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, ["setting", "seed", "steps", "wall_s_per_sim_h", "n_aggregates", "edge_speed_vb"])
        w.writeheader()
        for setting, values in edge.items():
            for seed, v in enumerate(values, 1):
                w.writerow(dict(setting=setting, seed=seed, steps=100, wall_s_per_sim_h=60.0, n_aggregates=5.0,
                                edge_speed_vb=v))
    v = cost.verdicts(path)
    assert v == {("explicit", 2.0): "reference", ("explicit", 3.0): "agrees", ("explicit", 5.0): "differs",
                 ("imex-explicit", 8.0): "agrees"}
    assert cost.verdicts(tmp_path / "missing.csv") == {}
    assert set(cost.verdicts(cost.OUTCOMES).values()) <= {"reference", "agrees", "differs"}


def test_aggregate_balance_refuses_a_missing_trajectory_by_name(tmp_path, capsys):
    """benchmarks/aggregate_balance.py: a trajectory that is not there is one line naming it and exit status 2,
    before any table is written."""
    mod = _benchmark("aggregate_balance")
    out = tmp_path / "table.md"
    assert mod.main([str(tmp_path / "no.gsd"), "--out", str(out)]) == 2
    assert "no trajectory" in capsys.readouterr().err and not out.exists()


def test_aggregate_balance_finds_a_rigid_disk_of_cells_along_circles_turning_rigidly(tmp_path):
    """End to end on a synthetic trajectory with a known answer: a disk of arcs turning rigidly (analysis/
    synthetic.py) is found, its cells lie along their circles (engines' torque that of cells along circles), it turns
    as the torque of its velocities says (rotation 1) and its edge keeps up with the rotation (edge profile 1)."""
    from taichimyxo.analysis.synthetic import write_synthetic
    mod = _benchmark("aggregate_balance")
    path = tmp_path / "disk.gsd"
    write_synthetic(str(path), scene={"guiding": {"kind": "adhesion"}}, box=(60.0, 60.0), n_frames=2,
                    disks=[dict(centre=(30.0, 30.0), radius=8.0, omega=0.6)])
    scene, P, n, rows = mod.run_rows(path, 0.0, 1)
    assert n == 2 and P["kind"] == "adhesion" and len(rows) == 2
    for r in rows:
        assert r["alignment_torque"] == pytest.approx(1.0, abs=0.02)
        assert r["rotation"] == pytest.approx(1.0, abs=0.02)
        assert r["edge_profile"] == pytest.approx(1.0, abs=0.03)
        assert r["against"] == 0.0 and abs(r["adhesion_outside"]) < 1e-9
    out = tmp_path / "table.md"
    assert mod.main([str(path), "--out", str(out), "--start-fraction", "0"]) == 0
    assert "| scene seed 1 (adhesion, ζ_n/ζ_t 0.5, 2 frames) | all | 7.7–7.7 | 2 |" in out.read_text()


def test_continue_state_refuses_a_length_that_is_not_positive(tmp_path, capsys):
    """benchmarks/continue_state.py: --minutes 0 is one line naming the option and exit status 2, before any state
    is loaded or folder made."""
    mod = _benchmark("continue_state")
    out = tmp_path / "run"
    assert mod.main(["--minutes", "0", "--out", str(out)]) == 2
    assert "--minutes" in capsys.readouterr().err and not out.exists()


def test_threads_times_one_thread_processes_at_once_and_refuses_a_count_below_one(tmp_path, monkeypatch, capsys):
    """benchmarks/threads.py: --concurrent starts as many one-thread workers at once as the largest count and labels
    each row with the processes it shared the machine with; --threads 0 is one line naming the option."""
    mod = _benchmark("threads")
    started = []

    class Worker:                       # a worker process as rows_at reads it: JSON rows on stdout
        def __init__(self, cmd, **kw):
            started.append(cmd)

        def communicate(self, timeout=None):
            row = {"state": "S3 6 h", "threads": int(started[-1][started[-1].index("--threads") + 1]),
                   "ms_per_step": 5.0, "particles": 16000}
            return json.dumps(row) + "\n", ""

    monkeypatch.setattr(mod.subprocess, "Popen", Worker)
    monkeypatch.setattr(sys, "argv", ["threads.py", "--threads", "1,2", "--repeats", "1", "--states", "S3 6 h",
                                      "--concurrent", "--out", str(tmp_path)])
    mod.main()
    assert len(started) == 4 and all("S3 6 h" in c for c in started)      # 1 thread, 2 threads, 2 x 1 thread
    table = (tmp_path / "threads.csv").read_text().splitlines()
    assert table[0].split(",")[:3] == ["state", "threads", "processes"]
    assert [line.split(",")[1:3] for line in table[1:]] == [["1", "1"], ["2", "1"], ["1", "2"]]
    monkeypatch.setattr(sys, "argv", ["threads.py", "--threads", "0", "--out", str(tmp_path / "no")])
    with pytest.raises(SystemExit) as e:
        mod.main()
    assert "--threads" in str(e.value) and not (tmp_path / "no").exists()


def test_machine_speed_times_each_core_alone_and_together_and_refuses_zero_bursts(tmp_path, capsys):
    """benchmarks/machine_speed.py: one row per core per burst, alone and (on a machine of several cores) together,
    each a positive rate; --bursts 0 is one line and exit status 2, before anything is compiled or written."""
    import os
    import shutil
    mod = _benchmark("machine_speed")
    assert mod.main(["--bursts", "0", "--out", str(tmp_path / "no")]) == 2
    assert "--bursts" in capsys.readouterr().err and not (tmp_path / "no").exists()
    if not (shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")):
        pytest.skip("no C compiler here")
    assert mod.main(["--bursts", "2", "--iterations", "100000", "--out", str(tmp_path)]) == 0
    rows = (tmp_path / "machine_speed.csv").read_text().splitlines()
    cores = len(os.sched_getaffinity(0))
    assert len(rows) - 1 == 2 * cores * (2 if cores > 1 else 1)
    assert all(float(r.split(",")[-1]) > 0 for r in rows[1:])


def test_pair_loop_c_gives_taichis_contact_forces_to_rounding_and_refuses_bad_chunks(tmp_path, capsys):
    """benchmarks/pair_loop_c.py: the C pair loop's pair_f equals Taichi's to rounding on a shipped state with real
    contacts (S3 1 h); a chunk size that is not a power of two is one line, before anything is built or written."""
    import shutil
    import subprocess
    mod = _benchmark("pair_loop_c")
    with pytest.raises(SystemExit) as e:
        mod.main(["--block-dims", "3", "--out", str(tmp_path / "no")])
    assert "--block-dims" in str(e.value) and not (tmp_path / "no").exists()
    if not shutil.which("gcc"):
        pytest.skip("no gcc here")
    p = subprocess.run([sys.executable, str(REPO / "benchmarks" / "pair_loop_c.py"), "--state", "S3 1 h", "--reps",
                        "1", "--out", str(tmp_path)], capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-2000:]
    info = json.loads(p.stdout.strip().splitlines()[-1])
    assert info["pairs_evaluated"] > 10000 and info["largest_force_pN"] > 0
    assert info["relative_difference"] < 1e-4
    assert (tmp_path / "pair_loop_c.csv").read_text().count("S3 1 h") == 1


def test_writers_cost_refuses_a_count_below_one_before_any_work(tmp_path, monkeypatch):
    """benchmarks/writers_cost.py: --steps 0 is one line naming the options, before Taichi starts or a file is
    written."""
    mod = _benchmark("writers_cost")
    monkeypatch.setattr(sys, "argv", ["writers_cost.py", "--state", "S3 6 h", "--steps", "0", "--out",
                                      str(tmp_path / "no")])
    with pytest.raises(SystemExit) as e:
        mod.main()
    assert "--steps" in str(e.value) and not (tmp_path / "no").exists()
