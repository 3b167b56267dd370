"""The stiffness series (S2 Fig, S3 Fig): what the populations form against the cells' bending stiffness k_a, and the
paper's four statements on stiffness judged on it.

Per run, each measure is the mean over the last quarter of its analysed frames (4.5-6 h of a 6 h run; the
convention of the claims table), from its analysis summary:
  n_aggregates            rotating aggregates per frame
  aggregate_cells         cells per aggregate (over aggregate-frames of the tracks)
  fraction_in_aggregates  fraction of the cells in rotating aggregates
  mean_cluster_size       mean size of the cluster a cell is in, cells (touching cells; clusters of one included)
  long_lived_fraction     fraction of aggregate-frames in tracks living >= stable_lifetime_min (10 min)
  rigid_fraction          fraction of the cells in aggregates that rotate rigidly by their speed profile: per frame
                          (frames with speeds) the n_cells of the aggregates whose rigidity exponent (track series
                          'rigidity_exponent') is >= RIGID_EXPONENT (0.5), summed, over the population's cells; an
                          aggregate whose exponent cannot be judged (a single ring of cells) is not rigid. None when
                          the tracks keep no per-frame exponents (records made before they were kept)
                          (EXTRA_MEASURES: judged, not in the figures' CSV table nor plot)
Per k_a and kind of run: mean ± SD over the seeds (n seeds).

The statements (Effect of cell bending stiffness, Results):
  stiffness_clusters_non_guided: non-guided clusters grow with stiffness (S2 Fig). Consistent when the mean cluster
    size rises with k_a: Spearman rho of the means against k_a >= 0.8 over >= 3 stiffnesses, and the stiffest above
    the most flexible.
  stiffness_aggregates_larger_fewer: with active following stiffer cells form larger and fewer aggregates (S3 Fig),
    over the stiffnesses that form aggregates (very flexible to rigid). Consistent when cells per aggregate rise
    (rho >= 0.8) and aggregates per frame fall (rho <= -0.8).
  stiffness_very_flexible_many_small_stable: very flexible cells form many small, stable aggregates (S3A Fig).
    Consistent when at k_a = 1e-18 aggregates per frame are the most and cells per aggregate the fewest of the
    stiffnesses that form aggregates, and >= 50 % of its aggregate-frames are in long-lived tracks.
  stiffness_very_rigid_none: very rigid cells form no circular aggregates (S3D Fig): "rigid cells cannot bend and
    are unlikely to generate a rotation seed or initiate the rotation of the entire stream", and the paper's
    circular aggregates rotate as rigid bodies (next paragraph). Very rigid cells here do circulate, in polygon
    rings of straight cells, which the aggregate finder counts; so the statement is judged by rigid_fraction:
    consistent when at k_a = 1e-15 it is below VERY_RIGID_MAX_RIGID_FRACTION (0.05) and below the flexible runs'
    (k_a = 1e-17) where those are measured; the fraction in any rotating aggregate is reported beside it. "Not
    measurable here" when the very rigid runs keep no per-frame rigidity exponents.
A statement whose runs are missing, or shorter than MIN_HOURS, says "not measurable here" and why."""
from __future__ import annotations

import numpy as np

from .aggregate_measure import RIGID_EXPONENT
from .stats import late_start

STIFFNESS = {1e-18: "very flexible", 1e-17: "flexible", 1e-16: "rigid", 1e-15: "very rigid"}
MEASURES = {
    "n_aggregates": "rotating aggregates per frame",
    "aggregate_cells": "cells per aggregate",
    "fraction_in_aggregates": "fraction of cells in rotating aggregates",
    "mean_cluster_size": "mean cluster size (cells), non-guided",
    "long_lived_fraction": "fraction of aggregate-frames long-lived",
}
# measures judged by the statements but not tabled or plotted by the figures (taichimyxo.figures.stiffness)
EXTRA_MEASURES = {
    "rigid_fraction": f"fraction of cells in rigidly rotating aggregates (alpha >= {RIGID_EXPONENT:g})",
}
# aggregates form within the first hour and grow for hours; the paper's statements are at 6 h
MIN_HOURS = 1.0
# very rigid cells form no circular aggregates: fewer than this fraction of the cells in rigidly rotating ones
VERY_RIGID_MAX_RIGID_FRACTION = 0.05


