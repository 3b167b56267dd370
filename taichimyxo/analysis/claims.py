"""The paper's claims as one table: each claim measured on the runs given, next to what the paper states.

``claims(paths, out_dir)`` analyses each trajectory (``analyze_frames``), sorts the runs by the guiding their scene
stored (non-guided, passive following, active following, adhesion, slime trails) and writes ``claims.md``,
``claims.csv``, ``claims.json`` and a plot per claim where a picture says it better (``claims.<name>.png``). A claim
whose runs are missing names the kind of run it needs instead of a number. The command line is
``python -m taichimyxo claims RUN.gsd [RUN.gsd ...] [--out DIR]``. Each claim is a function registered in ``CLAIMS`` by
``@claim(id)``; ``evaluate(runs)`` calls them in the order registered, which is the table's.

The claims (Janulevicius et al. 2015) and how each is measured; "± SE" over frames is by batch means
(stats.series_mean_se: blocks of sqrt(n) successive frames, so the correlation of successive frames widens it; NaN
below 8 frames), "± SE over tracks" over aggregates followed in time:

1. free_cell_speed: cells touching no other cell (clusters of one) nor their own tail (a curled cell's head follows
   it) move at v_b. Per run: the mean over frames of their mean speed / v_b ± SE. Consistent within 5 % (+ 2 SE) of 1.
2. speed_p95_guided_vs_non_guided: the 95th percentile of cell speed, mean over frames / v_b ± SE. Short-range
   guiding that speeds cells up (active following, adhesion) drives cells above v_b; without guiding nothing does.
   Consistent when every active-following or adhesion run lies above every non-guided one.
3. fraction_in_aggregates: fraction of cells in rotating aggregates, mean ± SD over the last quarter of the analysed
   frames. The paper gives no number: active following and adhesion form stable aggregates, passive following only
   small unstable ones, non-guided cells none. Consistent when every active-following / adhesion run has a larger
   fraction than every passive / non-guided one.
4. rigid_rotation: the rigidity exponent alpha of each aggregate (aggregate_measure.rigidity_exponent: the slope of
   ln speed against ln r over its particles; 1 for rigid rotation, 0 when every cell moves at one speed on
   circles), median and quartiles over the aggregate-frames it can judge (particles spanning radii by a factor of
   2). Consistent when the median over active following and adhesion runs is >= 0.5 (RIGID_EXPONENT). The R² of
   v = omega x (r - c) cannot be the test: cells all at v_b on circles pass it at 0.89-0.97.
5-7. edge_speed_active / _adhesion / _slime: edge speed (mean speed of the outermost ring of segments, one cell
   width inside the aggregate's outer radius R) / v_b, time mean per track seen in >= ``min_track_frames`` frames,
   mean ± SE over tracks; beside it the free-cell speed of the same runs. Paper: up to 4 v_b with active
   following, (4/3) v_b with adhesion (rigid-body model, S2 Text), about v_b with slime trails; edge faster than a
   free cell for short-range guiding. Consistent: active above the free-cell speed by 2 SE and at most 4 v_b + 2 SE;
   adhesion within 10 % or 2 SE of 4/3 and above the free cells; slime within 10 % or 2 SE of 1.
8. edge_speed_vs_size: per kind, the change of edge speed across the radius range of the tracks of R >= 3 µm
   tracked >= 10 min, over their mean edge speed, with a bootstrap 95 % interval; consistent below 25 % for each
   kind with >= 3 such tracks (edge_size.py; docs/measures.md). Not a test of slope = 0, which any large sample fails.
9. aggregate_lifetimes: tracks linked by shared cells (tracking.py); per run the median and longest lifetime and
   the fraction of aggregate-frames in tracks living >= ``stable_lifetime_min`` (10 min). Paper: passive following
   gives no stable aggregates, active following and adhesion do. Consistent when every passive run's fraction is
   below every active / adhesion run's.
10. strain_inside_vs_outside: mean segment strain energy of cells in aggregates over that of the other cells, mean
   over frames ± SE (only runs that logged strain). Paper: higher inside (toward the centre). Consistent when the
   ratio exceeds 1 by 2 SE.
11-14. stiffness_clusters_non_guided, stiffness_aggregates_larger_fewer, stiffness_very_flexible_many_small_stable,
   stiffness_very_rigid_none: the paper's four statements on bending stiffness over runs at several k_a
   (taichimyxo/analysis/stiffness.py says how each is judged); "not measurable here" without runs at the
   stiffnesses a statement compares, or with runs shorter than an hour.
15. spiral_stability: prearranged spiral aggregates (S9, S10: their own kind of run, "spiral start"): the largest
   aggregate's share of the cells and aggregates per frame at the end, rigid against flexible (spiral.py).
16-18. dense_circular_movement, dense_straight_streams, dense_stream_speedup: the high-density statements (Fig 3,
   S11-S14: runs from the aligned start, their own kind "dense"), judged as dense.py says.
A claim the runs given cannot support (too short, too small) says "not measurable here" and why, not a verdict.
"""
from __future__ import annotations

