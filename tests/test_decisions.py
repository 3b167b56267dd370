"""The decision study's table (taichimyxo/analysis/decisions.py) on run folders whose measures are known."""
import json

import pytest

from taichimyxo.analysis.decisions import read_runs, readings, rigid_fraction, to_markdown
from taichimyxo.interface.cli import main
from taichimyxo.io.scene import Scene, to_toml


def _run(root, name, scene, over, seed, edge, in_agg, tracks=()):
    d = root / "runs" / name
    d.mkdir(parents=True)
    nested = {}
    for k, v in over.items():
        sec, key = k.split(".")
        nested.setdefault(sec, {})[key] = v
    (d / "scene.toml").write_text(to_toml(Scene.load(scene, nested)))
    (d / "point.json").write_text(json.dumps({"overrides": {"scene": scene, **over}, "seed": seed}))
    analysis = {"meta": {"n_cells": 100}, "timeseries": {"time_min": [1.0, 2.0, 3.0, 4.0]}, "tracks": list(tracks)}
    (d / "a.analysis.json").write_text(json.dumps(analysis))
    (d / "result.json").write_text(json.dumps({"status": "completed", "seed": seed, "analysis": "a.analysis.json",
                                               "outcomes": {"edge_speed_vb": edge, "fraction_in_aggregates": in_agg}}))


def test_readings_sort_runs_by_their_resolved_values_and_give_mean_and_sd_over_seeds(tmp_path, capsys):
    for s, e in [(1, 0.6), (2, 0.8)]:
        _run(tmp_path, f"d{s}", "S4", {}, s, e, 0.5)                                   # the default reading
        _run(tmp_path, f"n{s}", "S4", {"guiding.self": False}, s, e + 0.4, 0.6)        # self-following off
        _run(tmp_path, f"r{s}", "S4", {"cell.drag_ratio_normal": 2.0}, s, 1.3, 0.7)    # drag ratio 2
        _run(tmp_path, f"m{s}", "S4", {"cell.drag_ratio_normal": 2.0, "guiding.self": False}, s, 1.4, 0.7)
    _run(tmp_path, "unfinished", "S4", {"guiding.pull_on": "head_segment"}, 1, 9.0, 0.9)
    (tmp_path / "runs" / "unfinished" / "result.json").write_text('{"status": "interrupted"}')
    runs = read_runs([tmp_path])
    assert len(runs) == 8
    rows = {r["reading"]: r for r in readings(runs)}
    d = rows["default"]["cells"]["S4 edge"]
    assert (d["mean"], d["n"]) == (pytest.approx(0.7), 2) and d["sd"] == pytest.approx(0.1414, abs=1e-3)
    assert rows["self-following = false"]["cells"]["S4 edge"]["mean"] == pytest.approx(1.1)
    assert rows["ζ_n / ζ_t = 2"]["cells"]["S4 edge"]["mean"] == pytest.approx(1.3)      # self at its default
    assert rows["ζ_n / ζ_t = 2, self-following = false"]["cells"]["S4 edge"]["mean"] == pytest.approx(1.4)
    assert not any("pull acts on" in k for k in rows)                                   # not finished: no row
    assert rows["default"]["cells"]["S3 edge"] is None
    md = to_markdown(list(rows.values()))
    assert "| default | 0.70 ± 0.14 (2) | 0.50 ± 0.00 (2) |" in md
    assert "**1.30 ± 0.00 (2)**" in md                                                  # 0.6 from the default
    assert main(["decisions", str(tmp_path), "--out", str(tmp_path / "t")]) == 0
    assert (tmp_path / "t" / "decisions.csv").read_text().count("S4 edge") == 4


