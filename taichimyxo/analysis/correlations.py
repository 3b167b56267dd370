"""Spatial velocity and orientation correlation functions with their correlation lengths, and the cells'
mean-squared displacement with its exponent; averages over frames carry a standard error that allows for correlated
frames (batch means, stats.series_mean_se).

Per frame, over pairs of cells (centres, minimum image) at distance r, in bins of ``dr_um`` up to ``r_max_um``:
- velocity: C_v(r) = <δv_i · δv_j> / <|δv|²>, δv = cell velocity minus the frame's mean (a common drift would
  otherwise never decorrelate); needs stored velocities.
- orientation: C_n(r) = <cos 2(θ_i - θ_j)> of the cells' axes (nematic: head and tail alike).
The pair averages are freud.density.CorrelationFunction with complex values (δv_x + i δv_y, e^{2iθ}; the real part
of conj(a) b is the product needed). The correlation length is where the frame-averaged C first falls below 1/e
(linear interpolation from C(0) = 1; None when it stays above within r_max); its SE comes from the per-frame
lengths.

MSD: cell centres unwrapped through the frames (minimum-image steps), for lags of 1 .. n/2 frames (log-spaced), the
mean over cells per time origin, then the mean over origins with its batch-means SE (overlapping windows are
correlated). The exponent is the log-log least-squares slope over lags up to ``msd_fit_max_fraction`` of the run; its
SE a jackknife over 10 groups of cells. freud.msd.MSD (window mode) gives the same means (tested), but not the
per-origin series the SE needs, so the lags are computed here in numpy. Frames must be equally spaced: the analysis
keeps the longest run of equal intervals from the start (a run's closing frame off the interval is dropped)."""
from __future__ import annotations

import math

import numpy as np

from ..physics.geometry import min_image
from .stats import ols, series_mean_se

CORR_DEFAULTS = dict(dr_um=1.0, r_max_um=25.0, msd_fit_max_fraction=0.25, msd_lags=24)


def _freud_corr(points, values, box, r_max, bins):
    import freud
    L = np.asarray(box, float)
    fb = freud.box.Box(float(L[0]), float(L[1]), is2D=True)
    p = np.zeros((len(points), 3), np.float32)
    p[:, :2] = np.mod(points, L) - L / 2
    cf = freud.density.CorrelationFunction(bins, r_max)
    cf.compute((fb, p), values=np.asarray(values, np.complex128))
    return np.real(cf.correlation).copy()


def frame_correlations(centres, axes, box, velocities=None, **kw) -> dict:
    """One frame's C_n(r) and (with velocities (n, 2)) C_v(r). centres (n, 2), axes (n, 2) unit vectors."""
    P = dict(CORR_DEFAULTS, **kw)
    L = np.asarray(box, float)
    r_max = min(P["r_max_um"], 0.499 * float(L.min()))
    bins = max(1, int(round(r_max / P["dr_um"])))
    e2 = (axes[:, 0] + 1j * axes[:, 1]) ** 2
    out = dict(r_um=(np.arange(bins) + 0.5) * r_max / bins, orientation=_freud_corr(centres, e2, L, r_max, bins))
    if velocities is not None:
        dv = velocities - velocities.mean(0)
        var = float((dv * dv).sum(1).mean())
        z = dv[:, 0] + 1j * dv[:, 1]
        out["velocity"] = _freud_corr(centres, z, L, r_max, bins) / var if var > 0 else np.full(bins, np.nan)
    return out


def correlation_length(r, c, level=1.0 / math.e):
    """First r where c falls below level (linear interpolation from C(0) = 1, which both normalisations give), or
    None when it stays above within r_max."""
    r = np.concatenate([[0.0], np.asarray(r, float)])
    c = np.concatenate([[1.0], np.asarray(c, float)])
    below = np.nonzero(c < level)[0]
    if not len(below) or not np.isfinite(c[below[0] - 1]):
        return None
    k = below[0]
    return float(r[k - 1] + (c[k - 1] - level) / (c[k - 1] - c[k]) * (r[k] - r[k - 1]))


