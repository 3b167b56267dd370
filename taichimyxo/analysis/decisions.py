"""The decision study's table (docs/decisions.md): each reading the paper leaves open, against the default, by the
claims it bears on.

``decision_table(roots)`` reads the finished runs of a decision sweep (``sweeps/decisions.toml``,
``sweeps/decisions_dense.toml``: each run folder's ``result.json``, ``scene.toml``, analysis and trajectory; or the
runs an earlier table kept in its ``decisions.json``) and sorts
them by their base scene and by the values their resolved scenes hold for the decision keys (``DECISIONS``), not by
the names of their points: a point of one grid that is another's default counts for both. A run is a reading of
decision D when every other decision key holds its base scene's value; the drag ratio and self-following, and the two
suppression rules, are also read together (``MATRICES``). Each cell of the table is one claim's measure (``CLAIMS``)
on one scene, mean ± SD over the seeds with their count. ``write_decisions(roots, out)`` writes ``decisions.md`` /
``.csv`` / ``.json``; the command line is ``python -m taichimyxo decisions DIR [DIR ...] [--records FOLDER] [--out
DIR]`` (with --records, a run a figure already made is read from its record instead of being run again:
read_record_run).

The measures per run, each over the last quarter of the analysed frames (as the sweep table's outcomes,
taichimyxo/sweep/collect.py): edge speed / v_b and the fraction of cells in rotating aggregates (the run's
outcomes); the fraction of cells in aggregates that rotate rigidly by their speed profile (rigidity exponent >=
RIGID_EXPONENT, the aggregate tracks' per-frame series); the fraction of cells whose head lies within guiding range
(W + d_g) of their own tail (the trajectory's frames); the mean aggregate size and count.
"""
from __future__ import annotations

import csv
import io
import json
import math
import tomllib
from pathlib import Path

import numpy as np

from .aggregate_measure import RIGID_EXPONENT
from .dense import dense_measures

# decision key -> how the table names it (docs/decisions.md says why each is open)
DECISIONS = {
    "cell.drag_ratio_normal": "ζ_n / ζ_t",
    "guiding.self": "self-following",
    "guiding.distance": "guiding distance between",
    "guiding.pull_on": "pull acts on",
    "guiding.reaction_on": "adhesion reaction on",
    "cell.length_reading": "5 µm read as",
    "cell.particles": "particles N",
    "reversals.suppression": "reversal suppression",
    "reversals.suppression_contacts": "contacts that hold a reversal",
    "reversals.suppressed_wait": "a held reversal waits",
}
# decisions read together, each pair in every combination: drag x self-following, and the two suppression rules
MATRICES = (("cell.drag_ratio_normal", "guiding.self"),
            ("reversals.suppression_contacts", "reversals.suppressed_wait"))

# (column id, scene, measure, what the paper says): the claims the decisions bear on
CLAIMS = [
    ("S4 edge", "S4", "edge_speed_vb", "adhesion edge (4/3) v_b = 1.33 v_b (Fig 2E, S2 Text)"),
    ("S4 in aggregates", "S4", "fraction_in_aggregates", "adhesion: stable rotating aggregates"),
    ("S4 self-curled", "S4", "self_curled", "no number; guiding acts on 'the tail of another (or the same) "
     "bacterium'"),
    ("S3 edge", "S3", "edge_speed_vb", "active following: edge above v_b, at most 4 v_b (Fig 2D)"),
    ("S3 in aggregates", "S3", "fraction_in_aggregates", "active following: stable rotating aggregates"),
    ("S3 self-curled", "S3", "self_curled", "no number; a rotation seed is 'of several flexible cells'"),
    ("S7 rigid rotating", "S7", "rigid_fraction", "very rigid cells form no circular aggregates (S3D Fig)"),
    ("S7 in aggregates", "S7", "fraction_in_aggregates", "very rigid: none"),
    ("S2 in aggregates", "S2", "fraction_in_aggregates", "passive following: occasional small unstable circles"),
    ("S3FigA aggregates", "S3FigA", "n_aggregates", "very flexible: many small stable aggregates"),
    ("S3FigC size", "S3FigC", "aggregate_cells", "rigid: aggregates larger than flexible cells' (S3C Fig)"),
    ("S15 in aggregates", "S15", "fraction_in_aggregates", "reversing cells aggregate only with suppression"),
    ("S14 in aggregates", "S14", "fraction_in_aggregates", "dense very rigid, active following (S14 Video): "
     "streams, no circular aggregates named"),
    ("S14 straight", "S14", "nematic_order", "rigid and very rigid cells with active following sort into adjacent "
     "straight streams (S14 Video)"),
    ("S14 faster", "S14", "fast_fraction", "with active following whole streams move faster than v_b"),
    ("S12 straight", "S12", "nematic_order", "very rigid non-guided cells sort themselves into straight streams "
     "(S12 Video)"),
    ("S12 sorted", "S12", "local_polar_order", "the streams sorted: touching cells heading one way (the start's "
     "polarities are random)"),
]
DENSE_MEASURES = ("nematic_order", "local_polar_order", "fast_fraction")   # dense.dense_measures, aligned starts


