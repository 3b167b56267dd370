"""The paper's figures; the stiffness series; claims measured as the paper defines them; one rigidity measure;
'not measurable here'.

- `figures`: bad input (unknown figure, a scale that leaves too few cells, --no-run with runs missing) is one line,
  exit 2, nothing written; --dry-run counts runs, simulated hours and the estimated wall time and writes nothing.
- Composites from finished runs: synthetic trajectories in the run folders (--no-run, through the CLI), and one
  figure from tiny real runs through the sweep machinery (S1 on 20 x 20 µm, 3.6 simulated s: the configuration
  tests/test_sweep.py compiles).
- Rigidity: cells all at v_b on circles pass the vector R² of a rigid fit (0.89-0.97, omega R = 1.3 v_b) and fail
  the rigidity exponent; a rigid rotation passes it. Edge speed is the outermost ring's, also for an aggregate
  smaller than a cell.
- The stiffness statements: consistent, not consistent and 'not measurable here' on synthetic records."""
from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

from taichimyxo.analysis import find_aggregates, synthetic_frames, write_synthetic
from taichimyxo.figures.plan import plan_figure
from taichimyxo.figures.specs import FIGURES
from taichimyxo.interface.cli import main

V_B = 4.0
REPO = Path(__file__).resolve().parent.parent


def error_line(capsys, rc) -> str:
    out = capsys.readouterr()
    assert rc == 2, (rc, out.err)
    lines = [ln for ln in out.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("taichimyxo: error: "), out.err
    return lines[0]


# ------------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("argv, says", [
    (["Fig9"], "unknown figure 'Fig9'"),
    (["S6Fig", "--scale", "quarter"], "31 cells in a 25 x 25 µm box"),
    (["Fig3", "--scale", "quarter"], "90 cells"),
    (["Fig2", "--scale", "half", "--no-run"], "--no-run: 4 of 4 runs not finished"),
    (["Fig2", "--seeds", "0"], "--seeds 0"),
    (["Fig2", "--runs", "scene=S9*"], "--runs 'scene=S9*': matches none of the runs (scene=S1_seed=1, "),
    (["Fig2", "--runs", "scene=S1*", "--no-run"], "--runs and --no-run together"),
    (["Fig2", "--scale", "tiny"], "invalid choice"),
])
def test_bad_input_is_one_line_exit_2_nothing_written(tmp_path, capsys, argv, says):
    out = tmp_path / "figs"
    try:
        rc = main(["figures", *argv, "--out", str(out)])
    except SystemExit as e:              # argparse's own refusals exit from the parser
        rc = e.code
    line = error_line(capsys, rc)
    assert says in line
    assert not out.exists()