def test_the_two_suppression_rules_are_read_together_as_the_drag_and_self_following_are(tmp_path):
    """S15's rules in every combination: each rule alone is its one-at-a-time row, and the two changed together is a
    matrix row of its own (its runs in no other row)."""
    c, w = "reversals.suppression_contacts", "reversals.suppressed_wait"
    for s in (1, 2):
        _run(tmp_path, f"d{s}", "S15", {}, s, 1.0, 0.5)
        _run(tmp_path, f"h{s}", "S15", {c: "head"}, s, 1.0, 0.7)
        _run(tmp_path, f"e{s}", "S15", {w: "contact_end"}, s, 1.0, 0.6)
        _run(tmp_path, f"b{s}", "S15", {c: "head", w: "contact_end"}, s, 1.0, 0.9)
    rows = {r["reading"]: r["cells"]["S15 in aggregates"] for r in readings(read_runs([tmp_path]))}
    assert rows["default"]["mean"] == pytest.approx(0.5)
    assert rows["contacts that hold a reversal = head"]["mean"] == pytest.approx(0.7)
    assert rows["a held reversal waits = contact_end"]["mean"] == pytest.approx(0.6)
    both = rows["contacts that hold a reversal = head, a held reversal waits = contact_end"]
    assert (both["mean"], both["n"]) == (pytest.approx(0.9), 2)
    assert sum(r is not None for r in rows.values()) == 4                    # the repeats of those rows dropped


def test_dense_runs_carry_their_stream_measures_and_sparse_runs_none(tmp_path):
    """A run from the aligned packing (S12, S14) is judged by its streams: nematic order (straight), local polar
    order (sorted) over the last quarter and the fraction of cell-frames faster than 1.1 v_b; S4 gets none."""
    def analysis(nem, polar, fast):
        t = [0.0, 20.0, 40.0, 60.0]
        counts = [0.0] * 16
        counts[7], counts[10] = 1 - fast, fast                       # 3.5-4 and 5-5.5 µm/min (v_b = 4)
        return {"meta": {"n_cells": 100}, "tracks": [],
                "timeseries": {"time_min": t, "fraction_in_aggregates": [0.0] * 4, "nematic_order": [1.0] + nem,
                               "local_polar_order": [0.0] + polar, "speed_p95_um_per_min": [4.0] * 4},
                "speed_histograms": {"bin_edges_um_per_min": [0.5 * i for i in range(17)],
                                     "inside_aggregates": [0.0] * 16, "outside_aggregates": counts}}
    for s, nem in ((1, 0.9), (2, 0.7)):
        _run(tmp_path, f"s12_{s}", "S12", {}, s, None, 0.0)
        d = tmp_path / "runs" / f"s12_{s}"
        (d / "a.analysis.json").write_text(json.dumps(analysis([0.5, 0.5, nem], [0.1, 0.3, 0.6], 0.25)))
    _run(tmp_path, "s4", "S4", {}, 1, 0.8, 0.5)
    runs = {r["run"]: r["measures"] for r in read_runs([tmp_path])}
    m = runs["s12_1"]
    assert m["nematic_order"] == pytest.approx(0.9) and m["local_polar_order"] == pytest.approx(0.6)  # t = 60 only
    assert m["fast_fraction"] == pytest.approx(0.25)
    assert "nematic_order" not in runs["s4"]
    cell = {r["reading"]: r for r in readings(read_runs([tmp_path]))}["default"]["cells"]["S12 straight"]
    assert (cell["mean"], cell["n"]) == (pytest.approx(0.8), 2)


def test_rigid_fraction_counts_cells_of_rigidly_rotating_aggregates_over_the_last_quarter():
    tracks = [{"series": {"time_min": [3.0, 4.0], "n_cells": [10, 20], "rigidity_exponent": [0.9, 1.0]}},
              {"series": {"time_min": [4.0], "n_cells": [30], "rigidity_exponent": [0.1]}},       # cells at v_b
              {"series": {"time_min": [1.0], "n_cells": [50], "rigidity_exponent": [1.0]}}]       # too early
    a = {"meta": {"n_cells": 100}, "timeseries": {"time_min": [1.0, 2.0, 3.0, 4.0]}, "tracks": tracks}
    assert rigid_fraction(a) == pytest.approx(0.2)                # the last quarter is t = 4: 20 of 100 cells


def test_a_kept_decisions_json_joins_the_runs_of_a_folder_once_each(tmp_path):
    for s in (1, 2):
        _run(tmp_path / "a", f"d{s}", "S4", {}, s, 0.5 + s / 10, 0.5)
    _run(tmp_path / "b", "d3", "S4", {}, 3, 0.9, 0.5)
    assert main(["decisions", str(tmp_path / "a"), "--out", str(tmp_path / "kept")]) == 0
    runs = read_runs([tmp_path / "kept" / "decisions.json", tmp_path / "a", tmp_path / "b"])
    assert sorted(r["run"] for r in runs) == ["d1", "d2", "d3"]
    assert readings(runs)[0]["cells"]["S4 edge"]["n"] == 3