import json
import math
import os
from typing import Callable

import numpy as np

from . import edge_size as es
from .aggregate_measure import RIGID_EXPONENT
from .claim_plots import write_claim_plots
from .claim_runs import (
    KINDS,
    MIN_RIGID_CELLS,
    free_speed,
    free_speed_text,
    load_runs,
    mean_se,
    needs,
    plus_minus,
    rigidity_unkept,
    runs_of,
    speed_span_min,
    stable_tracks,
)
from .claims_table import COLUMNS, format_claims, to_csv, to_markdown, write_complete  # noqa: F401
from .dense import dense_record, dense_rows
from .spiral import spiral_measures, spiral_row
from .stats import late_start, series_mean_se
from .stiffness import records_from_runs, stiffness_rows
from .summary import json_clean


def _describe(r) -> str:
    m = r["summary"]["meta"]
    t = m["time_range_min"]
    return f"{r['label']} ({_kind_label(r)}, {m['n_cells']} cells, {t[0]:.0f}-{t[1]:.0f} min)"


def _row(cid, claim, paper, runs, measured, status, values, plot=None):
    return dict(id=cid, claim=claim, measured=measured, paper=paper,
                runs="; ".join(_describe(r) for r in runs) if runs else "none", status=status,
                values=values, plot=plot)


# The claims in table order: id -> function(runs, shared) returning its row, or its rows (a claim may give several).
CLAIMS: dict[str, Callable[[list[dict], dict], dict | list[dict]]] = {}


def claim(cid: str):
    """Register the decorated function as claim `cid`; the table lists the claims in the order they are registered."""
    def register(fn):
        if cid in CLAIMS:
            raise ValueError(f"claim {cid!r} is registered twice")
        CLAIMS[cid] = fn
        return fn
    return register


def _kind_label(r) -> str:
    return KINDS.get(r["kind"], (r["kind"],))[0]


def _shared(runs: list[dict]) -> dict:
    """What several claims use, computed once: free_speed, each run's free-cell speed / v_b (mean, SE, frames) by
    id(run)."""
    return dict(free_speed={id(r): free_speed(r) for r in runs})


@claim("free_cell_speed")
def free_cell_speed(runs, shared):
    vals, parts = {}, []
    for r in runs:
        m, se, n = shared["free_speed"][id(r)]
        nf = int(np.nansum(r["summary"]["timeseries"]["n_free_cells"]))
        text, along = free_speed_text(r, m, se, n)      # and the part along the body, where kept (docs/measures.md)
        vals[r["label"]] = dict(mean_vb=m, se=se, n_frames=n, free_cell_frames=nf, **along)
        parts.append(text)
    ok = [v for v in vals.values() if v["n_frames"]]
    status = ("no free cells in these runs" if not ok else
              "consistent" if all(abs(v["mean_vb"] - 1) <= 0.05 + 2 * np.nan_to_num(v["se"]) for v in ok)
              else "not consistent")
    return _row("free_cell_speed", "Free cells (touching no other cell nor their own tail) move at v_b",
                "a freely moving bacterium moves at its equilibrium speed v_b = 4 µm/min", runs,
                "; ".join(parts), status, vals)


