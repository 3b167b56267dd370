"""The accuracy study's outcome check: does a larger step change what a user measures?

    python -m taichimyxo sweep sweeps/accuracy.toml --jobs 2 --out sweeps-results/accuracy    # the runs (~1.5 h)
    python benchmarks/accuracy_outcomes.py [sweeps-results/accuracy ...] [--rows CSV ...] [--out DIR]
                                                                     # default DIR: benchmarks-results

Several sweep folders are read as one (sweeps/step_control.toml is compared with the reference runs of
sweeps/accuracy.toml this way), and `--rows` adds the runs of an earlier accuracy_outcomes.csv (this script's own
rows: runs whose folders are gone, e.g. benchmarks/results/accuracy_outcomes.csv), so seeds run on different days
are compared as one ensemble without running them again. A run in both (same setting and seed) is taken from its
folder.

Trajectory errors of a few per cent are within the seed-to-seed spread of a chaotic many-cell system, so the
trajectory tolerance of benchmarks/accuracy.py cannot say whether a step changes the *results*. This reads a sweep
over a run setting (sweeps/accuracy.toml: half-scale S3, 1 simulated hour, 3 seeds per step), analyses every run's
trajectory again with the installed analysis (so all runs are measured by the same code), and compares the outcomes
of taichimyxo.sweep.collect (rotating aggregates, fraction of cells in them, mean edge speed, 95th-percentile speed,
..., each averaged over the last quarter of the frames) of each setting with the reference setting's seeds.

A setting **agrees** on an outcome when its seed mean lies within the reference's seed range (min..max); the table
also gives the difference of the means in units of the reference's seed standard deviation and Welch's t (the
difference over the standard error of the difference of two means; with 3 seeds a side a range can be narrow by
chance, so read both). A setting may become a default only if it agrees on every outcome (ACCURACY.md). An
outcome measured in at most half of either side's seeds is not judged: it hardly exists in that scene (the edge
speed and size of rotating aggregates where the runs form almost none, as non-guided S1), and whether aggregates
form is judged by n_aggregates. Also the cost: wall seconds per simulated hour of each run
(the runs of a sweep run side by side, so compare costs within one sweep only).

Writes accuracy_outcomes.csv (a row per run) and accuracy_outcomes.md (the comparison) into --out (default
benchmarks-results/ in the current directory, like every benchmark; the committed ones are benchmarks/results/).
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import tempfile
from pathlib import Path

import numpy as np

CHECKED = ("n_aggregates", "fraction_in_aggregates", "edge_speed_vb", "speed_p95_vb", "aggregate_cells",
           "cluster_cells")


def run_outcomes(run_dir: Path) -> dict | None:
    """Outcomes of one finished run, from its trajectory analysed now (None when the run has not finished)."""
    from taichimyxo.analysis import analyze
    from taichimyxo.sweep import outcomes
    from taichimyxo.sweep.rundir import read_json, read_result
    res = read_result(run_dir)
    if not res or res.get("status") != "completed":
        return None
    point = read_json(run_dir / "point.json")
    gsd = run_dir / f"{point['name']}.gsd"
    with tempfile.TemporaryDirectory() as tmp:            # the summary is all we need; leave the run folder as is
        summary = analyze(str(gsd), out_dir=tmp, plots=False)
    row = dict(setting=json.dumps(point["overrides"], sort_keys=True), seed=point["seed"],
               simulated_h=res["simulated_seconds"] / 3600.0, wall_s=res["wall_seconds"], steps=res["steps"])
    row["wall_s_per_sim_h"] = row["wall_s"] / row["simulated_h"]
    row.update({k: v for k, v in outcomes(summary).items() if k not in ("from_min", "to_min", "frames")})
    return row


def read_rows(path: Path) -> list[dict]:
    """The rows of an earlier accuracy_outcomes.csv, typed as run_outcomes writes them (empty: None)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out = []
    for r in rows:
        row = {}
        for k, v in r.items():
            if k == "setting":
                row[k] = json.dumps(json.loads(v), sort_keys=True)
            elif k in ("seed", "steps"):
                row[k] = int(v)
            else:
                row[k] = float(v) if v not in ("", None) else None
        out.append(row)
    return out


def compare(rows: list[dict], reference: str) -> list[dict]:
    """Per setting and outcome: seed mean, SD, values; reference range; agreement (mean within the range)."""
    by: dict[str, list[dict]] = {}
    for r in rows:
        by.setdefault(r["setting"], []).append(r)
    ref = by[reference]
    out = []
    for setting, rs in by.items():
        for oc in CHECKED + ("wall_s_per_sim_h",):
            rare = any(2 * sum(r.get(oc) is not None for r in side) <= len(side) for side in (rs, ref))
            vals = np.asarray([r[oc] for r in rs if r.get(oc) is not None], float)
            rv = np.asarray([r[oc] for r in ref if r.get(oc) is not None], float)
            m = float(vals.mean()) if len(vals) else math.nan
            sd = float(vals.std(ddof=1)) if len(vals) > 1 else math.nan
            rsd = float(rv.std(ddof=1)) if len(rv) > 1 else math.nan
            lo, hi = (float(rv.min()), float(rv.max())) if len(rv) else (math.nan, math.nan)
            cost = oc == "wall_s_per_sim_h"
            se = math.sqrt(rsd ** 2 / len(rv) + sd ** 2 / len(vals)) if len(rv) > 1 and len(vals) > 1 else math.nan
            out.append(dict(setting=setting, outcome=oc, seeds=len(vals), mean=m, sd=sd,
                            values=[float(v) for v in vals], ref_min=lo, ref_max=hi,
                            diff_in_ref_sd=(m - float(rv.mean())) / rsd if rsd and rsd > 0 else math.nan,
                            welch_t=(m - float(rv.mean())) / se if se and se > 0 else math.nan,
                            rare=rare and bool(len(vals)),
                            agrees=None if cost or rare else bool(lo <= m <= hi)))
    return out