def _mean(x) -> float | None:
    a = np.asarray([v for v in x if v is not None], float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if len(a) else None


def rigid_fraction(summary: dict) -> float | None:
    """The fraction of the population's cells in rigidly rotating aggregates (alpha >= RIGID_EXPONENT), per frame
    from the tracks' series, mean over the frames with speeds of the last quarter; None when the tracks keep no
    per-frame rigidity exponents or no frame of the last quarter has speeds."""
    tracks = summary.get("tracks", [])
    if any("rigidity_exponent" not in tr["series"] for tr in tracks):
        return None
    t = np.asarray(summary["timeseries"]["time_min"], float)
    if not len(t):
        return None
    without = {round(float(x), 4) for x in summary["meta"].get("frames_without_speed_min") or []}
    window = [round(float(x), 4) for x in t[late_start(len(t)):]]
    window = [x for x in window if x not in without]
    if not window:
        return None
    rigid = dict.fromkeys(window, 0)
    for tr in tracks:
        s = tr["series"]
        for tm, n, al in zip(s["time_min"], s["n_cells"], s["rigidity_exponent"]):
            k = round(float(tm), 4)
            if k in rigid and al is not None and al >= RIGID_EXPONENT:
                rigid[k] += n
    return float(np.mean(list(rigid.values()))) / float(summary["meta"]["n_cells"])


def run_measures(summary: dict) -> dict:
    """The measures of one run (module docstring) from its analysis summary, with its simulated hours."""
    ts = summary["timeseries"]
    t = np.asarray(ts["time_min"], float)
    q0 = late_start(len(t))
    t_from = float(t[q0]) if len(t) else 0.0
    cells = [n for tr in summary.get("tracks", []) for tm, n in zip(tr["series"]["time_min"],
                                                                    tr["series"]["n_cells"]) if tm >= t_from - 1e-9]
    n_agg = _mean(ts["n_aggregates"][q0:])
    return dict(n_aggregates=n_agg, aggregate_cells=_mean(cells) if cells else (None if n_agg else 0.0),
                fraction_in_aggregates=_mean(ts["fraction_in_aggregates"][q0:]),
                mean_cluster_size=_mean(ts["mean_cluster_size_weighted"][q0:]),
                long_lived_fraction=summary["lifetimes"].get("fraction_aggregate_frames_long_lived"),
                rigid_fraction=rigid_fraction(summary),
                hours=float(t[-1]) / 60.0 if len(t) else 0.0)


def series(records: list[dict], measures=MEASURES) -> list[dict]:
    """records: dict(kind, k_a, seed, measures) per run -> one row per (kind, k_a, measure of `measures`): mean,
    sd, n, values."""
    out = []
    for kind in sorted({r["kind"] for r in records}):
        for ka in sorted({r["k_a"] for r in records if r["kind"] == kind}):
            rs = [r for r in records if r["kind"] == kind and r["k_a"] == ka]
            for m in measures:
                v = [r["measures"].get(m) for r in rs if r["measures"].get(m) is not None]
                out.append(dict(kind=kind, k_a_N_m=ka, stiffness=STIFFNESS.get(ka, ""), measure=m,
                                mean=float(np.mean(v)) if v else None,
                                sd=float(np.std(v, ddof=1)) if len(v) > 1 else None, n_seeds=len(v),
                                hours=min(r["measures"]["hours"] for r in rs), values=v))
    return out


def _spearman(x, y) -> float:
    if len(x) < 3:
        return float("nan")
    from scipy.stats import spearmanr
    if np.ptp(np.asarray(y, float)) == 0:
        return 0.0                                          # all equal: no trend
    rho = spearmanr(x, y).statistic
    # Rounded: scipy gives 0.7999999999999999 for one adjacent swap of four, which the rule's ">= 0.8" admits.
    return round(float(rho), 9) if np.isfinite(rho) else 0.0


def _fmt(row) -> str:
    if row is None or row["mean"] is None:
        return "n/a"
    sd = f" ± {row['sd']:.2g}" if row["sd"] is not None else ""
    return f"{row['mean']:.3g}{sd} (n = {row['n_seeds']})"


def _pick(table, kind, measure) -> dict:
    return {r["k_a_N_m"]: r for r in table if r["kind"] == kind and r["measure"] == measure and r["mean"] is not None}


def _short(table, kind, kas) -> str | None:
    """Why the runs cannot support a verdict, or None."""
    hrs = [r["hours"] for r in table if r["kind"] == kind and r["k_a_N_m"] in kas]
    if hrs and min(hrs) < MIN_HOURS:
        return (f"not measurable here: runs of {min(hrs) * 60:.2g} simulated min; the statement is about the "
                f"patterns at 6 h, formed over hours (needs runs of >= {MIN_HOURS:g} h)")
    return None


def _missing(kind: str, need: str, scenes: str) -> str:
    return f"not measurable here: needs {kind} runs at {need} ({scenes})"


def _row(cid, claim, paper, measured, status, values) -> dict:
    return dict(id=cid, claim=claim, paper=paper, measured=measured, status=status, values=values)


def _trend_row(table, kind, measure, cid, claim, paper, scenes, kas=None, sign=1):
    got = _pick(table, kind, measure)
    if kas is not None:
        got = {k: v for k, v in got.items() if k in kas}
    ks = sorted(got)
    measured = "; ".join(f"k_a = {k:g}: {_fmt(got[k])}" for k in ks) or "no runs"
    if len(ks) < 3:
        return _row(cid, claim, paper, measured, _missing(kind, ">= 3 of the four stiffnesses", scenes), got), None
    why = _short(table, kind, ks)
    rho = _spearman(np.log10(ks), [got[k]["mean"] for k in ks])
    ok = sign * rho >= 0.8 and sign * (got[ks[-1]]["mean"] - got[ks[0]]["mean"]) > 0
    measured += f"; Spearman rho against k_a {rho:+.2f}"
    return _row(cid, claim, paper, measured, why or ("consistent" if ok else "not consistent"), got), ok


def stiffness_rows(records: list[dict]) -> list[dict]:
    """The four statements as claims-table rows (id, claim, paper, measured, status, values)."""
    table = series(records, {**MEASURES, **EXTRA_MEASURES})
    rows = []
    row, _ = _trend_row(table, "non-guided", "mean_cluster_size", "stiffness_clusters_non_guided",
                        "Non-guided clusters grow with bending stiffness (mean cluster size against k_a)",
                        "non-guided clusters appear to grow as bending stiffness increases: stiffer cells, larger "
                        "clusters (S2 Fig)", "S2FigA-D; figures S2Fig")
    rows.append(row)
    forming = (1e-18, 1e-17, 1e-16)
    big, ok_big = _trend_row(table, "active", "aggregate_cells", "", "", "", "S3FigA-C", kas=forming)
    few, ok_few = _trend_row(table, "active", "n_aggregates", "", "", "", "S3FigA-C", kas=forming, sign=-1)
    status = big["status"] if ok_big is None else few["status"] if ok_few is None else \
        _short(table, "active", forming) or ("consistent" if ok_big and ok_few else "not consistent")
    rows.append(_row("stiffness_aggregates_larger_fewer",
                     "Active following: stiffer cells form larger and fewer aggregates (very flexible to rigid)",
                     "the size of circular aggregates appears to increase with bending stiffness, and the number "
                     "of aggregates in the domain decreases (S3 Fig)",
                     f"cells per aggregate: {big['measured']}. Aggregates per frame: {few['measured']}", status,
                     dict(aggregate_cells=big["values"], n_aggregates=few["values"])))
    n_agg, cells = _pick(table, "active", "n_aggregates"), _pick(table, "active", "aggregate_cells")
    life = _pick(table, "active", "long_lived_fraction")
    paper = ("very flexible cells form many small and stable circular aggregates (S3A Fig, S6 Video): they easily form "
             "rotation seeds, and the aggregates cannot grow for want of free cells")
    others = [k for k in forming[1:] if k in n_agg and k in cells]
    if 1e-18 not in n_agg or not others:
        rows.append(_row("stiffness_very_flexible_many_small_stable", "Very flexible cells: many small, stable "
                         "aggregates", paper, "no runs", _missing("active", "k_a = 1e-18 and a stiffer k_a",
                                                                  "S3FigA and S3FigB-C"), {}))
    else:
        many = n_agg[1e-18]["mean"] >= max(n_agg[k]["mean"] for k in others)
        small = (cells[1e-18]["mean"] or 0) <= min(cells[k]["mean"] for k in others)
        stable = life.get(1e-18, {}).get("mean")
        good = many and small and stable is not None and stable >= 0.5
        measured = (f"k_a = 1e-18: {_fmt(n_agg[1e-18])} aggregates per frame, {_fmt(cells[1e-18])} cells each, "
                    f"{'n/a' if stable is None else f'{100 * stable:.0f} %'} of aggregate-frames long-lived; "
                    + "; ".join(f"k_a = {k:g}: {_fmt(n_agg[k])} aggregates, {_fmt(cells[k])} cells" for k in others))
        rows.append(_row("stiffness_very_flexible_many_small_stable", "Very flexible cells: many small, stable "
                         "aggregates", paper, measured, _short(table, "active", (1e-18,) + tuple(others)) or
                         ("consistent" if good else "not consistent"),
                         dict(n_aggregates=n_agg, aggregate_cells=cells, long_lived_fraction=life)))
    rows.append(_very_rigid_row(table, n_agg))
    return rows


def _very_rigid_row(table, n_agg) -> dict:
    """stiffness_very_rigid_none (module docstring): the fraction of cells in rigidly rotating aggregates at
    k_a = 1e-15, below VERY_RIGID_MAX_RIGID_FRACTION and below the flexible runs' (1e-17) where measured."""
    cid = "stiffness_very_rigid_none"
    claim = "Very rigid cells: no circular aggregates (cells in rigidly rotating ones)"
    paper = ("very stiff cells do not form circular aggregates (S3D Fig, S7 Video): rigid cells cannot bend and are "
             "unlikely to generate a rotation seed or initiate the rotation of the entire stream")
    frac = _pick(table, "active", "fraction_in_aggregates")
    rig = _pick(table, "active", "rigid_fraction")
    vr, fl = 1e-15, 1e-17
    if vr not in frac:
        return _row(cid, claim, paper, "no runs", _missing("active", "k_a = 1e-15", "S3FigD"), {})

    def at(k):
        r = f"{_fmt(rig[k])} of the cells in rigidly rotating aggregates (α >= {RIGID_EXPONENT:g})" if k in rig \
            else "rigidly rotating: not measurable (no per-frame rigidity exponents kept)"
        return f"k_a = {k:g} ({STIFFNESS[k]}): {r}; {_fmt(frac.get(k))} in any rotating aggregate " \
               f"({_fmt(n_agg.get(k))} aggregates per frame)"
    measured = "; ".join(at(k) for k in (vr, fl) if k in frac)
    values = dict(rigid_fraction=rig.get(vr), fraction_in_aggregates=frac.get(vr), n_aggregates=n_agg.get(vr),
                  flexible_rigid_fraction=rig.get(fl), flexible_fraction_in_aggregates=frac.get(fl))
    if vr not in rig:
        return _row(cid, claim, paper, measured, "not measurable here: the very rigid runs' analyses keep no per-frame "
                    "rigidity exponents (records made before they were kept); claims on their trajectories measure "
                    "them", values)
    why = _short(table, "active", (vr, fl) if fl in rig else (vr,))
    f = rig[vr]["mean"]
    ok = f < VERY_RIGID_MAX_RIGID_FRACTION and (fl not in rig or f < rig[fl]["mean"])
    return _row(cid, claim, paper, measured, why or ("consistent" if ok else "not consistent"), values)


def records_from_runs(runs: list[dict]) -> list[dict]:
    """The claims table's runs (taichimyxo.analysis.claim_runs.load_runs) as stiffness records."""
    out = []
    for r in runs:
        ka = (r.get("scene") or {}).get("cell", {}).get("k_a_N_m")
        if ka is not None and r["kind"] in ("non-guided", "active"):
            out.append(dict(kind=r["kind"], k_a=float(ka), seed=(r.get("scene") or {}).get("run", {}).get("seed"),
                            measures=run_measures(r["summary"])))
    return out