@claim("speed_p95_guided_vs_non_guided")
def speed_p95_guided_vs_non_guided(runs, shared):
    vals, parts = {}, []
    for r in runs:
        m, se, n = series_mean_se(np.asarray(r["summary"]["timeseries"]["speed_p95_um_per_min"], float) / r["v_b"])
        vals[r["label"]] = dict(kind=r["kind"], mean_vb=m, se=se, n_frames=n)
        parts.append(f"{_kind_label(r)} {r['label']}: {plus_minus(m, se)} v_b")
    g = [vals[r["label"]]["mean_vb"] for r in runs_of(runs, "active", "adhesion")]
    ng = [vals[r["label"]]["mean_vb"] for r in runs_of(runs, "non-guided")]
    if not ng:
        parts.append("non-guided: " + needs("non-guided"))
    status = (needs(*([] if g else ["active"]) + ([] if ng else ["non-guided"])) if not (g and ng) else
              "consistent" if min(g) > max(ng) else "not consistent")
    return _row("speed_p95_guided_vs_non_guided", "95th-percentile cell speed: guided above non-guided",
                "non-guided cells are sped up by nothing but pushes (about v_b at most); with active following "
                "or adhesion cells at aggregate edges and in streams move faster than v_b (up to 4 v_b)",
                runs, "; ".join(parts), status, vals, plot="speed")


@claim("fraction_in_aggregates")
def fraction_in_aggregates(runs, shared):
    vals, parts = {}, []
    for r in runs:
        f = np.asarray(r["summary"]["timeseries"]["fraction_in_aggregates"], float)
        t = np.asarray(r["summary"]["timeseries"]["time_min"], float)
        q = slice(late_start(len(f)), None)
        sd = float(f[q].std(ddof=1)) if len(f[q]) > 1 else float("nan")
        vals[r["label"]] = dict(kind=r["kind"], mean=float(f[q].mean()), sd=sd, final=float(f[-1]),
                                from_min=float(t[q][0]), to_min=float(t[-1]))
        parts.append(f"{_kind_label(r)} {r['label']}: {plus_minus(float(f[q].mean()), sd)} "
                     f"(t = {t[q][0]:.0f}-{t[-1]:.0f} min)")
    hi = [vals[r["label"]]["mean"] for r in runs_of(runs, "active", "adhesion")]
    lo = [vals[r["label"]]["mean"] for r in runs_of(runs, "passive", "non-guided")]
    status = (needs(*([] if hi else ["active"]) + ([] if lo else ["passive"])) if not (hi and lo) else
              "consistent (ordering; the paper gives no number)" if min(hi) > max(lo) else "not consistent")
    return _row("fraction_in_aggregates", "Fraction of cells in rotating aggregates (mean ± SD, last quarter)",
                "active following and adhesion form stable rotating circular aggregates (Fig 2D-E); passive "
                "following only small unstable circular structures (Fig 2C); non-guided cells clusters (Fig "
                "2B); no fraction is given (at 6 h)", runs, "; ".join(parts), status, vals, plot="fraction")


@claim("rigid_rotation")
def rigid_rotation(runs, shared):
    """The rigidity exponent of the speed-against-radius profile (aggregate_measure)."""
    vals, parts, judged = {}, [], []
    for r in runs:
        al = [x for t in r["summary"]["tracks"] for x in t["series"].get("rigidity_exponent", []) if x is not None]
        if not al:
            if r["kind"] in ("active", "adhesion", "slime"):
                parts.append(f"{_kind_label(r)} {r['label']}: " + ("its record keeps no rigidity exponents" if
                             rigidity_unkept(r) else "no aggregate spanning radii by a factor of 2"))
            continue
        q = np.percentile(al, [25, 50, 75])
        vals[r["label"]] = dict(kind=r["kind"], median=float(q[1]), quartiles=[float(q[0]), float(q[2])], n=len(al),
                                fraction_rigid=float(np.mean(np.asarray(al) >= RIGID_EXPONENT)))
        parts.append(f"{_kind_label(r)} {r['label']}: median α {q[1]:.2f} (quartiles {q[0]:.2f}-{q[2]:.2f}), "
                     f"{100 * vals[r['label']]['fraction_rigid']:.0f} % of {len(al)} aggregate-frames rigid")
        if r["kind"] in ("active", "adhesion"):
            judged += al
    sr = runs_of(runs, "active", "adhesion")
    unkept = not judged and any(map(rigidity_unkept, sr))
    status = (needs("active") if not sr else "not measurable here: the records of these runs keep no rigidity "
              "exponents; claims on their trajectories measure them" if unkept else "not measurable here: no "
              "aggregate of these runs spans radii by a factor of 2 (a ring of cells, or a run too short to form "
              "larger aggregates)" if not judged else "consistent" if float(np.median(judged)) >= RIGID_EXPONENT
              else "not consistent")
    return _row("rigid_rotation", "Aggregates rotate as rigid bodies (rigidity exponent α, speed ~ r^α over "
                f"an aggregate's particles; rigid when α >= {RIGID_EXPONENT:g}; 1 rigid, 0 every cell at one speed)",
                "stable rotating aggregates rotate as rigid bodies: cells do not slide laterally, cells in the "
                "centre move slower than at the edge (short-range guiding); with slime trails most cells move "
                "at v_b", runs, "; ".join(parts) or "no aggregates", status, vals, plot="rigid")


