"""Numpy reference geometry: closest points of two segments (vectorised), used by the initial configurations and
as the reference the Taichi `closest_points` function is tested against. Same algorithm as the kernel's
(Ericson, Real-Time Collision Detection 5.1.9), with one change: for parallel overlapping segments the closest
points are taken at the middle of the overlap, so the lever rule shares a side-by-side contact symmetrically."""
from __future__ import annotations

import numpy as np

# A segment outside (1 +- 0.5) l0 means the chain blew up: frames check it (writers.check_positions), and the
# neighbour grid is sized for segments up to 1.5 l0 and checks it at every build (neighbours.LENGTH_BOUND). Defined
# here, in a module that does not import taichi, so `import taichimyxo` stays light (tests/test_api.py).
SEGMENT_LENGTH_TOL = 0.5

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


def contact_samples(pos):
    """The points where the contact law samples each cell (docs/model.md "Contacts"): its particles and its segment
    midpoints, every l0 / 2 along the cell. Returns (points (n, 2N - 1, 2), weights (2N - 1,), index along the cell
    in half-segments (2N - 1,)). Weight 1/4, the two poles 1/2."""
    pos = np.asarray(pos, dtype=np.float64)
    n, N = pos.shape[:2]
    pts = np.empty((n, 2 * N - 1, 2))
    pts[:, 0::2] = pos
    pts[:, 1::2] = 0.5 * (pos[:, 1:] + pos[:, :-1])
    return pts, sample_weights(N), np.arange(2 * N - 1)


def sample_weights(N: int) -> np.ndarray:
    """Contact weight of each of a cell's 2N - 1 samples: 1/4, the two poles 1/2 (docs/model.md term 4)."""
    w = np.full(2 * N - 1, 0.25)
    w[0] = w[-1] = 0.5
    return w


def sample_polyline_contacts(pos, box, W: float, segments: bool = False):
    """Every sample point in contact with another chain, in plain numpy, written from the definition of the contact
    energy (docs/model.md, "Contacts") and independently of the kernels: for each sample p (contact_samples) and
    each chain B it may touch (another cell; its own cell's segments at least 1.5 segments away along the cell), the
    distance from p to the polyline B, i.e. to B's nearest segment, when below W. Chains are unwrapped (n, N, 2).
    Returns (sample cell, sample index, chain, d) arrays, with `segments` also the nearest segment's index (cell
    (N - 1) + k). One contact per sample and chain: a chain folded round a sample (touching it twice) counts once
    here, where the kernels count each locally nearest segment."""
    pos = np.asarray(pos, dtype=np.float64)
    L = np.asarray(box, dtype=np.float64)
    n, N = pos.shape[:2]
    pts, _, hidx = contact_samples(pos)
    X = pts.reshape(-1, 2)
    x_cell, x_h = np.divmod(np.arange(len(X)), 2 * N - 1)
    a = pos[:, :-1].reshape(-1, 2)
    e = (pos[:, 1:] - pos[:, :-1]).reshape(-1, 2)
    mid = a + 0.5 * e
    reach = 0.5 * np.linalg.norm(e, axis=-1).max(initial=0.0) + W
    seg_cell, seg_k = np.divmod(np.arange(len(a)), N - 1)
    # candidates: samples within reach of a segment's midpoint (a periodic k-d tree, sorted per sample)
    from scipy.spatial import cKDTree

    def wrap(y):                                  # into [0, L) as the periodic tree needs (mod can round up to L)
        y = np.mod(y, L)
        return np.where(y >= L, 0.0, y)
    found = cKDTree(wrap(mid), boxsize=L).query_ball_point(wrap(X), reach, return_sorted=True)
    ii = np.repeat(np.arange(len(X)), [len(f) for f in found])
    jj = np.fromiter((j for f in found for j in f), dtype=np.int64, count=len(ii))
    own = x_cell[ii] == seg_cell[jj]
    ok = ~own | (x_h[ii] - (2 * seg_k[jj] + 2) >= 3) | (2 * seg_k[jj] - x_h[ii] >= 3)
    ii, jj = ii[ok], jj[ok]
    e0 = min_image(a[jj] - X[ii], L)
    ee = np.maximum((e[jj] ** 2).sum(-1), EPS)
    u = np.clip(-(e0 * e[jj]).sum(-1) / ee, 0.0, 1.0)
    d = np.linalg.norm(e0 + u[:, None] * e[jj], axis=-1)
    near = d < W
    c, h, b, d, j = x_cell[ii[near]], x_h[ii[near]], seg_cell[jj[near]], d[near], jj[near]
    order = np.lexsort((d, b, h, c))              # nearest segment first within each (sample, chain)
    c, h, b, d, j = c[order], h[order], b[order], d[order], j[order]
    first = np.ones(len(c), bool)
    first[1:] = (c[1:] != c[:-1]) | (h[1:] != h[:-1]) | (b[1:] != b[:-1])
    out = c[first], h[first], b[first], d[first]
    return (*out, j[first]) if segments else out


def contact_energy(pos, box, W: float, k_c: float) -> float:
    """The contact energy (pN·µm): sum over samples p and chains B of w_p k_c / 2 (W - D)^2, D the distance from
    the sample to the chain (see sample_polyline_contacts)."""
    _, h, _, d = sample_polyline_contacts(pos, box, W)
    w = sample_weights(np.asarray(pos).shape[1])
    return float(0.5 * k_c * (w[h] * (W - d) ** 2).sum())


def segment_strain(pos, box, W: float, k_c: float) -> np.ndarray:
    """(n, N - 1) strain energy per segment, pN·µm, the numpy twin of terms/strain.py: each sample contact's energy
    w k_c (W - d)^2 / 2, half to the segment pressed, half to the sample's own (a particle's half split between the
    two segments meeting there, a pole's to its one segment). For a frame whose run did not log strain."""
    pos = np.asarray(pos, dtype=np.float64)
    n, N = pos.shape[:2]
    c, h, _, d, seg = sample_polyline_contacts(pos, box, W, segments=True)
    e = 0.5 * k_c * sample_weights(N)[h] * (W - d) ** 2
    out = np.zeros(n * (N - 1))
    np.add.at(out, seg, 0.5 * e)
    base = c * (N - 1)
    mid = h % 2 == 1
    np.add.at(out, base[mid] + (h[mid] - 1) // 2, 0.5 * e[mid])
    k = h[~mid] // 2                              # a particle sample: particle k, between segments k - 1 and k
    pole = (k == 0) | (k == N - 1)
    share = np.where(pole, 0.5, 0.25) * e[~mid]
    np.add.at(out, base[~mid] + np.minimum(k, N - 2), share)
    inner = ~pole
    np.add.at(out, base[~mid][inner] + k[inner] - 1, share[inner])
    return out.reshape(n, N - 1)