def _scene_name(run_dir: Path, point: dict) -> str:
    s = str(point.get("overrides", {}).get("scene") or point.get("base") or "")
    return Path(s).stem if s.endswith(".toml") else s


def rigid_fraction(analysis: dict) -> float | None:
    """Fraction of the population's cells in aggregates rotating rigidly by their speed profile, mean over the last
    quarter of the analysed frames (None without frames, or when the tracks carry no rigidity series)."""
    times = analysis.get("timeseries", {}).get("time_min") or []
    n = analysis.get("meta", {}).get("n_cells")
    if not times or not n:
        return None
    tracks = analysis.get("tracks", [])
    if tracks and not any("rigidity_exponent" in tr.get("series", {}) for tr in tracks):
        return None                     # an analysis (or a record of one) older than the rigidity series
    late = sorted(times)[int(0.75 * len(times)):] or sorted(times)[-1:]
    count = {t: 0 for t in late}
    for tr in tracks:
        s = tr["series"]
        for t, k, a in zip(s["time_min"], s["n_cells"], s.get("rigidity_exponent") or [None] * len(s["time_min"])):
            if t in count and a is not None and a >= RIGID_EXPONENT:
                count[t] += k
    return float(np.mean([count[t] / n for t in late]))


def dense_of(scene: dict, analysis: dict) -> dict:
    """A run from the aligned packing (a dense scene): its stream measures (DENSE_MEASURES, by
    dense.dense_measures over the last quarter); other runs: none."""
    if (scene.get("population") or {}).get("start") != "aligned" or not analysis.get("timeseries"):
        return {}
    m = dense_measures(analysis, float(scene["cell"]["speed_um_per_min"]))
    return {k: (m[k] if m[k] is not None and math.isfinite(m[k]) else None) for k in DENSE_MEASURES}


def self_curled(trajectory: Path, width: float, reach: float) -> float | None:
    """Fraction of cells whose head lies within W + d_g of their own tail, mean over the last quarter of the
    trajectory's frames."""
    from ..io.trajectory import count_frames, read_frames
    from .clusters import touches_own_tail
    n = count_frames(str(trajectory))
    if n == 0:
        return None
    fr = [touches_own_tail(f.positions, width, tol=reach).mean() for f in read_frames(str(trajectory),
                                                                                     start=int(0.75 * n))]
    return float(np.mean(fr)) if fr else None


def read_run(run_dir: Path) -> dict | None:
    """One finished run: its base scene, its resolved decision values and its measures (None: not finished)."""
    try:
        result = json.loads((run_dir / "result.json").read_text())
        point = json.loads((run_dir / "point.json").read_text())
        scene = tomllib.loads((run_dir / "scene.toml").read_text())
    except (OSError, ValueError):
        return None
    if result.get("status") != "completed":
        return None
    oc = result.get("outcomes") or {}
    values = {}
    for key in DECISIONS:
        sec, k = key.split(".")
        values[key] = scene.get(sec, {}).get(k)
    measures = {m: oc.get(m) for m in ("edge_speed_vb", "fraction_in_aggregates", "n_aggregates",
                                       "aggregate_cells", "free_cell_speed_vb")}
    an = run_dir / str(result.get("analysis") or "")
    if an.is_file():
        analysis = json.loads(an.read_text())
        measures["rigid_fraction"] = rigid_fraction(analysis)
        measures.update(dense_of(scene, analysis))
    gsd = next(iter(sorted(run_dir.glob("*.gsd"))), None)
    if gsd is not None:
        W = scene["cell"]["width_um"]
        measures["self_curled"] = self_curled(gsd, W, scene["guiding"]["range_um"])
    return {"scene": _scene_name(run_dir, point), "seed": result.get("seed"), "values": values,
            "measures": measures, "run": run_dir.name}