def _record(records, name, scene, fraction_in_aggregates, seed=1, rigidity=None):
    """A figure record (taichimyxo/figures/records.py) of `scene` whose analysis holds known series: four frames, one
    aggregate track of 40 cells in the last two, its rigidity series only when given."""
    import numpy as np
    series = {"time_min": [3.0, 4.0], "n_cells": [40, 40]}
    if rigidity is not None:
        series["rigidity_exponent"] = rigidity
    analysis = {"meta": {"n_cells": 100, "v_b_um_per_min": 4.0},
                "timeseries": {"time_min": [1.0, 2.0, 3.0, 4.0], "n_aggregates": [0, 0, 1, 1],
                               "fraction_in_aggregates": [0.0, 0.0, 0.4, fraction_in_aggregates],
                               "speed_p95_um_per_min": [4.0] * 4, "free_cell_speed_um_per_min": [4.4] * 4},
                "tracks": [{"id": 0, "series": series}]}
    summary = {"seed": seed, "completed": True, "fingerprint": scene.fingerprint(),
               "scene_values": {"run": {"hours": scene.hours}}}
    path = records / "S3Fig.half" / f"{name}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, version=np.array(1), **{f"{k}_json": np.frombuffer(json.dumps(v).encode(), np.uint8)
                                           for k, v in (("meta", {}), ("analysis", analysis), ("summary", summary))})
    return path


def test_a_run_a_figure_record_holds_is_read_from_it_and_only_a_record_of_the_same_physics(tmp_path, capsys):
    _run(tmp_path, "done", "S7", {}, 2, 0.9, 0.5)                                  # finished here: read as it is
    for name, over in (("rigid", {}), ("slender", {"cell.drag_ratio_normal": 2.0})):
        d = tmp_path / "runs" / name
        d.mkdir(parents=True)
        nested = {"cell": {"drag_ratio_normal": 2.0}} if over else {}
        nested["run"] = {"seed": 1}
        (d / "scene.toml").write_text(to_toml(Scene.load("S7", nested)))
        (d / "point.json").write_text(json.dumps({"overrides": {"scene": "S7", **over}, "seed": 1}))
    records = tmp_path / "records"
    _record(records, "scene=S3FigD_seed=1", Scene.load("S3FigD", {"run": {"seed": 1}}), 0.9)   # = S7, default drag
    _record(records, "scene=S3FigD_seed=2", Scene.load("S3FigD", {"run": {"seed": 2}}), 0.1)   # another seed
    assert sorted(r["run"] for r in read_runs([tmp_path])) == ["done"]                # without records: unfinished
    runs = {r["run"]: r for r in read_runs([tmp_path], records)}
    assert sorted(runs) == ["done", "rigid"]                      # no record holds drag 2; seed 2's is not seed 1's
    m = runs["rigid"]["measures"]
    assert m["fraction_in_aggregates"] == pytest.approx(0.9)      # the last quarter: the fourth frame
    assert m["aggregate_cells"] == pytest.approx(40.0) and m["n_aggregates"] == pytest.approx(1.0)
    assert m["edge_speed_vb"] is None and m["self_curled"] is None      # a record keeps no edge series, no frames
    assert m["free_cell_speed_vb"] is None                              # the records predate today's free-cell rule
    assert m["rigid_fraction"] is None                            # no rigidity series: not measurable, not 0
    assert runs["rigid"]["record"] == "S3Fig.half/scene=S3FigD_seed=1.npz"
    assert runs["rigid"]["values"]["cell.drag_ratio_normal"] == 0.5
    _record(records, "scene=S3FigD_seed=1", Scene.load("S3FigD", {"run": {"seed": 1}}), 0.9, rigidity=[1.0, 0.2])
    assert read_runs([tmp_path], records)[1]["measures"]["rigid_fraction"] == pytest.approx(0.0)   # 0.2 < 0.5
    assert main(["decisions", str(tmp_path), "--records", str(records), "--out", str(tmp_path / "t")]) == 0
    assert "2 finished runs" in capsys.readouterr().out
    assert main(["decisions", str(tmp_path), "--records", str(tmp_path / "nowhere"), "--out", str(tmp_path / "t")]) != 0
    assert "--records" in capsys.readouterr().err