EDGE_PAPER = {
    "active": "edge faster than v_b, at most 4 v_b = 16 µm/min (rigid-body model, F_max = 200 pN; S2 Text)",
    "adhesion": "edge at (4/3) v_b = 5.3 µm/min (rigid-body model, S2 Text), faster than a free cell",
    "slime": "most cells, the edge included, at about v_b (guiding turns cells, does not speed them up; "
             "rigid cells S16; flexible cells S17 form small short-lived aggregates)",
}


def _edge_speed(runs, shared, kind):
    """The edge speed / v_b of the runs of one kind, beside their free cells' speed."""
    rs = runs_of(runs, kind)
    ev = [t["mean_edge_speed_vb"] for r in rs for t in stable_tracks(r)]
    fs = [shared["free_speed"][id(r)][0] for r in rs]
    fs = float(np.nanmean(fs)) if rs and np.isfinite(fs).any() else float("nan")
    m, se, n = mean_se(ev)
    vals = dict(mean_vb=m, se=se, n_tracks=n, free_cell_speed_vb=fs, per_track=ev)
    if not rs:
        measured, status = needs(kind), needs(kind)
    elif not n:
        measured, status = "no aggregate seen in >= 3 frames", "no aggregates in these runs"
    else:
        measured = (f"{plus_minus(m, se)} v_b ({plus_minus(m * rs[0]['v_b'], se * rs[0]['v_b'], '.1f')} µm/min), "
                    f"SE over {n} tracks; free cells {fs:.2f} v_b")
        s2 = 2 * np.nan_to_num(se)
        if kind == "active":
            good = m - s2 > fs and m <= 4 + s2
        elif kind == "adhesion":
            good = abs(m - 4 / 3) <= max(s2, 0.1 * 4 / 3) and m - s2 > fs
        else:
            good = abs(m - 1) <= max(s2, 0.1)
        status = "consistent" if good else "not consistent"
    return _row(f"edge_speed_{kind}", f"Edge speed / v_b, {KINDS[kind][0]}", EDGE_PAPER[kind], rs,
                measured, status, vals, plot="edge_speed")


@claim("edge_speed_active")
def edge_speed_active(runs, shared):
    return _edge_speed(runs, shared, "active")


@claim("edge_speed_adhesion")
def edge_speed_adhesion(runs, shared):
    return _edge_speed(runs, shared, "adhesion")


@claim("edge_speed_slime")
def edge_speed_slime(runs, shared):
    return _edge_speed(runs, shared, "slime")


@claim("edge_speed_vs_size")
def edge_speed_vs_size(runs, shared):
    """Edge speed against aggregate size, judged by the size of the change (module docstring, item 8)."""
    vals, parts, judged = {}, [], []
    MIN_R, MIN_TRACKED, MAX_EFFECT = es.EDGE_SIZE_MIN_RADIUS_UM, es.EDGE_SIZE_MIN_TRACKED_MIN, es.EDGE_SIZE_MAX_EFFECT
    for kind in ("active", "adhesion"):
        rs = runs_of(runs, kind)
        if not rs:
            parts.append(f"{KINDS[kind][0]}: {needs(kind)}")
            continue
        vals[kind], text, verdict = es.judge_kind(KINDS[kind][0], rs)
        parts.append(text)
        if verdict is not None:
            judged.append(verdict)
    status = (needs("active") if not runs_of(runs, "active", "adhesion") else
              f"too few tracks (>= {es.EDGE_SIZE_MIN_TRACKS} of R >= {MIN_R:g} µm tracked >= "
              f"{MIN_TRACKED:g} min needed)" if not judged else
              "consistent" if all(judged) else "not consistent")
    return _row("edge_speed_vs_size", f"Edge speed vs aggregate radius (change across the radius range / mean edge "
                f"speed, tracks of R >= {MIN_R:g} µm tracked >= {MIN_TRACKED:g} min; "
                f"size-independent when |change| < {100 * MAX_EFFECT:.0f} %)",
                "speed of cells at the aggregate edge appears not to depend on the aggregate size (so larger "
                "aggregates turn slower)", runs_of(runs, "active", "adhesion"), "; ".join(parts), status, vals,
                plot="edge_vs_radius")