def read_record_run(run_dir: Path, records: Path) -> dict | None:
    """An unfinished sweep run whose physics a figure record already holds (taichimyxo/figures/records.py: the same
    scene fingerprint, seed included, and duration, completed): its measures from the record's analysis summary, by
    the same outcomes() a finished run's result holds. A record keeps each aggregate track's cell counts and
    rigidity, not its radius or edge speed, nor the trajectory: edge speed, radius and self-curling are None. The
    free cells' speed is None too: the committed records' analyses predate the rule that a cell curled onto its own
    tail is not free (docs/CHANGELOG.md), while the aggregate finder the other measures come from is unchanged."""
    from types import SimpleNamespace

    from ..figures.records import Record, shared_record
    from ..io.scene import Scene
    from ..sweep.collect import outcomes
    try:
        point = json.loads((run_dir / "point.json").read_text())
        scene_values = tomllib.loads((run_dir / "scene.toml").read_text())
        scene = Scene.from_dict(scene_values)
    except (OSError, ValueError):
        return None
    path = shared_record(records, SimpleNamespace(scene=scene), first=False)
    if path is None:
        return None
    rec = Record(path)
    analysis = rec.analysis
    if not analysis:
        return None
    values = {}
    for key in DECISIONS:
        sec, k = key.split(".")
        values[key] = scene_values.get(sec, {}).get(k)
    oc = outcomes(analysis)
    measures = {m: oc.get(m) for m in ("edge_speed_vb", "fraction_in_aggregates", "n_aggregates",
                                       "aggregate_cells")}
    measures.update(rigid_fraction=rigid_fraction(analysis), self_curled=None, free_cell_speed_vb=None,
                    **dense_of(scene_values, analysis))
    return {"scene": _scene_name(run_dir, point), "seed": (rec.summary or {}).get("seed"), "values": values,
            "measures": measures, "run": run_dir.name, "record": f"{path.parent.name}/{path.name}"}


def read_runs(roots, records=None) -> list[dict]:
    """The finished runs under each sweep folder, or kept in a decisions.json an earlier table wrote (so a study
    finished over several machines or sessions joins its parts); a run found twice counts once. With `records` (a
    figures' records folder, docs/figures/records), a sweep run not finished here whose physics a record holds is
    read from the record (read_record_run)."""
    out: dict = {}
    for root in roots:
        root = Path(root)
        if root.is_file() and root.suffix == ".json":
            try:
                kept = json.loads(root.read_text())["runs"]
            except (OSError, ValueError, KeyError, TypeError):
                raise FileNotFoundError(f"{root}: not a decisions.json (it lists no runs)") from None
            for r in kept:
                out.setdefault(r["run"], r)
            continue
        runs = root / "runs"
        if not runs.is_dir():
            raise FileNotFoundError(f"{root}: no runs/ folder (a sweep's --out folder holds one) and not a "
                                    f"decisions.json")
        for d in sorted(runs.iterdir()):
            r = read_run(d) if d.is_dir() else None
            if r is None and records is not None and d.is_dir():
                r = read_record_run(d, Path(records))
            if r is not None:
                out[r["run"]] = r
    return list(out.values())


def defaults_of(scene_name: str) -> dict:
    """The base scene's values of the decision keys: its default reading."""
    from ..io.scene import Scene
    sc = Scene.load(scene_name)
    return {k: sc.raw[k.split(".")[0]][k.split(".")[1]] for k in DECISIONS}


def _stat(xs):
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    if not xs:
        return None
    return {"mean": float(np.mean(xs)), "sd": float(np.std(xs, ddof=1)) if len(xs) > 1 else None, "n": len(xs)}


def _fmt(v) -> str:
    return "true" if v is True else "false" if v is False else f"{v:g}" if isinstance(v, float) else str(v)