def test_dry_run_counts_runs_hours_and_wall_time(tmp_path, capsys):
    out = tmp_path / "figs"
    assert main(["figures", "Fig2", "S3Fig", "--scale", "half", "--jobs", "2", "--out", str(out), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "Fig2 (half, 100 x 100 µm, 500 cells): 4 runs x 1 seed, 24 simulated hours" in text
    assert "S3Fig (half, 100 x 100 µm, 500 cells): 12 runs x 3 seeds, 72 simulated hours" in text
    assert "total: 16 runs, 96 simulated hours; estimated wall time on this machine with 2 at a time" in text
    assert "A: start; B: S1; C: S2; D: S3; E: S4; F: S8" in text          # which scenes each figure comes from
    assert main(["figures", "S3Fig", "--scale", "half", "--out", str(out), "--dry-run", "--runs", "*FigA_*"]) == 0
    text = capsys.readouterr().out
    assert text.count("not chosen") == 9 and "total: 3 of 12 runs chosen, 72 simulated hours" in text
    assert not out.exists()


def test_dry_run_prices_what_is_left_of_an_interrupted_run(tmp_path, capsys):
    """An interrupted run is priced by the steps its checkpoint has still to go, and says how far it got."""
    import numpy as np
    out = tmp_path / "figs"
    runs = plan_figure(FIGURES["S6Fig"], "half", out)
    pt = runs.points[1]
    runs.run_dir(pt).mkdir(parents=True)
    np.savez(runs.run_dir(pt) / f"{pt.scene.name}.ckpt.npz", fingerprint=np.array(pt.scene.fingerprint()),
             step=np.array(pt.scene.steps // 4))
    assert runs.run_state(pt) == "interrupted" and runs.fraction_done(pt) == 0.25
    assert main(["figures", "S6Fig", "--scale", "half", "--out", str(out), "--dry-run"]) == 0
    lines = {ln.split()[1]: ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("  ")}
    new, part = lines[runs.points[0].name], lines[pt.name]
    assert "left (25% done)" in part and "left" not in new

    def minutes(line):                               # '~1 h 31 min', '~48 min 10 s'
        t = line.split("~")[1]
        h = re.search(r"(\d+) h", t)
        return (int(h.group(1)) * 60 if h else 0) + int(re.search(r"(\d+) min", t).group(1))
    assert abs(minutes(part) - 0.75 * minutes(new)) <= 1      # three quarters of the same run
    np.savez(runs.run_dir(pt) / f"{pt.scene.name}.ckpt.npz", fingerprint=np.array("other"), step=np.array(9))
    assert runs.fraction_done(pt) == 0.0             # a checkpoint of other parameters is not this run's progress


def test_dry_run_prices_a_run_on_more_threads_by_the_measured_speed_up(tmp_path, capsys):
    """--threads N divides each run's one-thread estimate by the benchmark's measured speed-up at the largest
    measured count <= N (the median over its states), and says so; a count never measured is priced as one thread."""
    from taichimyxo.figures.plan import thread_speedup
    table = tmp_path / "threads.csv"
    table.write_text("state,threads,ms_per_step,speedup_vs_first,rounds,particles\n"
                     "a,1,1.0,1.0,2,10\na,2,0.5,2.0,2,10\nb,2,0.6,1.6,2,10\nc,2,0.55,1.8,2,10\n"
                     "a,4,0.3,3.5,2,10\n")
    assert thread_speedup(1, table) == (1.0, 1)
    assert thread_speedup(2, table) == (1.8, 2) and thread_speedup(3, table) == (1.8, 2)
    assert thread_speedup(8, table) == (3.5, 4)
    assert thread_speedup(2, tmp_path / "absent.csv") == (1.0, 1)
    out = tmp_path / "figs"

    def run_minutes(threads):
        assert main(["figures", "S6Fig", "--scale", "half", "--out", str(out), "--dry-run", "--jobs", "1",
                     "--threads", str(threads)]) == 0
        text = capsys.readouterr().out
        t = re.search(r"with 1 at a time \((.*)\): ((?:\d+ h )?\d+ min)", text)
        h = re.search(r"(\d+) h", t.group(2))
        return t.group(1), (int(h.group(1)) * 60 if h else 0) + int(re.search(r"(\d+) min", t.group(2)).group(1))
    (each1, one), (each2, two) = run_minutes(1), run_minutes(2)
    speedup, n = thread_speedup(2)
    assert each1 == "one thread each" and each2.startswith("2 threads each")
    assert n == 2 and speedup > 1 and abs(two - one / speedup) <= 1
    assert not out.exists()


def test_every_figure_has_a_sweep_file_whose_points_match_its_panels(tmp_path):
    for fig in FIGURES.values():
        runs = plan_figure(fig, "half", tmp_path)
        assert fig.sweep_path.is_file()
        for panel in fig.panels:
            assert runs.first_seed_point(panel.match) is not None, (fig.name, panel.letter)
    assert len(FIGURES["Fig2"].panels) == 6 and len(FIGURES["S3Fig"].panels) == 4
    assert "Fig 3A" in FIGURES["S3Fig"].caption and "Fig 2A" in FIGURES["S3Fig"].caption     # the reading chosen


# ------------------------------------------------------------------------------------------------ composites
def _fake_finished_runs(runs, **synthetic):
    """Each run folder of `runs` as a finished run: a synthetic trajectory and result.json."""
    for p in runs.points:
        d = runs.run_dir(p)
        d.mkdir(parents=True, exist_ok=True)
        write_synthetic(str(runs.trajectory(p)), v_b=V_B, box=p.scene.box, n_frames=3, **synthetic)
        (d / "result.json").write_text(json.dumps({"status": "completed"}))


def test_no_run_composes_from_finished_runs(tmp_path, capsys):
    out = tmp_path / "figs"
    runs = plan_figure(FIGURES["Fig3"], "half", out)
    _fake_finished_runs(runs, gas=30, seed=1)
    assert main(["figures", "Fig3", "--scale", "half", "--no-run", "--out", str(out)]) == 0
    doc = json.loads((out / "Fig3.half.json").read_text())
    assert [p["letter"] for p in doc["panels"]] == ["A", "B", "C"] and all(p["drawn"] for p in doc["panels"])
    assert doc["panels"][0]["frame"] == "first" and doc["panels"][0]["time_s"] == 0
    assert "At half scale the box is 30 µm" in doc["caption"]
    assert "Shorter than the paper's run" in doc["caption"]                   # 2 simulated minutes, not 3 h
    assert (out / "Fig3.half.png").stat().st_size > 10000 and (out / "Fig3.half.pdf").is_file()


def test_records_compose_a_figure_whose_run_folders_are_gone(tmp_path, capsys):
    """Each finished run is kept as a small record; with the run folders gone (another machine, a wiped one) the
    figure is composed from the records the same way, and a run of the figure does not redo recorded runs."""
    import shutil
    out, records = tmp_path / "figs", tmp_path / "kept"
    runs = plan_figure(FIGURES["Fig3"], "half", out)
    _fake_finished_runs(runs, gas=30, seed=1)
    args = ["figures", "Fig3", "--scale", "half", "--out", str(out), "--records", str(records)]
    assert main([*args, "--no-run"]) == 0
    kept = sorted((records / "Fig3.half").glob("*.npz"))
    assert [k.stem for k in kept] == sorted(p.dir_name for p in runs.points)
    assert all(k.stat().st_size < 200_000 for k in kept)
    before = json.loads((out / "Fig3.half.json").read_text())
    shutil.rmtree(out / "Fig3" / "runs")
    (out / "Fig3.half.json").unlink()
    assert main([*args, "--no-run"]) == 0
    after = json.loads((out / "Fig3.half.json").read_text())
    assert [(p["drawn"], p["time_s"]) for p in after["panels"]] == [(p["drawn"], p["time_s"]) for p in before["panels"]]
    assert all(p["run"].startswith("record: Fig3.half/") and p["run"].endswith(".npz") for p in after["panels"])
    assert all(p["run"].startswith("Fig3/runs/") for p in before["panels"])     # no machine's paths
    runs.records = records
    assert runs.states() == ["recorded", "recorded"]
    assert main(args) == 0                               # nothing left to run: the records stand for the runs
    assert not (out / "Fig3" / "runs").exists()
    capsys.readouterr()


def test_a_run_two_figures_share_is_run_once(tmp_path, capsys):
    """Fig 2 D (S3, seed 1) is S3 Fig B's first seed and Fig 2 B (S1) S2 Fig B's: the same physics, seed, box and
    duration. Kept as a record by one figure, the run stands for the other's ("shared"); a dry run of two figures
    that share a run counts it once; a record of a shorter run stands for nothing."""
    from taichimyxo.figures.records import save_records
    out, records = tmp_path / "figs", tmp_path / "kept"
    s3fig = plan_figure(FIGURES["S3Fig"], "half", out, seeds=1)
    _fake_finished_runs(s3fig, gas=30, seed=1)

    def keep(hours):
        for pt in s3fig.points:
            s3fig.trajectory(pt).with_suffix(".json").write_text(json.dumps(
                {"completed": True, "fingerprint": pt.scene.fingerprint(), "scene_values": {"run": {"hours": hours}}}))
        shutil.rmtree(records, ignore_errors=True)
        assert len(save_records(s3fig, records)) == 4

    import shutil
    fig2 = plan_figure(FIGURES["Fig2"], "half", out)
    fig2.records = records
    keep(1.0)                                                   # a 1 h run is not Fig 2's 6 h
    assert "shared" not in fig2.states()
    keep(6.0)
    states = dict(zip((p.name for p in fig2.points), fig2.states()))
    assert states == {"scene=S1_seed=1": "new", "scene=S2_seed=1": "new", "scene=S3_seed=1": "shared",
                      "scene=S4_seed=1": "new"}
    assert fig2.record_file(fig2.points[2]).parent.name == "S3Fig.half"
    assert main(["figures", "Fig2", "S2Fig", "--scale", "half", "--seeds", "1", "--out", str(out), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "shared      scene=S2FigB_seed=1                6 h  the same run as Fig2 scene=S1_seed=1" in text
    assert text.count("shared") == 1


def test_a_stiffness_figure_with_runs_missing_measures_its_series_on_those_finished(tmp_path, capsys):
    """S3 Fig with its very rigid run still to come: not composed, but its stiffness series and the statements are
    written on the three finished runs, the very rigid statement 'not measurable here'."""
    out = tmp_path / "figs"
    runs = plan_figure(FIGURES["S3Fig"], "half", out, seeds=1)
    formed = {1e-18: (50.0, 6.0), 1e-17: (35.0, 10.0), 1e-16: (8.0, 56.0)}      # aggregates per frame, cells each
    t = [float(m) for m in range(0, 361, 30)]
    _fake_finished_runs(runs, gas=30, seed=1)
    for pt in runs.points[:3]:
        n_agg, cells = formed[float(pt.scene.raw["cell"]["k_a_N_m"])]
        runs.trajectory(pt).with_suffix(".analysis.json").write_text(json.dumps(dict(
            timeseries=dict(time_min=t, n_aggregates=[n_agg] * len(t), fraction_in_aggregates=[0.8] * len(t),
                            mean_cluster_size_weighted=[cells] * len(t)),
            tracks=[dict(series=dict(time_min=t, n_cells=[cells] * len(t)))],
            lifetimes=dict(fraction_aggregate_frames_long_lived=0.9))))
    missing = runs.points[3]
    assert float(missing.scene.raw["cell"]["k_a_N_m"]) == 1e-15
    import shutil
    shutil.rmtree(runs.run_dir(missing))
    rc = main(["figures", "S3Fig", "--scale", "half", "--seeds", "1", "--out", str(out), "--runs", runs.points[0].name])
    err = capsys.readouterr().err
    assert rc == 0
    assert "S3Fig not composed: 3 of 4 runs finished; its stiffness series measured on those" in err
    assert not (out / "S3Fig.half.png").exists()
    table = (out / "stiffness.half.csv").read_text()
    assert table.count("active,") == 3 * 5 and "1e-15" not in table
    rows = {r["id"]: r for r in csv.DictReader(open(out / "stiffness.half.claims.csv"))}
    assert rows["stiffness_aggregates_larger_fewer"]["status"] == "consistent"
    assert rows["stiffness_very_flexible_many_small_stable"]["status"] == "consistent"
    assert rows["stiffness_very_rigid_none"]["status"].startswith("not measurable here: needs active runs at k_a")


def test_a_rerun_starts_the_interrupted_runs_before_new_ones():
    """After an interruption the runs already under way resume first, the longest of them first, then the new
    runs, longest first: what an earlier session started is finished and recorded before new work begins. A sweep
    (no sizes) keeps its file's order within each group."""
    from taichimyxo.sweep.rundir import queue_order
    sizes = {"D1": 8, "D2": 8, "B2": 4, "C1": 4, "C2": 5, "A2": 4}
    states = {"D1": "new", "D2": "new", "B2": "interrupted", "C1": "interrupted", "C2": "interrupted", "A2": "new"}
    assert queue_order(list(sizes), states, sizes) == ["C2", "B2", "C1", "D1", "D2", "A2"]
    assert queue_order(list(sizes), states) == ["B2", "C1", "C2", "D1", "D2", "A2"]


def test_strain_panel_without_logged_strain_computes_it_and_says_so(tmp_path):
    """A run that did not log strain still gives its strain panel: the energy is a function of the positions."""
    from taichimyxo.figures.compose import compose_figure
    runs = plan_figure(FIGURES["Fig4"], "half", tmp_path)
    _fake_finished_runs(runs, gas=30, seed=2)
    compose_figure(runs, tmp_path)
    doc = json.loads((tmp_path / "Fig4.half.json").read_text())
    assert [p["drawn"] for p in doc["panels"]] == [True, True, True]
    assert "B: strain energy computed from the frame's positions (its run did not log it)." in doc["caption"]
    pt = runs.points[0]
    fr = runs.frame(pt, "last").with_strain(pt.scene.width, pt.scene.k_c)
    assert fr.segment_strain.shape == (fr.n_cells, fr.particles_per_cell - 1) and fr.segment_strain.min() >= 0


def test_composite_from_tiny_runs_with_stiffness_series(tmp_path):
    from taichimyxo.figures.command import run_all
    from taichimyxo.figures.compose import compose_figure
    runs = plan_figure(FIGURES["S2Fig"], "tiny", tmp_path, seeds=1, scale=0.1, hours=0.001,
                       extra_set={"output.frame_interval_min": 0.01}, min_cells=1)
    assert [p.scene.n_cells for p in runs.points] == [20] * 4
    first = runs.points[0].name                                          # --runs: part of a figure now
    runs.records = tmp_path / "kept-as-each-ends"       # a run's record as it completes, not after the figure's last
    assert run_all([runs], "local", 2, {}, chosen={first}) == 0
    assert [f.stem for f in runs.records.glob("*/*.npz")] == [runs.points[0].dir_name]
    runs.records = None
    assert runs.states()[0] == "done" and not any(st in ("done", "recorded") for st in runs.states()[1:])
    assert run_all([runs], "local", 2, {}) == 0
    assert all(st == "done" for st in runs.states())
    files = compose_figure(runs, tmp_path)
    doc = json.loads((tmp_path / "S2Fig.tiny.json").read_text())
    assert [p["letter"] for p in doc["panels"]] == list("ABCD") and all(p["drawn"] for p in doc["panels"])
    csv_text = (tmp_path / "stiffness.tiny.csv").read_text()
    assert csv_text.count("non-guided,") == 4 * 5                         # 4 stiffnesses x 5 measures
    claims = (tmp_path / "stiffness.tiny.claims.md").read_text()
    assert claims.count("not measurable here") == 4                       # 3.6 s runs support no verdict
    assert {f.name for f in files} >= {"S2Fig.tiny.png", "S2Fig.tiny.pdf", "stiffness.tiny.png"}
    assert run_all([runs], "local", 2, {}) == 0                           # a rerun skips the finished runs
    # kept as records, the runs give the same series once their folders are gone
    import shutil

    from taichimyxo.figures.records import save_records
    runs.records = tmp_path / "records"
    assert len(save_records(runs, runs.records)) == 4
    from taichimyxo.figures.records import Record
    assert all(str(tmp_path) not in json.dumps(Record(f).analysis) for f in runs.records.glob("*/*.npz"))
    shutil.rmtree(runs.root / "runs")
    assert runs.states() == ["recorded"] * 4
    compose_figure(runs, tmp_path / "again")
    assert (tmp_path / "again" / "stiffness.tiny.csv").read_text() == csv_text


# ------------------------------------------------------------------------------------------------ rigidity
def test_cells_all_at_v_b_on_circles_are_not_rigid():
    """Every cell at v_b on circles, no rigidity at all. The vector R² of v = ω × (r − c)
    passes it and ω R is 1.3 v_b; the rigidity exponent fails it, and the edge speed is v_b."""
    for radius in (4.25, 10.25):
        disk = dict(centre=(50.0, 50.0), radius=radius, omega=1.0, speed=V_B)
        fr = next(synthetic_frames(box=(100.0, 100.0), disks=[disk], speed_noise=0.05, jitter_deg=5, seed=4))
        (a,) = find_aggregates(fr, v_b=V_B)
        assert 0.85 < a["rotation_fit"]["r2"] < 0.98                      # what the old test looked at
        assert a["edge_speed_rigid_vb"] == pytest.approx(1.3, abs=0.05)    # ω R of the rigid fit
        assert abs(a["rigidity_exponent"]) < 0.1 and not a["rigid"]
        assert a["edge_speed_vb"] == pytest.approx(1.0, abs=0.05)


def test_rigid_rotation_is_rigid_and_edge_speed_is_at_the_outer_radius():
    # an aggregate 3.25 µm in radius, smaller than a cell (9 cells on rings at r = 1.5 to 3 µm; edge at 3 µm), and
    # a large one: the outermost ring moves at 2 v_b in both
    for radius, omega in ((3.25, 2 * V_B / 3.0), (10.25, 2 * V_B / 10.0)):
        disk = dict(centre=(40.0, 60.0), radius=radius, omega=omega)
        fr = next(synthetic_frames(box=(100.0, 100.0), disks=[disk], speed_noise=0.02, seed=2))
        (a,) = find_aggregates(fr, v_b=V_B)
        assert a["rigidity_exponent"] == pytest.approx(1.0, abs=0.1) and a["rigid"]
        assert a["edge_speed_vb"] == pytest.approx(2.0, rel=0.05)
        assert a["edge_speed_rigid_vb"] == pytest.approx(omega * a["radius_um"] / V_B, rel=0.05)


def test_table_text_and_plot_use_one_rigidity_measure(tmp_path):
    from taichimyxo.analysis import analyze, format_summary
    from taichimyxo.analysis.claims import claims
    runs = {}
    for name, disk in (("uniform", dict(centre=(50.0, 50.0), radius=6.25, omega=1.0, speed=V_B)),
                       ("rigid", dict(centre=(50.0, 50.0), radius=6.25, omega=0.6))):
        runs[name] = write_synthetic(str(tmp_path / f"{name}.gsd"), v_b=V_B, box=(100.0, 100.0), n_frames=4,
                                     disks=[disk], speed_noise=0.05, seed=3, scene={"guiding": {"kind": "active"}})
    s = analyze(runs["uniform"], plots=True)
    txt = format_summary(s)
    assert "α(v~r^α)" in txt and "R²(fit)" not in txt and "0 % rigid" in txt
    assert any(p.endswith(".profiles.png") for p in s["plots"])
    assert s["predictions"]["verdict"]["rigid_rotation"] is False
    for name, verdict in (("uniform", "not consistent"), ("rigid", "consistent")):
        rows = {r["id"]: r for r in claims([runs[name]], out_dir=str(tmp_path / name), plots=False)["rows"]}
        assert rows["rigid_rotation"]["status"] == verdict
        assert "median α" in rows["rigid_rotation"]["measured"]


def test_short_run_lifetimes_not_measurable(tmp_path):
    from taichimyxo.analysis.claims import claims
    common = dict(v_b=V_B, box=(60.0, 60.0), n_frames=4, seed=5)
    act = write_synthetic(str(tmp_path / "act.gsd"), disks=[dict(centre=(30.0, 30.0), radius=6.25, omega=0.6)],
                          scene={"guiding": {"kind": "active"}}, **common)
    pas = write_synthetic(str(tmp_path / "pas.gsd"), gas=20, scene={"guiding": {"kind": "passive"}}, **common)
    rows = {r["id"]: r for r in claims([act, pas], out_dir=str(tmp_path / "c"), plots=False)["rows"]}
    st = rows["aggregate_lifetimes"]["status"]
    assert st.startswith("not measurable here: a run with 3.0 min of measured speeds cannot show a lifetime of 10")
    assert {"stiffness_clusters_non_guided", "stiffness_very_rigid_none"} <= set(rows)


# ------------------------------------------------------------------------------------------------ stiffness
def _records(kind, by_ka: dict, hours=6.0, seeds=(1, 2)):
    return [dict(kind=kind, k_a=ka, seed=s, measures={**m, "hours": hours}) for ka, m in by_ka.items() for s in seeds]


def test_stiffness_statements_judged_and_not_measurable():
    from taichimyxo.analysis.stiffness import stiffness_rows

    def act(n, cells, frac, life=0.9, rigid=None):
        return dict(n_aggregates=n, aggregate_cells=cells, fraction_in_aggregates=frac, mean_cluster_size=None,
                    long_lived_fraction=life, rigid_fraction=rigid)

    paper_like = _records("active", {1e-18: act(12, 8, 0.5), 1e-17: act(6, 20, 0.5, rigid=0.4),
                                     1e-16: act(3, 40, 0.4), 1e-15: act(0.1, 5, 0.01, rigid=0.01)})
    paper_like += _records("non-guided", {ka: dict(mean_cluster_size=s) for ka, s in
                                          ((1e-18, 2.0), (1e-17, 3.0), (1e-16, 5.0), (1e-15, 9.0))})
    rows = {r["id"]: r for r in stiffness_rows(paper_like)}
    assert [r["status"] for r in rows.values()] == ["consistent"] * 4
    assert "k_a = 1e-18: 12 ± 0 (n = 2)" in rows["stiffness_very_flexible_many_small_stable"]["measured"]
    reversed_ = _records("active", {1e-18: act(3, 40, 0.4), 1e-17: act(6, 20, 0.5, rigid=0.2),
                                    1e-16: act(12, 8, 0.5), 1e-15: act(4, 10, 0.3, rigid=0.3)})
    rows = {r["id"]: r for r in stiffness_rows(reversed_)}
    assert rows["stiffness_aggregates_larger_fewer"]["status"] == "not consistent"
    assert rows["stiffness_very_rigid_none"]["status"] == "not consistent"
    assert rows["stiffness_clusters_non_guided"]["status"].startswith("not measurable here: needs non-guided runs")
    # Rising, the two stiffest swapped: rho exactly 0.8 (6 * 2 / (4 * 15) from 1), at the rule's bound.
    plateau = _records("non-guided", {ka: dict(mean_cluster_size=s) for ka, s in
                                      ((1e-18, 16.0), (1e-17, 75.0), (1e-16, 184.0), (1e-15, 181.0))})
    row = {r["id"]: r for r in stiffness_rows(plateau)}["stiffness_clusters_non_guided"]
    assert row["status"] == "consistent" and "Spearman rho against k_a +0.80" in row["measured"]
    short = _records("active", {1e-18: act(12, 8, 0.5), 1e-17: act(6, 20, 0.5), 1e-16: act(3, 40, 0.4)}, hours=0.17)
    rows = {r["id"]: r for r in stiffness_rows(short)}
    assert rows["stiffness_aggregates_larger_fewer"]["status"].startswith("not measurable here: runs of 10 simulated")
    assert rows["stiffness_very_rigid_none"]["status"].startswith("not measurable here: needs active runs at "
                                                                  "k_a = 1e-15")


# ------------------------------------------------------------------------------------------------ videos from runs
def test_every_panel_run_is_its_scene():
    """Each panel's run is the scene `list` names for it (the same fingerprint: physics, step, seed), so the run is
    that supplementary video at the figure's scale."""
    from taichimyxo.figures.specs import _scene_of
    from taichimyxo.io.scene import Scene
    for fig in FIGURES.values():
        runs = plan_figure(fig, "paper", "unused")
        for panel in fig.panels:
            name = _scene_of(fig, panel)
            if name:
                assert runs.first_seed_point(panel.match).scene.fingerprint() == Scene.load(name).fingerprint(), \
                    (fig.name, panel.letter, name)


def test_videos_render_a_finished_run_instead_of_simulating_it(tmp_path, capsys):
    """`videos --scale half --from DIR` finds a finished run of S1 at half scale below DIR and renders its movie from
    that trajectory: no simulation. A preview with a scale, or a missing folder, is one line, exit 2."""
    from taichimyxo.io.videos import video_scene
    sc = video_scene("S1", scale="half")
    assert sc.name == "S1-half" and sc.box == (100.0, 100.0) and sc.n_cells == 500
    run = tmp_path / "figs" / "Fig2" / "runs" / "scene=S1_seed=1-abc"
    run.mkdir(parents=True)
    write_synthetic(str(run / "scene=S1_seed=1.gsd"), v_b=V_B, box=sc.box, n_frames=3, gas=30, seed=1)
    (run / "scene=S1_seed=1.json").write_text(json.dumps(
        {"fingerprint": sc.fingerprint(), "completed": True, "simulated_seconds": sc.hours * 3600,
         "trajectory_interval_s": sc.frame_every_steps * sc.dt, "files": {"gsd": "scene=S1_seed=1.gsd"}}))
    out = tmp_path / "vids"
    assert main(["videos", "--only", "S1", "--scale", "half", "--from", str(tmp_path / "figs"),
                 "--out", str(out)]) == 0
    done = json.loads((out / "S1-half.json").read_text())
    assert done["status"] == "rendered from trajectory" and done["frames"] == 3
    assert (out / "S1-half.mp4").stat().st_size > 0 and "rendered from the finished run" in capsys.readouterr().out
    # S8 (S3 coloured by strain) from a run of S3's physics that did not log strain (S3 Fig B's): computed
    s8 = video_scene("S8", scale="half")
    run = tmp_path / "figs" / "S3Fig" / "runs" / "scene=S3FigB_seed=1-abc"
    run.mkdir(parents=True)
    write_synthetic(str(run / "scene=S3FigB_seed=1.gsd"), v_b=V_B, box=s8.box, n_frames=3, gas=30, seed=1)
    (run / "scene=S3FigB_seed=1.json").write_text(json.dumps(
        {"fingerprint": s8.fingerprint(), "completed": True, "simulated_seconds": s8.hours * 3600,
         "strain_logged": False, "trajectory_interval_s": s8.frame_every_steps * s8.dt,
         "files": {"gsd": "scene=S3FigB_seed=1.gsd"}}))
    assert main(["videos", "--only", "S8", "--scale", "half", "--from", str(tmp_path / "figs"),
                 "--out", str(out)]) == 0
    assert json.loads((out / "S8-half.json").read_text())["status"] == "rendered from trajectory"
    capsys.readouterr()
    for argv, says in ((["--preview", "--scale", "half"], "--preview and --scale half together"),
                       (["--from", str(tmp_path / "nowhere")], "no such folder")):
        assert says in error_line(capsys, main(["videos", "--only", "S1", *argv, "--out", str(tmp_path / "o")]))
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------------------------------------------ spiral (S6 Fig)
def test_spiral_statement_judged_on_rigid_and_flexible_runs():
    """Rigid spirals keep a larger share in their largest aggregate than flexible ones, whose aggregates split:
    consistent; the other way round: not consistent; without a flexible run, or shorter than an hour: not
    measurable here. A spiral start is its own kind of run, not a random start's active following."""
    from taichimyxo.analysis.claim_runs import run_kind
    from taichimyxo.analysis.spiral import spiral_measures, spiral_row
    assert run_kind({"population": {"start": "spiral"}, "guiding": {"kind": "active"}}) == "spiral"

    def summary(n_agg, largest, minutes=360):
        t = list(range(0, minutes + 1, 30))
        return {"timeseries": {"time_min": t, "n_aggregates": [n_agg] * len(t)},
                "tracks": [{"series": {"time_min": t, "n_cells": [largest] * len(t)}}]}

    m = spiral_measures(summary(3, 40), 125)
    assert m == {"n_aggregates": 3.0, "largest_fraction": 0.32, "hours": 6.0}
    def rec(lab, ka, n, big, mins=360):
        return dict(label=lab, k_a=ka, measures=spiral_measures(summary(n, big, mins), 125))

    assert spiral_row([rec("S9", 1e-16, 1, 110), rec("S10", 1e-17, 4, 40)])["status"] == "consistent"
    assert spiral_row([rec("S9", 1e-16, 3, 40), rec("S10", 1e-17, 1, 110)])["status"] == "not consistent"
    assert spiral_row([rec("S9", 1e-16, 1, 110)])["status"].startswith("not measurable here")
    assert spiral_row([rec("S9", 1e-16, 1, 110, 30), rec("S10", 1e-17, 4, 40, 30)])["status"].startswith(
        "not measurable here")


# ------------------------------------------------------------------------------------------------ dense (Fig 3)
def test_dense_statements_judged_on_aligned_runs():
    """High density (Fig 3, S11-S14): a run from the aligned packing is its own kind. Guided flexible runs with
    more of their cells in stable rotating aggregates than non-guided ones: circular movement consistent; rigid runs
    more nematic than flexible ones: straight streams consistent; active runs with more fast cells and p95 above v_b:
    speed-up consistent. Reversed orderings are not consistent; missing runs or runs under an hour are not
    measurable, naming the scenes that would measure them."""
    from taichimyxo.analysis.claim_runs import run_kind
    from taichimyxo.analysis.dense import dense_record, dense_rows
    assert run_kind({"population": {"start": "aligned"}, "guiding": {"kind": "active"}}) == "dense"
    assert run_kind({"population": {"start": "random"}, "guiding": {"kind": "active"}}) == "active"
    edges = [0.5 * i for i in range(17)]

    def rec(label, guiding, ka, frac, nem, fast, p95, minutes=180, long_lived=0.8):
        t = list(range(0, minutes + 1, 10))
        n = len(t)
        counts = [0.0] * 16
        counts[7], counts[10] = 1 - fast, fast            # 3.5-4 and 5-5.5 µm/min
        summary = {"timeseries": {"time_min": t, "fraction_in_aggregates": [frac] * n, "nematic_order": [nem] * n,
                                  "speed_p95_um_per_min": [4.0 * p95 + 0.01 * (i % 2) for i in range(n)]},
                   "speed_histograms": {"bin_edges_um_per_min": edges, "inside_aggregates": [0.0] * 16,
                                        "outside_aggregates": counts},
                   "lifetimes": {"fraction_aggregate_frames_long_lived": long_lived}}
        return dense_record(label, {"guiding": {"kind": guiding}, "cell": {"k_a_N_m": ka}}, summary, 4.0)

    s11, s13 = rec("S11", "none", 1e-17, 0.02, 0.2, 0.05, 1.05), rec("S13", "active", 1e-17, 0.3, 0.1, 0.3, 1.5)
    s12, s14 = rec("S12", "none", 1e-15, 0.0, 0.8, 0.02, 1.0), rec("S14", "active", 1e-15, 0.0, 0.7, 0.4, 1.8)
    m = s13["measures"]
    assert m["fraction_in_aggregates"] == pytest.approx(0.3) and m["fast_fraction"] == pytest.approx(0.3)
    assert m["fast_above_um_per_min"] == 4.5 and m["speed_p95_vb"] == pytest.approx(1.50125, abs=1e-3)
    assert m["hours"] == 3.0 and m["from_min"] == 150            # the last quarter: 4 of 19 frames

    def status(*recs):
        return {r["id"]: r["status"] for r in dense_rows(list(recs))}

    assert set(status(s11, s12, s13, s14).values()) == {"consistent"}
    flipped = status(rec("S11", "none", 1e-17, 0.4, 0.9, 0.5, 1.05), s12, s13, s14)
    assert set(flipped.values()) == {"not consistent"}
    unstable = rec("S13", "active", 1e-17, 0.3, 0.1, 0.3, 1.5, long_lived=0.2)
    assert status(s11, unstable)["dense_circular_movement"] == "not consistent"
    only = status(s11, s13)
    assert only["dense_straight_streams"].startswith("not measurable here") and "S12" in \
        only["dense_straight_streams"] and "S14" in only["dense_straight_streams"]
    short = status(s11, rec("S13", "active", 1e-17, 0.3, 0.1, 0.3, 1.5, minutes=30))
    assert short["dense_circular_movement"].startswith("not measurable here")


def test_dry_run_estimates_from_finished_runs_when_kept(tmp_path, capsys):
    """A finished one-thread run kept as a record gives the estimate for runs of its kind of scene and integrator:
    its whole run's particle-steps per second, formed states included, instead of the start-state benchmark x a
    factor."""
    from taichimyxo.figures.plan import bench_rates, measured_rates, run_seconds
    from taichimyxo.figures.records import record_path, write_record
    out, records = tmp_path / "figs", tmp_path / "kept"
    runs = plan_figure(FIGURES["S6Fig"], "half", out)
    _fake_finished_runs(runs, gas=30, seed=1)
    pt = runs.points[0]
    sc = pt.scene
    summary = runs.trajectory(pt).with_suffix(".json")
    summary.write_text(json.dumps({"completed": True, "cpu_threads": 1, "steps": sc.steps, "particles": 1000,
                                   "wall_seconds_total": sc.steps * 1000 / 2e6, "scene_values": sc.to_dict()}))
    write_record(record_path(records, runs, pt), runs.trajectory(pt), None, summary, first=False)
    measured = measured_rates(records)
    assert measured == {("S3", "explicit"): [(1000, 2e6)]}
    other = runs.points[1].scene
    assert run_seconds(other, bench_rates(), measured) == other.steps * other.n_cells * other.N / 2e6
    # an imex run of the same kind is not priced by an explicit run's cost per step
    imex = other.with_overrides({"run": {"integrator": "imex-explicit"}})
    assert run_seconds(imex, bench_rates(), measured) != imex.steps * imex.n_cells * imex.N / 2e6
    assert main(["figures", "S6Fig", "--scale", "half", "--out", str(out), "--records", str(records),
                 "--dry-run"]) == 0
    assert "the particle-steps/s of the 1 finished run kept in" in capsys.readouterr().out
    # a run on two threads stands for the one-thread rate its measured speed-up implies
    from taichimyxo.figures.plan import thread_speedup
    summary.write_text(json.dumps({"completed": True, "cpu_threads": 2, "steps": sc.steps, "particles": 1000,
                                   "wall_seconds_total": sc.steps * 1000 / 3e6, "scene_values": sc.to_dict()}))
    write_record(record_path(records, runs, pt), runs.trajectory(pt), None, summary, first=False)
    ((particles, rate),) = measured_rates(records)[("S3", "explicit")]
    assert particles == 1000 and rate == pytest.approx(3e6 / thread_speedup(2)[0])
    # several finished runs at the nearest size price a run at their median, whichever of them sorts first
    rows = {("S3", "explicit"): [(1000, 4e6), (1000, 1e6), (1000, 2e6), (4000, 9e6)]}
    assert run_seconds(other, bench_rates(), rows) == other.steps * other.n_cells * other.N / 2e6


def test_the_committed_records_compose_their_figure(tmp_path):
    """The runs this project made and kept in docs/figures/records compose their figure on a machine without the
    runs (as a user's checkout is): every panel drawn, from the records."""
    from taichimyxo.figures.compose import figure_files
    from taichimyxo.figures.records import Record
    records = REPO / "docs" / "figures" / "records"
    kept = sorted(records.glob("*/*.npz"))
    assert kept, "no committed records"
    assert all(Record(k).frame("last") is not None for k in kept)          # a figure's runs may still be running
    composed = []
    for folder in sorted({k.parent.name for k in kept}):          # one folder per figure and scale: "Fig3.half"
        name, scale = folder.split(".")
        most = max(int(m) for m in re.findall(r"seed=(\d+)", " ".join(k.name for k in kept
                                                                     if k.parent.name == folder)))
        for seeds in range(most, 0, -1):                  # the most seeds whose runs are all kept
            runs = plan_figure(FIGURES[name], scale, tmp_path, seeds)
            runs.records = records
            if all(st in ("recorded", "shared") for st in runs.states()):
                break
        else:
            continue
        assert main(["figures", name, "--scale", scale, "--seeds", str(seeds), "--no-run", "--records", str(records),
                     "--out", str(tmp_path)]) == 0
        files = figure_files(runs, tmp_path)
        doc = json.loads(files["json"].read_text())      # Fig3.json at paper scale
        assert all(p["drawn"] and p["run"].startswith("record: ") for p in doc["panels"]), folder
        if not FIGURES[name].stiffness:                  # the claims table, measured on the records' analyses
            table = json.loads((tmp_path / f"{files['json'].stem}.claims" / "claims.json").read_text())
            assert all(r["path"].endswith(".npz") for r in table["runs"]), folder
        composed.append(folder)
    assert {"Fig2.half", "Fig3.half", "Fig3.paper", "Fig4.half", "S2Fig.half", "S3Fig.half",
            "S6Fig.half"} <= set(composed)


def test_a_panel_title_wraps_its_label_and_keeps_the_time_on_one_line():
    from taichimyxo.figures.compose import TITLE_CHARS, panel_title

    short = panel_title("flexible, k_a = 1e-17 N·m", "t = 6 h 00 min")
    assert short == "flexible, k_a = 1e-17 N·m,  t = 6 h 00 min"
    long = panel_title("very flexible, k_a = 1e-18 N·m", "t = 6 h 00 min")
    assert long.splitlines() == ["very flexible, k_a = 1e-18 N·m", "t = 6 h 00 min"]
    wrapped = panel_title("non-guided rigid cells from the dense aligned start of Fig 3A", "t = 3 h 00 min")
    assert all(len(line) <= TITLE_CHARS for line in wrapped.splitlines())
    assert wrapped.splitlines()[-1].endswith("t = 3 h 00 min")
    assert panel_title("the start", "") == "the start"


def test_dry_run_names_where_a_finished_run_is_instead_of_pricing_it(tmp_path, capsys):
    """A recorded run shows no cost; a run another figure recorded names that record; a figure with every run
    finished says so (the committed records: S3 Fig's eight runs, one of them Fig 2's S3 seed 2)."""
    records = REPO / "docs" / "figures" / "records"
    assert main(["figures", "Fig2", "S3Fig", "--scale", "half", "--seeds", "2", "--dry-run", "--records",
                 str(records), "--out", str(tmp_path / "figs")]) == 0
    text = capsys.readouterr().out
    lines = {ln.split()[1]: ln for ln in text.splitlines() if ln.startswith("  ")}
    assert re.search(r"shared +scene=S3_seed=1 +6 h  the record S3Fig\.half/scene=S3FigB_seed=1-\w+\.npz$",
                     lines["scene=S3_seed=1"])
    assert lines["scene=S3_seed=2"].split() == ["recorded", "scene=S3_seed=2", "6", "h"]
    assert "the record Fig2.half/scene=S3_seed=2-" in lines["scene=S3FigB_seed=2"]
    unfinished = [ln for ln in lines.values() if ln.split()[0] in ("new", "interrupted")]
    assert all(re.search(r" 6 h  ~(\d+ h )?\d+ min", ln) for ln in unfinished)      # priced, as before
    assert "S3Fig (half, 100 x 100 µm, 500 cells): 8 runs x 2 seeds, 48 simulated hours, every run finished" in text
    assert not (tmp_path / "figs").exists()
