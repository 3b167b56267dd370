"""Aggregates followed across frames, and the size-independence regression.

Aggregates are linked between analysed frames by nearest centre (a link needs the distance below the larger of the
two radii; gaps of up to ``max_gap_frames`` frames are bridged). Each track seen in >= ``min_track_frames`` frames
gives one point (time means of radius and edge speed); the ordinary least-squares slope of edge speed against
radius, its standard error and t = slope / SE; "consistent with 0" when |t| < 2. Also the exponent of edge speed ~
R^a on log-log axes (0: size-independent edge speed, 1: common angular speed) and the same regression on the
aggregates of the last frame with aggregates."""
from __future__ import annotations

import math

import numpy as np

from ..geometry import min_image
from .stats import ols


def public(a: dict) -> dict:
    """An aggregate dict without its private ('_') entries, the arrays kept for the plots."""
    return {k: v for k, v in a.items() if not k.startswith("_")}


def link_tracks(per_frame: list[list[dict]], L: np.ndarray, max_gap: int) -> list[list[tuple[int, dict]]]:
    """Tracks as lists of (frame index, aggregate): greedy nearest-centre links, closest pairs first."""
    tracks: list[list[tuple[int, dict]]] = []
    for fi, aggs in enumerate(per_frame):
        active = [t for t in tracks if fi - t[-1][0] <= max_gap + 1]
        pairs = []
        for ti, t in enumerate(active):
            last = t[-1][1]
            for ai, a in enumerate(aggs):
                dist = float(np.hypot(*min_image(np.array(a["centre_um"]) - np.array(last["centre_um"]), L)))
                if dist < max(a["radius_um"], last["radius_um"]):
                    pairs.append((dist, ti, ai))
        pairs.sort()
        used_t, used_a = set(), set()
        for dist, ti, ai in pairs:
            if ti in used_t or ai in used_a:
                continue
            used_t.add(ti)
            used_a.add(ai)
            active[ti].append((fi, aggs[ai]))
        for ai, a in enumerate(aggs):
            if ai not in used_a:
                tracks.append([(fi, a)])
    return tracks


def track_summaries(tracks: list[list[tuple[int, dict]]], min_track_frames: int) -> list[dict]:
    """One dict per track: time means, the fraction of frames rigid, the last aggregate and the time series."""
    track_out = []
    for tid, t in enumerate(tracks):
        aa = [a for _, a in t]
        mean = lambda k: float(np.nanmean([a[k] for a in aa]))            # noqa: E731
        track_out.append(dict(
            id=tid, n_frames=len(t), first_time_min=aa[0]["time_min"], last_time_min=aa[-1]["time_min"],
            stable=len(t) >= min_track_frames,
            mean_radius_um=mean("radius_um"), mean_n_cells=mean("n_cells"),
            mean_omega_rad_per_min=mean("omega_rad_per_min"), mean_edge_speed_um_per_min=mean("edge_speed_um_per_min"),
            mean_edge_speed_vb=mean("edge_speed_vb"), mean_r2_origin=mean("r2_origin"),
            fraction_rigid=float(np.mean([a["rigid"] for a in aa])),
            last=public(aa[-1]),
            series=dict(time_min=[a["time_min"] for a in aa], centre_um=[a["centre_um"] for a in aa],
                        radius_um=[a["radius_um"] for a in aa], n_cells=[a["n_cells"] for a in aa],
                        omega_rad_per_min=[a["omega_rad_per_min"] for a in aa],
                        edge_speed_um_per_min=[a["edge_speed_um_per_min"] for a in aa],
                        r2_origin=[a["r2_origin"] for a in aa]),
        ))
    return track_out


def size_regression(R, E) -> dict:
    """Edge speed E (µm/min) against radius R (µm) over aggregates: OLS slope, its t, and the log-log exponent."""
    R, E = np.asarray(R, float), np.asarray(E, float)
    out = ols(R, E)
    out = dict(n_aggregates=len(R), slope_um_per_min_per_um=out["slope"], stderr=out["stderr"],
               intercept_um_per_min=out["intercept"], r2=out["r2"])
    t = out["slope_um_per_min_per_um"] / out["stderr"] if out["stderr"] and math.isfinite(out["stderr"]) \
        else float("nan")
    out["t"] = t
    out["consistent_with_zero"] = bool(abs(t) < 2.0) if math.isfinite(t) else None
    if len(R) >= 2 and math.isfinite(out["slope_um_per_min_per_um"]):
        out["relative_change_over_range"] = out["slope_um_per_min_per_um"] * float(R.max() - R.min()) / float(E.mean())
    good = (R > 0) & (E > 0)
    lg = ols(np.log(R[good]), np.log(E[good])) if good.sum() >= 2 else ols([], [])
    out["loglog_exponent"] = lg["slope"]
    out["loglog_exponent_stderr"] = lg["stderr"]
    return out