def readings(runs: list[dict]) -> list[dict]:
    """The table's rows: the default, each decision's other readings, and each pair of MATRICES; each with the
    statistic of every claim column over the runs of that reading."""
    base = {s: defaults_of(s) for s in {r["scene"] for r in runs}}

    def is_reading(r, fixed: dict) -> bool:
        d = base[r["scene"]]
        return all(r["values"][k] == (fixed[k] if k in fixed else d[k]) for k in DECISIONS)

    rows = []

    def add(label, decision, fixed):
        cells = {}
        for cid, scene, measure, _ in CLAIMS:
            # a one-at-a-time row shows only the scenes where its value is not already the default
            sel = [r for r in runs if r["scene"] == scene and is_reading(r, fixed) and scene in base and
                   (decision in ("", "matrix") or any(base[scene][k] != v for k, v in fixed.items()))]
            cells[cid] = _stat([r["measures"].get(measure) for r in sel])
        if any(v is not None for v in cells.values()):
            rows.append({"reading": label, "decision": decision, "fixed": {k: v for k, v in fixed.items()},
                         "cells": cells})

    add("default", "", {})
    for key in DECISIONS:
        seen = sorted({r["values"][key] for r in runs}, key=str)
        for v in seen:
            if all(base[s][key] == v for s in base):
                continue
            add(f"{DECISIONS[key]} = {_fmt(v)}", key, {key: v})
    for a, b in MATRICES:
        for va in sorted({r["values"][a] for r in runs}, key=str):
            for vb in sorted({r["values"][b] for r in runs}, key=str):
                add(f"{DECISIONS[a]} = {_fmt(va)}, {DECISIONS[b]} = {_fmt(vb)}", "matrix", {a: va, b: vb})
    # the matrix repeats the default and the one-at-a-time rows where they coincide: keep the first of each
    out, seen_rows = [], set()
    for row in rows:
        sig = json.dumps(row["cells"], sort_keys=True)
        if row["decision"] == "matrix" and sig in seen_rows:
            continue
        seen_rows.add(sig)
        out.append(row)
    return out


def effect(row: dict, default: dict) -> dict:
    """Per column: (reading - default) / the larger seed SD of the two (None where either is missing)."""
    out = {}
    for cid, st in row["cells"].items():
        d = default["cells"].get(cid)
        if st is None or d is None:
            out[cid] = None
            continue
        sd = max(x for x in (st["sd"] or 0.0, d["sd"] or 0.0, 1e-9))
        out[cid] = (st["mean"] - d["mean"]) / sd
    return out


def cell_text(st) -> str:
    if st is None:
        return "–"
    sd = "" if st["sd"] is None else f" ± {st['sd']:.2f}"
    return f"{st['mean']:.2f}{sd} ({st['n']})"


def to_markdown(rows: list[dict]) -> str:
    cols = [c for c in CLAIMS if any(r["cells"].get(c[0]) for r in rows)]
    head = "| reading | " + " | ".join(c[0] for c in cols) + " |"
    lines = [head, "|" + "---|" * (len(cols) + 1)]
    default = next((r for r in rows if r["reading"] == "default"), None)
    for r in rows:
        eff = effect(r, default) if default and r is not default else {}
        cells = []
        for c in cols:
            t = cell_text(r["cells"].get(c[0]))
            e = eff.get(c[0])
            cells.append(f"**{t}**" if e is not None and abs(e) >= 3 else t)
        lines.append(f"| {r['reading']} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append("Columns (scene, measure, the paper): " + "; ".join(f"{c[0]}: {c[3]}" for c in cols) + ".")
    lines.append("Each cell: mean ± SD over seeds (seeds); **bold**: differs from the default by at least 3 of the "
                 "larger seed SD.")
    return "\n".join(lines) + "\n"


def to_csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["reading", "decision", "claim", "scene", "measure", "mean", "sd", "seeds"])
    for r in rows:
        for cid, scene, measure, _ in CLAIMS:
            st = r["cells"].get(cid)
            if st is not None:
                w.writerow([r["reading"], r["decision"], cid, scene, measure, f"{st['mean']:.6g}",
                            "" if st["sd"] is None else f"{st['sd']:.6g}", st["n"]])
    return buf.getvalue()


def write_decisions(roots, out, records=None) -> dict:
    if records is not None and not Path(records).is_dir():
        raise FileNotFoundError(f"--records {records}: no such folder (a figures' records folder, docs/figures/"
                                f"records)")
    runs = read_runs(roots, records)
    if not runs:
        raise FileNotFoundError(f"no finished runs under {', '.join(map(str, roots))}")
    rows = readings(runs)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "decisions.md").write_text(to_markdown(rows))
    (out / "decisions.csv").write_text(to_csv(rows))
    (out / "decisions.json").write_text(json.dumps({"rows": rows, "runs": runs}, indent=1, default=str))
    return {"rows": rows, "runs": len(runs), "out": str(out)}
