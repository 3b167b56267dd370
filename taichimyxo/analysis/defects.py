"""The coarse-grained nematic field of the cells' segments and its ±½ topological defects, found by winding number,
counted per frame and tracked across frames.

Field: each segment (consecutive particles of a cell, any chain length) adds its length times (cos 2θ, sin 2θ) and its
length to the grid cell holding its midpoint (square-ish cells of side ``spacing``, fitted to the periodic box); both
sums are smoothed by a periodic Gaussian of SD ``smoothing`` µm (scipy.ndimage, mode "wrap"). Where the smoothed
length density is below ``min_density`` of its mean the field is undefined (empty space has no director). The Q tensor
is Q = S (n n - I/2): Qxx = S cos 2ψ / 2, Qxy = S sin 2ψ / 2, with S = |q| / ρ the local order and ψ = arg(q) / 2
the director angle.

Defects: around each plaquette of four grid nodes the wrapped differences of 2ψ are summed; a sum of ±2π is a ±½
defect at the plaquette's centre (a sum of ±4π, ±1, is reported with that charge). A plaquette touching an undefined
node has no defect. Tracking: defects of the same charge in consecutive analysed frames are linked by the
assignment of least total (periodic) distance, a link at most ``max_step_um`` long; a defect missed for a frame ends
its track. Validated on synthetic fields with known ±½ pairs (tests/test_measures.py): positions within one grid cell,
charges exact. freud has no coarse-grained Q field or winding number, so this is numpy and scipy."""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.optimize import linear_sum_assignment

from ..physics.geometry import min_image

FIELD_DEFAULTS = dict(spacing_um=2.5, smoothing_um=5.0, min_density=0.25, max_step_um=10.0)


class OrientationField:
    """The smoothed nematic field on an (nx, ny) grid: q (complex, length-weighted e^{2iθ}), rho (length density),
    S, psi, Qxx, Qxy, defined (bool); node (i, j) sits at ((i + ½) hx, (j + ½) hy)."""

    def __init__(self, q, rho, box, min_density):
        self.q, self.rho = q, rho
        self.L = np.asarray(box, float)
        self.h = self.L / np.array(q.shape)
        mean = rho.mean()
        self.defined = rho > min_density * mean if mean > 0 else np.zeros(q.shape, bool)
        with np.errstate(invalid="ignore", divide="ignore"):
            self.S = np.where(self.defined, np.abs(q) / np.where(rho > 0, rho, 1.0), np.nan)
        self.psi = np.where(self.defined, 0.5 * np.angle(q), np.nan)
        self.Qxx = 0.5 * self.S * np.cos(2 * self.psi)
        self.Qxy = 0.5 * self.S * np.sin(2 * self.psi)

    def nodes(self):
        """(nx, ny, 2) positions of the grid nodes, µm."""
        i, j = np.meshgrid(np.arange(self.q.shape[0]), np.arange(self.q.shape[1]), indexing="ij")
        return np.stack([(i + 0.5) * self.h[0], (j + 0.5) * self.h[1]], axis=-1)