def average_correlations(per_frame: list[dict], key: str) -> dict | None:
    """Frame average of C(r) (key "velocity" or "orientation") with batch-means SE per bin, and the correlation
    length of the average with the SE of the per-frame lengths."""
    rows = [f[key] for f in per_frame if key in f]
    if not rows:
        return None
    C = np.array(rows)
    r = per_frame[0]["r_um"]
    mean_se = [series_mean_se(C[:, b]) for b in range(C.shape[1])]
    lengths = [correlation_length(r, c) for c in C]
    lm, lse, ln = series_mean_se([x for x in lengths if x is not None])
    return dict(r_um=r, C=[m for m, _, _ in mean_se], C_se=[s for _, s, _ in mean_se], n_frames=len(rows),
                length_um=correlation_length(r, [m for m, _, _ in mean_se]), length_frame_mean_um=lm,
                length_se_um=lse, n_frames_with_length=ln)


def uniform_prefix(times) -> int:
    """Number of leading frames equally spaced (to 1e-6 of the interval)."""
    t = np.asarray(times, float)
    if len(t) < 3:
        return len(t)
    d = np.diff(t)
    dt = d[0]
    bad = np.nonzero(np.abs(d - dt) > 1e-6 * max(abs(dt), 1e-12))[0]
    return len(t) if not len(bad) else int(bad[0] + 1)


def unwrap_tracks(wrapped, box) -> np.ndarray:
    """(n_frames, n, 2) positions in the box to continuous tracks (each step the minimum image)."""
    w = np.asarray(wrapped, float)
    steps = min_image(np.diff(w, axis=0), np.asarray(box, float))
    return np.concatenate([w[:1], w[:1] + np.cumsum(steps, axis=0)], axis=0)


def msd(tracks, dt_min, **kw) -> dict:
    """Mean-squared displacement of unwrapped tracks (n_frames, n, 2) frames dt_min apart: per lag the mean and
    batch-means SE over time origins, and the log-log exponent with its jackknife SE (module docstring)."""
    P = dict(CORR_DEFAULTS, **kw)
    X = np.asarray(tracks, float)
    nf, n = X.shape[:2]
    out = dict(lag_min=[], msd_um2=[], msd_se_um2=[], exponent=None, exponent_se=None, fit_max_lag_min=None)
    if nf < 3 or n == 0:
        return out
    lags = np.unique(np.round(np.geomspace(1, max(1, nf // 2), P["msd_lags"])).astype(int))
    groups = np.arange(n) % 10
    per_group = []
    for lag in lags:
        d = X[lag:] - X[:-lag]
        sq = (d * d).sum(2)                               # (origins, cells)
        m, se, _ = series_mean_se(sq.mean(1))
        out["lag_min"].append(float(lag * dt_min))
        out["msd_um2"].append(m)
        out["msd_se_um2"].append(se)
        per_group.append([sq[:, groups != g].mean() for g in range(min(10, n))])
    lag_t = np.array(out["lag_min"])
    fit = lag_t <= max(P["msd_fit_max_fraction"] * nf * dt_min, lag_t[min(1, len(lag_t) - 1)])
    if fit.sum() >= 2:
        y = np.log(np.maximum(out["msd_um2"], 1e-300))
        out["exponent"] = ols(np.log(lag_t[fit]), y[fit])["slope"]
        out["fit_max_lag_min"] = float(lag_t[fit].max())
        G = np.array(per_group)                           # (lags, groups): leave-one-group-out means
        if G.shape[1] >= 2:
            jk = np.array([ols(np.log(lag_t[fit]), np.log(np.maximum(G[fit, g], 1e-300)))["slope"]
                           for g in range(G.shape[1])])
            k = len(jk)
            out["exponent_se"] = float(math.sqrt((k - 1) / k * ((jk - jk.mean()) ** 2).sum()))
    return out