def markdown(cmp: list[dict], reference: str) -> str:
    lines = [f"Reference: {reference}. Agrees: the setting's seed mean within the reference's seed range. Welch t: "
             "difference of the means / its standard error.", "",
             "| setting | outcome | mean ± SD (seeds) | per seed | reference range | Δ / SD_ref | Welch t | agrees |",
             "|---|---|---|---|---|---|---|---|"]
    for c in cmp:
        vals = ", ".join(f"{v:.3g}" for v in c["values"])
        ag = "" if c["agrees"] is None else ("yes" if c["agrees"] else "**no**")
        if c.get("rare"):
            ag = "not judged (in at most half the seeds)"
        if not c["seeds"]:
            continue                        # an outcome these runs were not measured by (earlier CSVs' rows)
        lines.append(f"| {c['setting']} | {c['outcome']} | {c['mean']:.3g} ± {c['sd']:.2g} ({c['seeds']}) | "
                     f"{vals} | {c['ref_min']:.3g}–{c['ref_max']:.3g} | {c['diff_in_ref_sd']:+.2f} | "
                     f"{c['welch_t']:+.2f} | {ag} |")
    settings = list(dict.fromkeys(c["setting"] for c in cmp))
    lines.append("")
    for s in settings:
        if s == reference:
            continue
        bad = [c["outcome"] for c in cmp if c["setting"] == s and c["agrees"] is False]
        rare = [c["outcome"] for c in cmp if c["setting"] == s and c.get("rare")]
        lines.append(f"- {s}: " + ("agrees with the reference on every outcome" if not bad else
                                    "outside the reference's seed range on " + ", ".join(bad))
                     + (f" (not judged, measured in at most half the seeds: {', '.join(rare)})" if rare else ""))
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sweep_out", nargs="*", help="sweep output folders (default: sweeps-results/accuracy, "
                    "unless --rows is given)")
    ap.add_argument("--rows", action="append", default=[], metavar="CSV",
                    help="add the runs of an earlier accuracy_outcomes.csv (repeatable)")
    ap.add_argument("--reference", default=None, help='the reference setting as JSON (default: the smallest '
                    'first swept value, e.g. {"run.dt_ms": 2})')
    ap.add_argument("--group", default=None, metavar="KEY", help="compare within each value of a swept KEY (e.g. "
                    "scene, cell.k_a_N_m), each against its own reference")
    ap.add_argument("--out", default="benchmarks-results")
    a = ap.parse_args(argv)
    for p in a.rows:
        if not Path(p).is_file():
            print(f"accuracy_outcomes: --rows {p}: no such file")
            return 2
    roots = [Path(p) for p in (a.sweep_out or ([] if a.rows else ["sweeps-results/accuracy"]))]
    where = ", ".join([str(r / "runs") for r in roots] + a.rows)
    dirs = [d for r in roots for d in sorted((r / "runs").glob("*/"))]
    if roots and not dirs:
        print(f"accuracy_outcomes: no run folders in {where}")
        return 2
    rows = [r for r in (run_outcomes(d) for d in dirs) if r is not None]
    have = {(r["setting"], r["seed"]) for r in rows}
    for p in a.rows:
        for r in read_rows(Path(p)):
            if (r["setting"], r["seed"]) not in have:
                rows.append(r)
                have.add((r["setting"], r["seed"]))
    if not rows:
        print(f"accuracy_outcomes: no finished run in {where}")
        return 2
    rows.sort(key=lambda r: (r["setting"], r["seed"]))
    settings = sorted({r["setting"] for r in rows}, key=lambda s: [str(v) for v in json.loads(s).values()])
    groups: dict = {}
    for st in settings:
        groups.setdefault(json.loads(st).get(a.group) if a.group else None, []).append(st)
    references = {}
    for g, members in groups.items():
        given = {**json.loads(a.reference), **({a.group: g} if a.group else {})} if a.reference else None
        references[g] = json.dumps(given, sort_keys=True) if given else members[0]
        if references[g] not in members:
            print(f"accuracy_outcomes: reference {references[g]} has no finished run (settings: {', '.join(members)})")
            return 2
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "accuracy_outcomes.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(dict.fromkeys(k for r in rows for k in r)))
        w.writeheader()
        w.writerows(rows)
    md = ""
    for g, members in groups.items():
        cmp = compare([r for r in rows if r["setting"] in members], references[g])
        md += ("\n" if md else "") + markdown(cmp, references[g])
    (out / "accuracy_outcomes.md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