@claim("aggregate_lifetimes")
def aggregate_lifetimes(runs, shared):
    """Lifetimes of the aggregates' tracks, passive against active following and adhesion."""
    vals, parts = {}, []
    for r in runs:
        lt = r["summary"]["lifetimes"]
        vals[r["label"]] = dict(kind=r["kind"], **{k: lt[k] for k in (
            "n_tracks", "median_lifetime_min", "max_lifetime_min", "n_long_lived",
            "fraction_aggregate_frames_long_lived", "events", "lifetimes_min", "lifetime_censored")})
        if lt["n_tracks"]:
            parts.append(f"{_kind_label(r)} {r['label']}: {lt['n_tracks']} tracks, median "
                         f"{lt['median_lifetime_min']:.0f} min, longest {lt['max_lifetime_min']:.0f} min, "
                         f"{100 * lt['fraction_aggregate_frames_long_lived']:.0f} % of aggregate-frames in tracks "
                         f">= {lt['stable_lifetime_min']:g} min")
        else:
            parts.append(f"{_kind_label(r)} {r['label']}: no aggregates")
    fr = lambda rs: [vals[r["label"]]["fraction_aggregate_frames_long_lived"] or 0.0 for r in rs]  # noqa: E731
    pas, act = fr(runs_of(runs, "passive")), fr(runs_of(runs, "active", "adhesion"))
    stable_min = runs[0]["summary"]["parameters"]["stable_lifetime_min"] if runs else 10
    # a run whose frames with speeds span less than the lifetime asked for cannot show one (its 0 % would be the
    # run's, not the cells')
    span = [speed_span_min(r) for r in runs_of(runs, "passive", "active", "adhesion")]
    status = (needs(*([] if pas else ["passive"]) + ([] if act else ["active"])) if not (pas and act) else
              f"not measurable here: a run with {min(span):.1f} min of measured speeds cannot show a lifetime of "
              f"{stable_min:g} min (needs longer runs)" if min(span) < stable_min else
              "consistent" if max(pas) < min(act) else "not consistent")
    return _row("aggregate_lifetimes", f"Aggregate lifetimes (tracks by shared cells; long-lived: >= "
                f"{stable_min:g} min)",
                "passive following gives only small unstable circular structures that quickly dissipate; active "
                "following and adhesion give stable rotating aggregates", runs, "; ".join(parts), status, vals,
                plot="lifetimes")


@claim("strain_inside_vs_outside")
def strain_inside_vs_outside(runs, shared):
    vals, parts = {}, []
    for r in runs:
        ts = r["summary"]["timeseries"]
        if not ts["strain_inside_aggregates_J"]:
            continue
        a = np.asarray(ts["strain_inside_aggregates_J"], float)
        b = np.asarray(ts["strain_outside_aggregates_J"], float)
        with np.errstate(invalid="ignore", divide="ignore"):
            m, se, n = series_mean_se(np.where(b > 0, a / b, np.nan))
        sp = r["summary"].get("strain_profile") or {}
        vals[r["label"]] = dict(kind=r["kind"], ratio=m, se=se, n_frames=n, inner_over_outer=sp.get("inner_over_outer"))
        io_ = sp.get("inner_over_outer")
        parts.append(f"{_kind_label(r)} {r['label']}: inside / outside {plus_minus(m, se)} over {n} frames" +
                     (f"; inner (r < R/2) / outer {io_:.2f}" if io_ is not None and math.isfinite(io_) else ""))
    if not vals:
        measured = "not in these runs (no strain logged)"
        status = "needs a run with strain logged (--set output.strain=true; S3 logs it)"
    else:
        measured = "; ".join(parts)
        ok = [v for v in vals.values() if v["n_frames"]]
        status = ("no aggregates in the runs with strain" if not ok else
                  "consistent" if all(v["ratio"] - 2 * np.nan_to_num(v["se"]) > 1 for v in ok) else "not consistent")
    return _row("strain_inside_vs_outside", "Strain energy inside vs outside aggregates",
                "overlaps (strain energy) are higher towards the centre of rotating aggregates, and stay high "
                "there (Fig 2F, S8 Video)", [r for r in runs if r["label"] in vals], measured, status, vals,
                plot="strain" if vals else None)


