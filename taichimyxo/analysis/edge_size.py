"""Claim 8, edge speed against aggregate size, judged by the size of the change (docs/measures.md, "Claims judged as
the paper states them"; taichimyxo/analysis/claims.py registers the claim)."""
from __future__ import annotations

import math

import numpy as np

from .claim_runs import plus_minus
from .tracking import size_regression

# Claim 8 (edge speed against aggregate size), docs/measures.md "Claims judged as the paper states them": the tracks
# it reads (aggregates, not seeds of a few cells: mean radius >= 3 µm, tracked >= 10 min), the largest relative
# change of edge speed across their radius range still read as "appears not to depend on the aggregate size", and
# the bootstrap of that change (resamples over tracks, numpy's generator with a fixed seed)
EDGE_SIZE_MIN_RADIUS_UM = 3.0
EDGE_SIZE_MIN_TRACKED_MIN = 10.0
EDGE_SIZE_MAX_EFFECT = 0.25
EDGE_SIZE_MIN_TRACKS = 3
EDGE_SIZE_BOOTSTRAP = 2000
EDGE_SIZE_SEED = 0


def _frame_interval_min(r) -> float:
    t = np.asarray(r["summary"]["timeseries"]["time_min"], float)
    return float(np.median(np.diff(t))) if len(t) > 1 else float("nan")


def tracked_min(t: dict, frame_min: float) -> float:
    """How long a track was followed (min): its lifetime_min, else its frames x the run's frame interval."""
    life = t.get("lifetime_min")
    return float(life) if life is not None else float(t["n_frames"]) * frame_min


def edge_size_tracks(runs) -> tuple[list[dict], dict]:
    """The tracks claim 8 reads: finite mean radius and edge speed, mean radius >= EDGE_SIZE_MIN_RADIUS_UM, tracked
    >= EDGE_SIZE_MIN_TRACKED_MIN. Returns (tracks, counts of those left out: small, short)."""
    keep, out = [], dict(small=0, short=0)
    for r in runs:
        dt = _frame_interval_min(r)
        for t in r["summary"]["tracks"]:
            R, E = t.get("mean_radius_um"), t.get("mean_edge_speed_um_per_min")
            if R is None or E is None or not (math.isfinite(R) and math.isfinite(E)):
                continue
            if R < EDGE_SIZE_MIN_RADIUS_UM:
                out["small"] += 1
            elif not tracked_min(t, dt) >= EDGE_SIZE_MIN_TRACKED_MIN:
                out["short"] += 1
            else:
                keep.append(t)
    return keep, out


def edge_size_effect(R, E, n_boot: int = EDGE_SIZE_BOOTSTRAP, seed: int = EDGE_SIZE_SEED) -> dict:
    """The effect size of edge speed E against radius R over tracks: slope x (R_max - R_min) / mean E (the fitted
    line's change across the radius range, relative), and its bootstrap 95 % interval (tracks resampled with
    replacement; each resample's own slope, range and mean). With size_regression's slope, SE, t."""
    R, E = np.asarray(R, float), np.asarray(E, float)
    out = size_regression(R, E)
    n = len(R)
    eff = out.get("relative_change_over_range", float("nan")) if n >= 2 else float("nan")
    ci = [float("nan"), float("nan")]
    if n >= EDGE_SIZE_MIN_TRACKS and math.isfinite(eff):
        rng = np.random.default_rng(seed)
        idx = rng.integers(0, n, size=(n_boot, n))
        rb, eb = R[idx], E[idx]
        rc = rb - rb.mean(1, keepdims=True)
        sxx = (rc * rc).sum(1)
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = (rc * (eb - eb.mean(1, keepdims=True))).sum(1) / sxx
            b = slope * np.ptp(rb, axis=1) / eb.mean(1)
        b = b[np.isfinite(b)]
        if len(b):
            ci = [float(x) for x in np.percentile(b, [2.5, 97.5])]
    out.update(effect=float(eff), effect_ci95=ci, n_bootstrap=n_boot, bootstrap_seed=seed,
               radius_range_um=[float(R.min()), float(R.max())] if n else None,
               mean_edge_speed_um_per_min=float(E.mean()) if n else float("nan"),
               consistent=bool(abs(eff) < EDGE_SIZE_MAX_EFFECT) if math.isfinite(eff) and n >= EDGE_SIZE_MIN_TRACKS
               else None)
    return out


def judge_kind(label: str, runs) -> tuple[dict, str, bool | None]:
    """One guiding kind's runs: (values, the sentence for the table, consistent or None when too few tracks)."""
    tr, left = edge_size_tracks(runs)
    reg = edge_size_effect([t["mean_radius_um"] for t in tr], [t["mean_edge_speed_um_per_min"] for t in tr])
    reg.update(n_tracks=len(tr), n_left_out_small=left["small"], n_left_out_short=left["short"])
    why = (f"left out: {left['small']} of R < {EDGE_SIZE_MIN_RADIUS_UM:g} µm, {left['short']} tracked < "
           f"{EDGE_SIZE_MIN_TRACKED_MIN:g} min")
    if len(tr) < EDGE_SIZE_MIN_TRACKS:
        return reg, (f"{label}: {len(tr)} track(s) of R >= {EDGE_SIZE_MIN_RADIUS_UM:g} µm tracked >= "
                     f"{EDGE_SIZE_MIN_TRACKED_MIN:g} min, too few ({why})"), None
    lo, hi = reg["effect_ci95"]
    text = (f"{label}: edge speed changes by {100 * reg['effect']:+.0f} % (95 % CI {100 * lo:+.0f} to "
            f"{100 * hi:+.0f} %) of its mean {reg['mean_edge_speed_um_per_min']:.1f} µm/min across R = "
            f"{reg['radius_range_um'][0]:.1f}-{reg['radius_range_um'][1]:.1f} µm over {len(tr)} tracks ({why}); "
            f"slope {plus_minus(reg['slope_um_per_min_per_um'], reg['stderr'], '.3f')} µm/min per µm "
            f"(t = {reg['t']:.1f})")
    return reg, text, reg["consistent"]