def orientation_field(points, directions, box, spacing_um=FIELD_DEFAULTS["spacing_um"],
                      smoothing_um=FIELD_DEFAULTS["smoothing_um"], min_density=FIELD_DEFAULTS["min_density"],
                      weights=None) -> OrientationField:
    """The field of segments with midpoints ``points`` (n, 2) and directions ``directions`` (n, 2, any length: the
    length is the weight unless ``weights`` are given) in the periodic box."""
    L = np.asarray(box, float)
    nxy = np.maximum(np.round(L / spacing_um).astype(int), 4)
    h = L / nxy
    p = np.mod(np.asarray(points, float), L)
    d = np.asarray(directions, float)
    ln = np.hypot(d[:, 0], d[:, 1])
    w = ln if weights is None else np.asarray(weights, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        e2 = ((d[:, 0] + 1j * d[:, 1]) / np.where(ln > 0, ln, 1.0)) ** 2
    ix = np.minimum((p[:, 0] / h[0]).astype(int), nxy[0] - 1)
    iy = np.minimum((p[:, 1] / h[1]).astype(int), nxy[1] - 1)
    k = ix * nxy[1] + iy
    m = int(nxy[0] * nxy[1])
    qr = np.bincount(k, w * e2.real, m).reshape(nxy)
    qi = np.bincount(k, w * e2.imag, m).reshape(nxy)
    rho = np.bincount(k, w, m).reshape(nxy)
    sig = smoothing_um / h
    qr, qi, rho = (gaussian_filter(a, sig, mode="wrap") for a in (qr, qi, rho))
    return OrientationField(qr + 1j * qi, rho, L, min_density)


def segments(positions, box):
    """Midpoints (M, 2) and vectors (M, 2) of every segment of cells positions (n, N, 2) (chains unwrapped)."""
    pos = np.asarray(positions, float)
    mid = 0.5 * (pos[:, 1:] + pos[:, :-1])
    vec = pos[:, 1:] - pos[:, :-1]
    return np.mod(mid.reshape(-1, 2), np.asarray(box, float)), vec.reshape(-1, 2)


def frame_field(positions, box, **kw) -> OrientationField:
    """The field of one frame's cells (positions (n, N, 2))."""
    mid, vec = segments(positions, box)
    return orientation_field(mid, vec, box, **kw)


def find_defects(field: OrientationField) -> tuple[np.ndarray, np.ndarray]:
    """Defects of the field: positions (k, 2) µm and charges (k,) (±0.5, ±1, ...), by winding number."""
    a = np.angle(field.q)                          # 2ψ
    ok = field.defined

    def wrap(x):
        return (x + np.pi) % (2 * np.pi) - np.pi

    a10 = np.roll(a, -1, 0)
    a11 = np.roll(a10, -1, 1)
    a01 = np.roll(a, -1, 1)
    tot = wrap(a10 - a) + wrap(a11 - a10) + wrap(a01 - a11) + wrap(a - a01)
    good = ok & np.roll(ok, -1, 0) & np.roll(ok, -1, 1) & np.roll(np.roll(ok, -1, 0), -1, 1)
    w = np.rint(tot / (2 * np.pi)).astype(int)
    i, j = np.nonzero(good & (w != 0))
    u, v = _zero_in_plaquette(field.q, i, j)
    pos = np.stack([(i + 0.5 + u) * field.h[0], (j + 0.5 + v) * field.h[1]], axis=1) % field.L
    return pos.reshape(-1, 2), 0.5 * w[i, j]


def _zero_in_plaquette(q, i, j, iters=8):
    """Where the bilinear interpolation of q over the plaquette (i, j) .. (i+1, j+1) vanishes, (u, v) in [0, 1]²
    (Newton from its centre): the core lies inside the plaquette whose loop winds, so this only refines it."""
    nx, ny = q.shape
    a, b = q[i, j], q[(i + 1) % nx, j]
    c, d = q[i, (j + 1) % ny], q[(i + 1) % nx, (j + 1) % ny]
    u = np.full(len(i), 0.5)
    v = np.full(len(i), 0.5)
    for _ in range(iters):
        f = a * (1 - u) * (1 - v) + b * u * (1 - v) + c * (1 - u) * v + d * u * v
        fu = (b - a) * (1 - v) + (d - c) * v
        fv = (c - a) * (1 - u) + (d - b) * u
        det = fu.real * fv.imag - fv.real * fu.imag
        det = np.where(np.abs(det) > 1e-300, det, 1e-300)
        du = (f.real * fv.imag - fv.real * f.imag) / det
        dv = (fu.real * f.imag - f.real * fu.imag) / det
        u = np.clip(u - du, 0.0, 1.0)
        v = np.clip(v - dv, 0.0, 1.0)
    return u, v


def track_defects(per_frame, box, max_step_um=FIELD_DEFAULTS["max_step_um"]) -> list[np.ndarray]:
    """Track ids for per_frame [(positions (k, 2), charges (k,)), ...]: same id = the same defect. A defect links to
    one of the same charge in the previous frame by least total periodic distance, at most max_step_um away."""
    L = np.asarray(box, float)
    ids, prev, nxt = [], None, 0
    for pos, q in per_frame:
        cur = np.full(len(q), -1, int)
        if prev is not None and len(q) and len(prev[1]):
            ppos, pq, pid = prev
            d = np.linalg.norm(min_image(pos[:, None, :] - ppos[None, :, :], L), axis=2)
            d[q[:, None] != pq[None, :]] = np.inf
            big = 1e9
            r, c = linear_sum_assignment(np.where(d <= max_step_um, d, big))
            keep = d[r, c] <= max_step_um
            cur[r[keep]] = pid[c[keep]]
        new = cur < 0
        cur[new] = nxt + np.arange(new.sum())
        nxt += int(new.sum())
        ids.append(cur)
        prev = (pos, q, cur)
    return ids

