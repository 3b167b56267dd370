"""Numpy reference geometry: closest points of two segments (vectorised), used by the initial configurations and
as the reference the Taichi `closest_points` function is tested against. Same algorithm as the kernel's
(Ericson, Real-Time Collision Detection 5.1.9), with one change: for parallel overlapping segments the closest
points are taken at the middle of the overlap, so the lever rule shares a side-by-side contact symmetrically."""
from __future__ import annotations

import numpy as np

EPS = 1e-12


def closest_points(p1, q1, p2, q2):
    """Segments p1-q1 and p2-q2 (arrays (..., 2)). Returns (s, t, c1, c2, d): parameters in [0, 1] on each segment,
    the closest points and their distance."""
    p1, q1, p2, q2 = (np.asarray(a, dtype=np.float64) for a in (p1, q1, p2, q2))
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = np.sum(d1 * d1, -1)
    e = np.sum(d2 * d2, -1)
    f = np.sum(d2 * r, -1)
    c = np.sum(d1 * r, -1)
    b = np.sum(d1 * d2, -1)
    denom = a * e - b * b
    a_ = np.maximum(a, EPS)
    e_ = np.maximum(e, EPS)
    parallel = denom <= 1e-9 * a_ * e_
    s = np.where(parallel, 0.0, np.clip((b * f - c * e) / np.where(parallel, 1.0, denom), 0.0, 1.0))
    # parallel: middle of the overlap of segment 2's projection onto segment 1
    t0 = np.clip(-c / a_, 0.0, 1.0)                  # projection of p2 onto segment 1
    t1 = np.clip((-c + b) / a_, 0.0, 1.0)            # projection of q2 onto segment 1
    s_par = np.where(a > EPS, 0.5 * (t0 + t1), 0.0)
    s = np.where(parallel, s_par, s)
    t = (b * s + f) / e_
    t = np.where(e > EPS, t, 0.0)
    tc = np.clip(t, 0.0, 1.0)
    s2 = np.where(a > EPS, np.clip((b * tc - c) / a_, 0.0, 1.0), 0.0)
    s = np.where(t != tc, s2, s)
    t = tc
    c1 = p1 + d1 * s[..., None]
    c2 = p2 + d2 * t[..., None]
    d = np.sqrt(np.sum((c1 - c2) ** 2, -1))
    return s, t, c1, c2, d


def min_image(d, box):
    L = np.asarray(box, dtype=np.float64)
    return d - L * np.round(d / L)