@claim("stiffness")
def stiffness(runs, shared):
    """The paper's four statements on bending stiffness (stiffness.py), over the runs' k_a: four rows."""
    return [dict(r, runs="; ".join(_describe(x) for x in runs if x["kind"] in ("non-guided", "active")) or "none",
                 plot=None) for r in stiffness_rows(records_from_runs(runs))]


@claim("spiral_stability")
def spiral_stability(runs, shared):
    """Prearranged spiral aggregates: rigid cells keep theirs, flexible cells' split (spiral.py)."""
    rs = runs_of(runs, "spiral")
    recs = [dict(label=r["label"], k_a=float(r["scene"]["cell"]["k_a_N_m"]),
                 measures=spiral_measures(r["summary"], r["summary"]["meta"]["n_cells"])) for r in rs]
    row = spiral_row(recs)
    return _row("spiral_stability", "Prearranged spiral aggregates against stiffness",
                "aggregates of rigid cells stay relatively stable, losing some cells; those of flexible cells split "
                "into several smaller aggregates and swirling streams (S6 Fig, S9 and S10 Video)", rs,
                row["measured"], row["status"], row["values"])


@claim("dense")
def dense(runs, shared):
    """The high-density statements (Fig 3, S11-S14): three rows (dense.py)."""
    rs = runs_of(runs, "dense")
    recs = [dense_record(r["label"], r["scene"], r["summary"], r["v_b"]) for r in rs]
    return [_row(x["id"], x["claim"], x["paper"], [r for r in rs if r["label"] in x["labels"]], x["measured"],
                 x["status"], x["values"]) for x in dense_rows(recs)]


def evaluate(runs: list[dict]) -> list[dict]:
    """The claims table (list of row dicts: id, claim, measured, paper, runs, status, values, plot)."""
    shared = _shared(runs)
    rows = []
    for fn in CLAIMS.values():
        out = fn(runs, shared)
        rows += out if isinstance(out, list) else [out]
    return rows


def claims(paths, out_dir: str | None = None, every: int = 1, v_b: float | None = None, plots: bool = True,
           progress=None, **params) -> dict:
    """Measure the paper's claims on the trajectories `paths`; write claims.md, claims.csv, claims.json (and
    claims.<name>.png) into out_dir (default: the current folder). Returns dict(rows, runs, files)."""
    out_dir = out_dir or "."
    runs = load_runs(paths, every=every, v_b=v_b, progress=progress, **params)
    rows = evaluate(runs)
    os.makedirs(out_dir, exist_ok=True)
    files = []
    if plots:
        files = write_claim_plots(runs, rows, os.path.join(out_dir, "claims"))
    for r in rows:                  # outputs name their inputs and plots relative to out_dir, never machine paths
        r["plot_file"] = os.path.relpath(r["plot_file"], out_dir) if r.get("plot_file") else None
    run_info = [dict(label=r["label"], path=os.path.relpath(r["path"], out_dir), kind=r["kind"],
                     v_b_um_per_min=r["v_b"],
                     n_cells=r["summary"]["meta"]["n_cells"], time_range_min=r["summary"]["meta"]["time_range_min"],
                     n_frames_analyzed=r["summary"]["meta"]["n_frames_analyzed"], every=every) for r in runs]
    doc = dict(claims=rows, runs=run_info, min_rigid_cells=MIN_RIGID_CELLS,
               note="see taichimyxo/analysis/claims.py for how each claim is measured and judged")
    md = ("# The paper's claims on these runs\n\n" + to_markdown(rows) + "\nRuns: " +
          "; ".join(f"{x['label']} = {x['path']}" for x in run_info) + "\n")
    if files:
        md += "\nPlots: " + ", ".join(os.path.basename(f) for f in files) + "\n"
    paths_out = {k: os.path.join(out_dir, f"claims.{k}") for k in ("md", "csv", "json")}
    write_complete(paths_out["md"], md)
    write_complete(paths_out["csv"], to_csv(rows))
    write_complete(paths_out["json"], json.dumps(json_clean(doc), indent=1))
    return dict(rows=json_clean(rows), runs=run_info, files=list(paths_out.values()) + files)
