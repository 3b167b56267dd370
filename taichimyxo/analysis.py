"""Quantify what the movies show: clusters, rotating aggregates, speed and strain profiles (issue 6).

The paper's central testable prediction (Janulevicius et al. 2015, "Circular aggregates as rigid bodies"): aggregates
formed by short-range guiding rotate as rigid bodies, so cell speed grows linearly with the distance from the centre,
the edge speed exceeds v_b (4/3 v_b for adhesion, up to 4 v_b for active following) and does not depend on the
aggregate size; aggregates formed by slime trails move at about v_b everywhere. `analyze()` turns a trajectory into
those numbers (a JSON file) and plots (PNG).

Public API
----------
- ``analyze(gsd_path, out_dir=None, every=1, v_b=None, plots=True, **params) -> dict``: reads the trajectory, writes
  ``<stem>.analysis.json`` and ``<stem>.analysis.<name>.png`` next to it (or in ``out_dir``), returns the summary.
- ``analyze_frames(frames, v_b=4.0, **params) -> dict``: the same on an iterable of ``Frame`` (no files).
- ``format_summary(summary) -> str``: a short human-readable report.
- ``main_analyze(argv) -> int``: ``python -m taichimyxo analyze FILE.gsd [--out DIR] [--every K] [--v-b V]``.
- Building blocks, usable on their own: ``contact_pairs``, ``connected_components``, ``cell_clusters``,
  ``find_aggregates`` (one frame).
- ``synthetic_frames(...)``: trajectories with known answers (rotating disks, straight streams, a gas), used by the
  tests and the timing benchmark.

Definitions, criteria and thresholds (all defaults in ``DEFAULTS``; every one can be overridden by keyword)
-------------------------------------------------------------------------------------------------------
Everything is periodic (minimum image in the box (Lx, Ly)); positions are µm, speeds µm/min, times min.

Per cell: centre = mean of its particles (wrapped into the box); heading = k_e (p_0 - p_{N-1}) normalised (tail to
head); per-particle forward tangent = -k_e d p / d i (central differences along the chain); cell speed = mean of its
particle speeds (the logged, window-averaged speeds). Velocities are taken as speed x heading (not from finite
differences between frames: at one frame per minute an aggregate edge turns by up to ~1 rad between frames).

Contacts and clusters. Two cells touch when any particle of one is closer than ``W + contact_tol_um`` (0.3 µm) to any
particle of the other (minimum image; found with a numpy cell list). With particles l0 = 0.64 µm apart this catches
every pair whose outlines touch or overlap (segment distance <= W needs particle distance <= sqrt(W^2 + l0^2/2) =
0.68 µm < 0.8 µm) and most pairs within the guiding range d_g = 0.25 µm. Clusters = connected components of the
contact graph (numpy union-find by hooking and pointer jumping).

Circular aggregates, per frame:
1. Candidates (Hough vote). Every cell in a cluster of >= ``min_cells`` (10) cells votes along its normal line: if it
   circulates counter-clockwise around a centre c at distance r, then c = x + r n (n = heading turned +90°); clockwise,
   c = x - r n. Votes for 0 < r <= ``max_radius_um`` (40 µm, at most 0.45 of the box) go into two periodic grids of
   ``hough_bin_um`` (1 µm) bins (one vote per bin length along the line), one per sense, smoothed over 3 x 3 bins
   and normalised so that a peak counts the
   cells whose normal passes within ~1.5 bins. Local maxima with at least ``0.5 min_cells`` votes are candidates
   (at most ``max_candidates``, strongest first).
2. Radius by an outward ring walk around the candidate centre, rings ``ring_um`` (= 2 W = 1 µm) wide, counting
   particles: a ring is "good" when its area occupancy (particles x L W / N over the ring area) is >= ``min_occupancy``
   (0.25) and >= ``min_ring_circulating`` (50 %) of its particles have a forward tangent within 36.9° of the
   tangential direction of the candidate's sense (cos >= ``cos_tangent`` = 0.8), rings inside ``core_radius_um``
   (L/2 = 2.5 µm) being exempt from the tangential test. The walk starts at the first occupied ring (hollow aggregates
   are allowed) and stops where ``ring_gap`` + 1 (2) consecutive rings are not good (a single bad ring, a void or a
   joining stream, is bridged); the outer edge of the last good ring is R_edge. Members: cells that belong to no
   aggregate accepted earlier in the frame and whose centre is within R_edge, or within R_edge + ring_um when the cell
   is circulating (the partly filled outer layer).
3. Accepted when: >= ``min_cells`` members; among members whose centre is outside the core, >= ``min_circulating``
   (60 %) are circulating (heading within 36.9° of the tangent, consistent sense: |cos(heading, radial)| <= 0.6); and
   circulating members cover >= ``min_octants`` (6) of the 8 octants around the centre (rejects a curved stream); and
   so many circulating cells are unlikely by chance: the binomial tail P(>= k circulating of n | p0), p0 = acos(0.8)
   / pi = 0.205 the chance for a randomly oriented cell, is <= ``max_p_value`` (1e-8) (rejects chance vortices in a
   dense random gas, where the centre and radius are otherwise tuned to the noise; there, false candidates had
   p >= 1e-6). A perfect aggregate needs >= 12 cells outside the core (0.205^12 = 5e-9).
4. Centre refined (up to 4 times) as the least-squares point on the normal lines of the circulating members,
   c = argmin sum_i ((c - x_i) . h_i)^2 (speed- and rigidity-free, so it works for slime aggregates with uniform
   speed); the walk and tests are redone at the refined centre.

Per aggregate: centre (wrapped into the box); radius R = sqrt(2 <r^2> - a^2) over member particles, a = their 2nd
percentile distance (the outer radius of a uniform disk or annulus a..R with the same second moment; a is reported as
the inner radius, R_edge, the ring-walk radius, too); number of cells; sense; angular speed
from tangential velocities omega_tan = sum r v_t / sum r^2 over member particles (v_t = speed x (tangent . phi-hat),
signed, > 0 counter-clockwise, rad/min); the rigid-body test: particle speed against r, least-squares line through the
origin (slope omega_fit, R^2 = 1 - SS_res / SS_tot about the mean) and with intercept (slope, intercept, R^2, standard
error of the slope with the number of cells as the number of independent samples); ``rigid`` when R^2 (origin) >= 0.5
and omega_fit / |omega_tan| is within [0.75, 1.33]. Edge speed = mean speed of the outer ``edge_fraction`` (20 %) of
member cells by centre distance (also as edge_speed / v_b) and the rigid extrapolation omega_fit R.

Across aggregates (the size-independence prediction): aggregates are linked between analysed frames by nearest centre
(a link needs the distance below the larger of the two radii; gaps of up to ``max_gap_frames`` frames are bridged).
Each track seen in >= ``min_track_frames`` frames gives one point (time means of radius and edge speed); the ordinary
least-squares slope of edge speed against radius, its standard error and t = slope / SE; "consistent with 0" when
|t| < 2. Also the exponent of edge speed ~ R^a on log-log axes (0: size-independent edge speed, 1: common angular
speed) and the same regression on the aggregates of the last frame with aggregates.

``predictions.verdict`` condenses this: rigid rotation (>= 50 % of aggregate-frames rigid), edge faster than v_b (mean
edge speed / v_b over tracks > 1.15), size-independent edge speed (|t| < 2 with >= 3 tracks).

Frames whose particle speeds are all zero (the first frame of a run, before the speed window has elapsed) count for
the cluster, order and aggregate-number time series but not for speeds, tracks or profiles (meta lists their times).

Also reported: cluster statistics and size distribution over time; mean speed; polar and nematic order (global, and
local = mean over touching pairs); speed histograms of cells inside and outside aggregates; speed and strain energy
profiles against r / R pooled over aggregates and frames (strain only when logged; strain inner (r < R/2) over outer).

Cost: per frame O(particles) numpy (cell list, bincounts, a few dozen candidate walks): about 35 ms of CPU for
2000 cells x 8 particles, so a 6-hour, 360-frame paper-scale trajectory takes ~12 s (+1.5 s for the plots) on one core.

Limitations: velocities are speed x heading, so a cell pushed sideways or backwards in a jammed core is counted as
moving along its heading; two counter-rotating aggregates that touch like gears can exchange a few edge cells (their
edges move in parallel at the contact), which shifts centres by ~0.1 µm; a perfect aggregate needs >= 12 cells outside
its core to pass the chance test; aggregate identities across frames use nearest centres only (merging and splitting
aggregates end and start tracks).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import warnings
from typing import Iterable, Iterator

import numpy as np

from .frame import Frame

DEFAULTS = dict(
    contact_tol_um=0.3,        # contact when particle distance < W + tol
    min_cells=10,              # smallest cluster that votes / smallest aggregate
    max_radius_um=40.0,        # largest aggregate radius searched (clamped to 0.45 of the box)
    hough_bin_um=1.0,          # Hough grid bin
    ring_um=None,              # ring-walk ring width; None: 2 W
    core_radius_um=None,       # core exempt from the tangential test; None: L / 2
    min_occupancy=0.25,        # ring area occupancy needed to continue the walk
    cos_tangent=0.8,           # heading within acos(0.8) = 36.9° of the tangent counts as circulating
    min_ring_circulating=0.5,  # fraction of a ring's particles circulating
    ring_gap=1,                # the walk bridges this many consecutive bad rings when a good one follows
    min_circulating=0.6,       # fraction of (non-core) member cells circulating
    min_octants=6,             # octants covered by circulating members
    max_p_value=1e-8,          # chance that randomly oriented cells circulate that well (binomial tail)
    edge_fraction=0.2,         # outer fraction of member cells (by radius) that defines the edge speed
    max_candidates=40,         # Hough candidates verified per frame
    max_gap_frames=2,          # tracking: analysed frames an aggregate may be missed
    min_track_frames=3,        # tracking: frames a track needs to enter the across-aggregate regression
    speed_hist_max=24.0,       # µm/min, upper edge of the speed histograms
    speed_hist_bin=0.5,        # µm/min
)

PAPER = {
    "v_b_um_per_min": 4.0,
    "edge_speed_vb_adhesion_rigid_disk": 4.0 / 3.0,
    "edge_speed_vb_active_following_max": 4.0,
    "edge_speed_vb_slime_trails": 1.0,
}

_RBINS = np.linspace(0.0, 1.3, 14)   # r / R bins of the pooled profiles


# ------------------------------------------------------------------------------------------------- small helpers
def _mi(d: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Minimum image of displacement(s) d (..., 2)."""
    return d - L * np.round(d / L)


def _clean(o):
    """JSON-safe: numpy to Python, non-finite floats to None."""
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    if isinstance(o, (np.bool_, bool)):
        return bool(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        f = float(o)
        return float(f"{f:.7g}") if math.isfinite(f) else None
    return o


def _ols(x, y):
    """Ordinary least squares y = a + b x. Returns dict(slope, intercept, stderr, r2, n) (NaN where undefined)."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    n = len(x)
    out = dict(slope=float("nan"), intercept=float("nan"), stderr=float("nan"), r2=float("nan"), n=n)
    if n < 2:
        return out
    xm, ym = x.mean(), y.mean()
    sxx = float(((x - xm) ** 2).sum())
    if sxx <= 0:
        return out
    b = float(((x - xm) * (y - ym)).sum() / sxx)
    a = float(ym - b * xm)
    res = y - a - b * x
    ssr = float((res ** 2).sum())
    sst = float(((y - ym) ** 2).sum())
    out.update(slope=b, intercept=a, r2=(1.0 - ssr / sst) if sst > 0 else float("nan"))
    if n > 2:
        out["stderr"] = math.sqrt(ssr / (n - 2) / sxx)
    return out


# ------------------------------------------------------------------------------------------------- contacts, clusters
def contact_pairs(points: np.ndarray, box, rc: float) -> tuple[np.ndarray, np.ndarray]:
    """All pairs (i < j) of points closer than rc under minimum image, with a numpy cell list.

    points (P, 2) in µm (any image; wrapped here). Returns two int arrays i, j."""
    L = np.asarray(box, float)
    p = np.mod(np.asarray(points, float), L)
    P = len(p)
    if P < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    nb = np.floor(L / rc).astype(np.int64)
    if (nb < 3).any():   # tiny box: brute force
        i, j = np.triu_indices(P, 1)
        d = _mi(p[j] - p[i], L)
        keep = (d * d).sum(1) < rc * rc
        return i[keep], j[keep]
    bsz = L / nb
    ix = np.minimum((p[:, 0] / bsz[0]).astype(np.int64), nb[0] - 1)
    iy = np.minimum((p[:, 1] / bsz[1]).astype(np.int64), nb[1] - 1)
    b = ix * nb[1] + iy
    order = np.argsort(b, kind="stable")
    counts = np.bincount(b, minlength=int(nb[0] * nb[1]))
    starts = np.cumsum(counts) - counts
    I, J = [], []
    ar = np.arange(P)
    rc2 = rc * rc
    for dx, dy in ((0, 0), (1, -1), (1, 0), (1, 1), (0, 1)):      # half shell
        nbb = ((ix + dx) % nb[0]) * nb[1] + (iy + dy) % nb[1]
        cnt = counts[nbb]
        tot = int(cnt.sum())
        if tot == 0:
            continue
        ii = np.repeat(ar, cnt)
        offs = np.arange(tot) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        jj = order[np.repeat(starts[nbb], cnt) + offs]
        if dx == 0 and dy == 0:
            m = jj > ii
            ii, jj = ii[m], jj[m]
        d = _mi(p[jj] - p[ii], L)
        m = (d * d).sum(1) < rc2
        I.append(ii[m])
        J.append(jj[m])
    if not I:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = np.concatenate(I), np.concatenate(J)
    return np.minimum(i, j), np.maximum(i, j)


def connected_components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Component labels 0..k-1 (n,) of the undirected graph with edges (a, b): union-find by hooking roots to the
    smaller root and pointer jumping, all numpy."""
    lab = np.arange(n)
    a = np.asarray(a, np.int64)
    b = np.asarray(b, np.int64)
    while len(a):
        la, lb = lab[a], lab[b]
        m = la != lb
        if not m.any():
            break
        a, b, la, lb = a[m], b[m], la[m], lb[m]
        np.minimum.at(lab, np.maximum(la, lb), np.minimum(la, lb))
        while True:
            nl = lab[lab]
            if np.array_equal(nl, lab):
                break
            lab = nl
    return np.unique(lab, return_inverse=True)[1].reshape(n)


def cell_clusters(positions: np.ndarray, box, width: float, tol: float = DEFAULTS["contact_tol_um"]):
    """Clusters of touching cells. positions (n_cells, N, 2). Returns (labels (n,), sizes (k,), pair_i, pair_j) with
    pair_i/j the touching particle pairs expressed as cell indices (one entry per close particle pair)."""
    n, N = positions.shape[:2]
    i, j = contact_pairs(positions.reshape(-1, 2), box, width + tol)
    ci, cj = i // N, j // N
    m = ci != cj
    ci, cj = ci[m], cj[m]
    lab = connected_components(n, ci, cj)
    return lab, np.bincount(lab), ci, cj


# ------------------------------------------------------------------------------------------------- per-frame geometry
class _Geo:
    """Per-frame cell geometry (all numpy)."""

    def __init__(self, fr: Frame):
        pos = np.asarray(fr.positions, float)
        self.L = np.asarray(fr.box, float)
        self.n, self.N = pos.shape[:2]
        self.W = float(fr.width_um)
        self.t_min = float(fr.time_s) / 60.0
        ke = np.where(np.asarray(fr.engine_direction).reshape(-1) >= 0, 1.0, -1.0)
        self.ke = ke
        cen_raw = pos.mean(axis=1)
        self.cen = np.mod(cen_raw, self.L)
        self.poff = pos - cen_raw[:, None, :]
        self.pos = pos
        h = ke[:, None] * (pos[:, 0] - pos[:, -1])
        hn = np.linalg.norm(h, axis=1)
        self.head = h / np.where(hn > 0, hn, 1.0)[:, None]
        if self.N > 1:
            g = -ke[:, None, None] * np.gradient(pos, axis=1)
            gn = np.linalg.norm(g, axis=2)
            self.ptan = g / np.where(gn > 0, gn, 1.0)[..., None]
            seg = np.linalg.norm(np.diff(pos, axis=1), axis=2)
            self.chain = float(np.median(seg.sum(1))) if self.n else 0.0
            self.l0 = self.chain / (self.N - 1)
        else:
            self.ptan = self.head[:, None, :].copy()
            self.chain, self.l0 = 0.0, 0.0
        self.cell_len = self.chain + self.W            # outline length L
        self.pspeed = np.asarray(fr.particle_speed, float).reshape(self.n, self.N)
        self.cspeed = self.pspeed.mean(axis=1)
        self.strain = None if fr.segment_strain is None else np.asarray(fr.segment_strain, float)


# ------------------------------------------------------------------------------------------------- aggregates
def _params(**kw):
    p = dict(DEFAULTS)
    unknown = set(kw) - set(p)
    if unknown:
        raise TypeError(f"unknown analysis parameter(s): {sorted(unknown)}")
    p.update(kw)
    return p


def _hough_candidates(geo: _Geo, voters: np.ndarray, P: dict, Lam: float):
    L = geo.L
    nbx, nby = (max(3, int(round(L[k] / P["hough_bin_um"]))) for k in (0, 1))
    hx, hy = L[0] / nbx, L[1] / nby
    h = min(hx, hy)
    x = geo.cen[voters]
    hd = geo.head[voters]
    nrm = np.stack([-hd[:, 1], hd[:, 0]], axis=1)
    step = h
    lam = np.arange(0.5 * step, Lam + 1e-9, step)
    cands = []
    if len(x) == 0 or len(lam) == 0:
        return cands
    for sense in (1, -1):
        pts = x[:, None, :] + sense * lam[None, :, None] * nrm[:, None, :]
        pts = np.mod(pts.reshape(-1, 2), L)
        bx = np.minimum((pts[:, 0] / hx).astype(np.int64), nbx - 1)
        by = np.minimum((pts[:, 1] / hy).astype(np.int64), nby - 1)
        acc = np.bincount(bx * nby + by, minlength=nbx * nby).reshape(nbx, nby).astype(float)
        acc *= step / (3.0 * h)                   # a line through a 3x3 window adds ~1
        sm = acc.copy()
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                if dx or dy:
                    sm += np.roll(np.roll(acc, dx, 0), dy, 1)
        peak = sm >= 0.5 * P["min_cells"]
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                if dx or dy:
                    peak &= sm >= np.roll(np.roll(sm, dx, 0), dy, 1)
        kx, ky = np.nonzero(peak)
        hts = sm[kx, ky]
        top = np.argsort(-hts, kind="stable")[: P["max_candidates"]]
        for q in top:
            a, b_ = kx[q], ky[q]
            # sub-bin centre: vote-weighted mean over the 3x3 window
            w = acc[np.ix_((a + np.arange(-1, 2)) % nbx, (b_ + np.arange(-1, 2)) % nby)]
            off = np.array([-1.0, 0.0, 1.0])
            sw = w.sum()
            cx = (a + 0.5 + (w.sum(1) @ off) / sw) * hx
            cy = (b_ + 0.5 + (w.sum(0) @ off) / sw) * hy
            cands.append((float(hts[q]), sense, np.mod(np.array([cx, cy]), L)))
    cands.sort(key=lambda c: -c[0])
    return cands[: P["max_candidates"]]


def _walk(geo: _Geo, c: np.ndarray, sense: int, free: np.ndarray, P: dict, Lam: float):
    """Ring walk and acceptance tests at centre c. Returns (ok, info dict). Tries a 16 µm search radius first and
    repeats with Lam only when the walk reaches it."""
    d = _mi(geo.cen - c, geo.L)
    lam0 = min(Lam, 16.0)
    ok, info = _walk_r(geo, d, sense, free, P, lam0)
    if lam0 < Lam and info is not None and info["R_edge"] >= lam0 - 2 * P["ring_um"]:
        ok, info = _walk_r(geo, d, sense, free, P, Lam)
    return ok, info


def _walk_r(geo: _Geo, d: np.ndarray, sense: int, free: np.ndarray, P: dict, Lam: float):
    r = np.hypot(d[:, 0], d[:, 1])
    near = np.nonzero(free & (r < Lam + 0.5 * geo.cell_len))[0]
    if len(near) < P["min_cells"]:
        return False, None
    rp = d[near, None, :] + geo.poff[near]                       # (k, N, 2) particles relative to c
    rpn = np.hypot(rp[..., 0], rp[..., 1])
    safe = np.where(rpn > 0, rpn, 1.0)
    ap = sense * (geo.ptan[near, :, 0] * -rp[..., 1] + geo.ptan[near, :, 1] * rp[..., 0]) / safe
    dr = P["ring_um"]
    nring = int(math.ceil(Lam / dr))
    ring = (rpn / dr).astype(np.int64).ravel()
    ok_r = ring < nring
    cnt = np.bincount(ring[ok_r], minlength=nring)[:nring].astype(float)
    circ = np.bincount(ring[ok_r], weights=(ap.ravel()[ok_r] >= P["cos_tangent"]).astype(float),
                       minlength=nring)[:nring]
    k = np.arange(nring)
    area = math.pi * dr * dr * (2 * k + 1)
    occ = cnt * (geo.cell_len * geo.W / geo.N) / area
    frac = circ / np.maximum(cnt, 1.0)
    core = P["core_radius_um"]
    good = (occ >= P["min_occupancy"]) & ((frac >= P["min_ring_circulating"]) | ((k + 1) * dr <= core))
    occd = np.nonzero(occ >= P["min_occupancy"])[0]
    if len(occd) == 0 or not good[occd[0]]:
        return False, None
    start = occd[0]
    g = good[start:]
    gap = int(P["ring_gap"])
    if gap > 0:       # bridge runs of up to `gap` bad rings followed by a good one
        run = np.ones(len(g), bool)
        for q in range(gap + 1):
            run &= np.concatenate([~g[q:], np.ones(q, bool)])     # rings q.. q+gap all bad
        stop = np.nonzero(run)[0]
        last_good = np.nonzero(g[: stop[0]] if len(stop) else g)[0]
    else:
        bad = np.nonzero(~g)[0]
        last_good = np.nonzero(g[: bad[0]] if len(bad) else g)[0]
    end = start + int(last_good[-1]) + 1                          # one past the last good ring
    R_edge = end * dr
    dn, rn = d[near], r[near]
    phi = np.stack([-dn[:, 1], dn[:, 0]], 1) / np.where(rn > 0, rn, 1.0)[:, None]
    an = sense * (geo.head[near] * phi).sum(1)
    # members: centre inside R_edge, or in the next ring and circulating (the partly filled outer layer)
    inm = (rn < R_edge) | ((rn < R_edge + dr) & (an >= P["cos_tangent"]))
    mem = near[inm]
    if len(mem) < P["min_cells"]:
        return False, dict(R_edge=float(R_edge))
    dm, rm, ac = dn[inm], rn[inm], an[inm]
    outer = rm >= core
    circ_c = outer & (ac >= P["cos_tangent"])
    n_outer = int(outer.sum())
    f_circ = circ_c.sum() / n_outer if n_outer else 0.0
    octs = np.unique(((np.arctan2(dm[circ_c, 1], dm[circ_c, 0]) + math.pi) / (math.pi / 4)).astype(int) % 8)
    pval = _binom_tail(int(circ_c.sum()), n_outer, math.acos(P["cos_tangent"]) / math.pi)
    ok = (f_circ >= P["min_circulating"]) and (len(octs) >= P["min_octants"]) and pval <= P["max_p_value"]
    return ok, dict(members=mem, d=dm, r=rm, circ=circ_c, f_circ=float(f_circ), n_octants=int(len(octs)), p_value=pval,
                    R_edge=float(R_edge), R_inner=float(start * dr))


def _binom_tail(k: int, n: int, p: float) -> float:
    """P(X >= k) for X ~ Binomial(n, p)."""
    if k <= 0:
        return 1.0
    if k > n:
        return 0.0
    lg = [math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1) + i * math.log(p) + (n - i) * math.log1p(-p)
          for i in range(k, n + 1)]
    m = max(lg)
    return min(1.0, math.exp(m) * sum(math.exp(x - m) for x in lg))


def _refine(geo: _Geo, c: np.ndarray, info: dict) -> np.ndarray | None:
    """Least-squares point on the circulating members' normal lines: argmin sum ((c - x_i) . h_i)^2."""
    sel = info["circ"]
    if sel.sum() < 3:
        return None
    h = geo.head[info["members"][sel]]
    x = info["d"][sel]                                            # relative to c
    M = np.einsum("ni,nj->ij", h, h)
    rhs = np.einsum("ni,nj,nj->i", h, h, x)
    ev = np.linalg.eigvalsh(M)
    if ev[0] <= 0.2 * ev[1]:
        return None
    return c + np.linalg.solve(M, rhs)


def _measure(geo: _Geo, c: np.ndarray, sense: int, info: dict, P: dict, v_b: float) -> dict:
    mem = info["members"]
    rp = info["d"][:, None, :] + geo.poff[mem]
    rpn = np.hypot(rp[..., 0], rp[..., 1]).ravel()
    tp = geo.ptan[mem].reshape(-1, 2)
    rpf = rp.reshape(-1, 2)
    sp = geo.pspeed[mem].ravel()
    m = rpn > 1e-9
    phi = np.stack([-rpf[m, 1], rpf[m, 0]], 1) / rpn[m, None]
    vt = sp[m] * (tp[m] * phi).sum(1)                             # signed tangential velocity, > 0 CCW
    r_, s_ = rpn[m], sp[m]
    srr = float((r_ * r_).sum())
    omega_tan = float((r_ * vt).sum() / srr) if srr > 0 else float("nan")
    omega_fit = float((r_ * s_).sum() / srr) if srr > 0 else float("nan")
    sst = float(((s_ - s_.mean()) ** 2).sum())
    r2_origin = 1.0 - float(((s_ - omega_fit * r_) ** 2).sum()) / sst if sst > 0 else float("nan")
    lin = _ols(r_, s_)
    if math.isfinite(lin["stderr"]):
        lin["stderr"] *= math.sqrt(max(len(r_) - 2, 1) / max(len(mem) - 2, 1))   # cells are the samples
    a_in = float(np.percentile(rpn, 2.0))
    R = math.sqrt(max(2.0 * float((rpn * rpn).mean()) - a_in * a_in, 0.0))
    # edge: outer fraction of member cells by centre distance
    k_edge = max(1, int(math.ceil(P["edge_fraction"] * len(mem))))
    outer = np.argsort(info["r"])[-k_edge:]
    edge = float(geo.cspeed[mem][outer].mean())
    ratio = omega_fit / abs(omega_tan) if omega_tan and math.isfinite(omega_tan) else float("nan")
    rigid = bool(math.isfinite(r2_origin) and r2_origin >= 0.5 and 0.75 <= ratio <= 1.0 / 0.75)
    out = dict(
        time_min=geo.t_min, centre_um=[float(c[0]), float(c[1])], radius_um=R, radius_edge_um=info["R_edge"],
        radius_inner_um=a_in, n_cells=int(len(mem)), sense=int(sense),
        omega_rad_per_min=omega_tan, omega_fit_rad_per_min=omega_fit, omega_fit_over_omega_tan=ratio,
        r2_origin=r2_origin, linear_fit=lin, rigid=rigid,
        edge_speed_um_per_min=edge, edge_speed_vb=edge / v_b,
        edge_speed_rigid_um_per_min=omega_fit * R, edge_speed_rigid_vb=omega_fit * R / v_b,
        mean_speed_um_per_min=float(geo.cspeed[mem].mean()), fraction_circulating=info["f_circ"],
        octants=info["n_octants"], p_value=info["p_value"],
    )
    # pooled profiles (not written per aggregate)
    x = rpn / R
    b = np.clip(np.digitize(x, _RBINS) - 1, 0, len(_RBINS) - 2)
    out["_speed_prof"] = (np.bincount(b, weights=sp / v_b, minlength=len(_RBINS) - 1),
                          np.bincount(b, minlength=len(_RBINS) - 1).astype(float))
    out["_scatter"] = (rpn, sp)
    if geo.strain is not None and geo.N > 1:
        sg = info["d"][:, None, :] + 0.5 * (geo.poff[mem][:, 1:] + geo.poff[mem][:, :-1])
        rs = np.hypot(sg[..., 0], sg[..., 1]).ravel() / R
        e = geo.strain[mem].ravel()
        b = np.clip(np.digitize(rs, _RBINS) - 1, 0, len(_RBINS) - 2)
        out["_strain_prof"] = (np.bincount(b, weights=e, minlength=len(_RBINS) - 1),
                               np.bincount(b, minlength=len(_RBINS) - 1).astype(float))
        inner, outr = e[rs < 0.5], e[(rs >= 0.5) & (rs <= 1.0)]
        out["strain_inner_over_outer"] = (float(inner.mean() / outr.mean())
                                          if len(inner) and len(outr) and outr.mean() > 0 else float("nan"))
    return out


def find_aggregates(geo_or_frame, clusters=None, v_b: float = 4.0, **params) -> list[dict]:
    """Detect circulating aggregates in one frame (see the module docstring for the criteria).

    geo_or_frame: a Frame (or the internal geometry); clusters: (labels, sizes) of touching cells, computed when None.
    Returns a list of aggregate dicts (centre_um, radius_um, n_cells, omega_rad_per_min, edge_speed_vb, ...), each
    with the member cell indices under "_members"."""
    geo = geo_or_frame if isinstance(geo_or_frame, _Geo) else _Geo(geo_or_frame)
    P = _params(**params)
    if P["ring_um"] is None:
        P["ring_um"] = 2.0 * geo.W
    if P["core_radius_um"] is None:
        P["core_radius_um"] = 0.5 * geo.cell_len
    if clusters is None:
        lab, sizes, _, _ = cell_clusters(geo.pos, geo.L, geo.W, P["contact_tol_um"])
    else:
        lab, sizes = clusters
    Lam = min(P["max_radius_um"], 0.45 * float(geo.L.min()))
    voters = np.nonzero(sizes[lab] >= P["min_cells"])[0]
    cands = _hough_candidates(geo, voters, P, Lam)
    free = np.ones(geo.n, bool)
    found = []
    fc = np.zeros((0, 2))
    fr_ = np.zeros(0)
    for height, sense, c in cands:
        if len(fr_):
            dd = _mi(fc - c, geo.L)
            if (np.hypot(dd[:, 0], dd[:, 1]) < fr_).any():
                continue
        ok, info = _walk(geo, c, sense, free, P, Lam)
        if not ok:
            continue
        for _ in range(4):
            c2 = _refine(geo, c, info)
            if c2 is None:
                break
            ok2, info2 = _walk(geo, np.mod(c2, geo.L), sense, free, P, Lam)
            if not ok2:
                break
            moved = np.hypot(*_mi(c2 - c, geo.L))
            c, info = np.mod(c2, geo.L), info2
            if moved < 0.05:
                break
        agg = _measure(geo, c, sense, info, P, v_b)
        agg["_members"] = info["members"]
        agg["hough_votes"] = height
        free[info["members"]] = False
        found.append(agg)
        fc = np.vstack([fc, c])
        fr_ = np.append(fr_, info["R_edge"])
    return found


# ------------------------------------------------------------------------------------------------- tracking
def _track(per_frame: list[list[dict]], L: np.ndarray, max_gap: int) -> list[list[tuple[int, dict]]]:
    tracks: list[list[tuple[int, dict]]] = []
    for fi, aggs in enumerate(per_frame):
        active = [t for t in tracks if fi - t[-1][0] <= max_gap + 1]
        pairs = []
        for ti, t in enumerate(active):
            last = t[-1][1]
            for ai, a in enumerate(aggs):
                dist = float(np.hypot(*_mi(np.array(a["centre_um"]) - np.array(last["centre_um"]), L)))
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


# ------------------------------------------------------------------------------------------------- whole trajectory
def _size_bins(n: int) -> np.ndarray:
    e = [1, 2]
    while e[-1] <= n:
        e.append(2 * e[-1] - 1)       # 1, 2, 3, 5, 9, 17, ... (bins [1], [2], [3,4], [5,8], ...)
    return np.array(e)


def analyze_frames(frames: Iterable[Frame], v_b: float = 4.0, **params) -> dict:
    """Analyse an iterable of Frames (see the module docstring). Returns the summary dict (JSON-ready after _clean);
    private keys starting with '_' carry data for the plots."""
    P = _params(**params)
    t0 = time.perf_counter()
    ts = dict(time_min=[], mean_speed_um_per_min=[], polar_order=[], nematic_order=[], local_polar_order=[],
              local_nematic_order=[], n_clusters=[], largest_cluster=[], mean_cluster_size_weighted=[],
              fraction_in_clusters=[], n_aggregates=[], fraction_in_aggregates=[])
    per_frame: list[list[dict]] = []
    size_dist = []
    hist_edges = np.arange(0.0, P["speed_hist_max"] + 1e-9, P["speed_hist_bin"])
    h_in = np.zeros(len(hist_edges) - 1)
    h_out = np.zeros(len(hist_edges) - 1)
    s_io = np.zeros(2)          # exact speed sums inside / outside
    no_speed: list[float] = []  # times of frames without logged speeds
    sprof = [np.zeros(len(_RBINS) - 1), np.zeros(len(_RBINS) - 1)]
    eprof = [np.zeros(len(_RBINS) - 1), np.zeros(len(_RBINS) - 1)]
    have_strain = False
    meta = None
    last_geo = None
    last_agg_frame = None
    for fr in frames:
        geo = _Geo(fr)
        if meta is None:
            if P["ring_um"] is None:
                P["ring_um"] = 2.0 * geo.W
            if P["core_radius_um"] is None:
                P["core_radius_um"] = 0.5 * geo.cell_len
            meta = dict(n_cells=geo.n, particles_per_cell=geo.N, box_um=[float(geo.L[0]), float(geo.L[1])],
                        width_um=geo.W, cell_length_um=geo.cell_len)
            sbins = _size_bins(geo.n)
        lab, sizes, ci, cj = cell_clusters(geo.pos, geo.L, geo.W, P["contact_tol_um"])
        aggs = find_aggregates(geo, (lab, sizes), v_b=v_b, **P)
        # time series
        ts["time_min"].append(geo.t_min)
        ts["mean_speed_um_per_min"].append(float(geo.cspeed.mean()))
        hd = geo.head
        ts["polar_order"].append(float(np.hypot(*hd.mean(0))))
        th = np.arctan2(hd[:, 1], hd[:, 0])
        ts["nematic_order"].append(float(np.abs(np.exp(2j * th).mean())))
        if len(ci):
            cdot = (hd[ci] * hd[cj]).sum(1)
            ts["local_polar_order"].append(float(cdot.mean()))
            ts["local_nematic_order"].append(float((2 * cdot * cdot - 1).mean()))
        else:
            ts["local_polar_order"].append(float("nan"))
            ts["local_nematic_order"].append(float("nan"))
        csize = sizes[lab]
        ts["n_clusters"].append(int((sizes >= 2).sum()))
        ts["largest_cluster"].append(int(sizes.max()))
        ts["mean_cluster_size_weighted"].append(float(csize.mean()))
        ts["fraction_in_clusters"].append(float((csize >= 2).mean()))
        size_dist.append(np.histogram(sizes, bins=sbins, weights=sizes)[0] / geo.n)
        inside = np.zeros(geo.n, bool)
        for a in aggs:
            inside[a["_members"]] = True
        ts["n_aggregates"].append(len(aggs))
        ts["fraction_in_aggregates"].append(float(inside.mean()))
        last_geo = (geo, aggs)
        if not np.any(geo.pspeed > 0):
            # no speeds yet (the first frame of a run: the speed window has not elapsed): geometry only
            no_speed.append(geo.t_min)
            per_frame.append([])
            continue
        for a in aggs:
            sprof[0] += a["_speed_prof"][0]
            sprof[1] += a["_speed_prof"][1]
            if "_strain_prof" in a:
                have_strain = True
                eprof[0] += a["_strain_prof"][0]
                eprof[1] += a["_strain_prof"][1]
        sp = np.clip(geo.cspeed, 0, hist_edges[-1] - 1e-9)
        h_in += np.histogram(sp[inside], bins=hist_edges)[0]
        h_out += np.histogram(sp[~inside], bins=hist_edges)[0]
        s_io += (geo.cspeed[inside].sum(), geo.cspeed[~inside].sum())
        per_frame.append(aggs)
        if aggs:
            last_agg_frame = (geo, aggs)
    if meta is None:
        raise ValueError("no frames to analyse")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)      # NaN means/medians of empty or all-NaN lists
        summary = _summarise(P, v_b, t0, ts, per_frame, size_dist, sbins, hist_edges, h_in, h_out, s_io, sprof,
                             eprof, have_strain, meta, last_agg_frame)
    summary["meta"]["frames_without_speed_min"] = no_speed
    summary["_last"] = last_geo
    summary["_last_agg"] = last_agg_frame
    return summary


def _summarise(P, v_b, t0, ts, per_frame, size_dist, sbins, hist_edges, h_in, h_out, s_io, sprof, eprof, have_strain,
               meta, last_agg_frame):
    n_fr = len(per_frame)
    L = np.array(meta["box_um"])
    tracks = _track(per_frame, L, P["max_gap_frames"])
    min_tf = min(P["min_track_frames"], n_fr)
    pub = lambda a: {k: v for k, v in a.items() if not k.startswith("_")}   # noqa: E731
    track_out = []
    for tid, t in enumerate(tracks):
        aa = [a for _, a in t]
        mean = lambda k: float(np.nanmean([a[k] for a in aa]))            # noqa: E731
        track_out.append(dict(
            id=tid, n_frames=len(t), first_time_min=aa[0]["time_min"], last_time_min=aa[-1]["time_min"],
            stable=len(t) >= min_tf,
            mean_radius_um=mean("radius_um"), mean_n_cells=mean("n_cells"),
            mean_omega_rad_per_min=mean("omega_rad_per_min"), mean_edge_speed_um_per_min=mean("edge_speed_um_per_min"),
            mean_edge_speed_vb=mean("edge_speed_vb"), mean_r2_origin=mean("r2_origin"),
            fraction_rigid=float(np.mean([a["rigid"] for a in aa])),
            last=pub(aa[-1]),
            series=dict(time_min=[a["time_min"] for a in aa], centre_um=[a["centre_um"] for a in aa],
                        radius_um=[a["radius_um"] for a in aa], n_cells=[a["n_cells"] for a in aa],
                        omega_rad_per_min=[a["omega_rad_per_min"] for a in aa],
                        edge_speed_um_per_min=[a["edge_speed_um_per_min"] for a in aa],
                        r2_origin=[a["r2_origin"] for a in aa]),
        ))
    stable = [t for t in track_out if t["stable"]]

    def size_regression(R, E):
        R, E = np.asarray(R, float), np.asarray(E, float)
        out = _ols(R, E)
        out = dict(n_aggregates=len(R), slope_um_per_min_per_um=out["slope"], stderr=out["stderr"],
                   intercept_um_per_min=out["intercept"], r2=out["r2"])
        t = out["slope_um_per_min_per_um"] / out["stderr"] if out["stderr"] and math.isfinite(out["stderr"]) \
            else float("nan")
        out["t"] = t
        out["consistent_with_zero"] = bool(abs(t) < 2.0) if math.isfinite(t) else None
        if len(R) >= 2 and math.isfinite(out["slope_um_per_min_per_um"]):
            out["relative_change_over_range"] = out["slope_um_per_min_per_um"] * float(R.max() - R.min()) / float(E.mean())
        good = (R > 0) & (E > 0)
        lg = _ols(np.log(R[good]), np.log(E[good])) if good.sum() >= 2 else _ols([], [])
        out["loglog_exponent"] = lg["slope"]
        out["loglog_exponent_stderr"] = lg["stderr"]
        return out

    final = last_agg_frame[1] if last_agg_frame else []
    all_aggs = [a for fa in per_frame for a in fa]
    ratio = [a["omega_fit_over_omega_tan"] for a in all_aggs]
    predictions = dict(
        paper=PAPER,
        v_b_um_per_min=v_b,
        edge_speed_vb_per_track=[t["mean_edge_speed_vb"] for t in stable],
        edge_speed_vb_mean=float(np.mean([t["mean_edge_speed_vb"] for t in stable])) if stable else None,
        edge_speed_vb_final=[a["edge_speed_vb"] for a in final],
        edge_speed_vs_radius_tracks=size_regression([t["mean_radius_um"] for t in stable],
                                                    [t["mean_edge_speed_um_per_min"] for t in stable]),
        edge_speed_vs_radius_final=size_regression([a["radius_um"] for a in final],
                                                   [a["edge_speed_um_per_min"] for a in final]),
        rigid_rotation=dict(
            n_aggregate_frames=len(all_aggs),
            fraction_rigid=float(np.mean([a["rigid"] for a in all_aggs])) if all_aggs else None,
            r2_origin_median=float(np.nanmedian([a["r2_origin"] for a in all_aggs])) if all_aggs else None,
            r2_linear_median=float(np.nanmedian([a["linear_fit"]["r2"] for a in all_aggs])) if all_aggs else None,
            omega_fit_over_omega_tan_median=float(np.nanmedian(ratio)) if all_aggs else None,
            speed_grows_with_radius_fraction=float(np.mean([a["linear_fit"]["slope"] > 0 for a in all_aggs]))
            if all_aggs else None,
        ),
    )
    reg = predictions["edge_speed_vs_radius_tracks"]
    rr = predictions["rigid_rotation"]
    em = predictions["edge_speed_vb_mean"]
    predictions["verdict"] = dict(
        criteria="aggregates: stable tracks (>= min_track_frames); rigid: fraction of aggregate-frames rigid >= 0.5; "
                 "edge faster than v_b: mean edge speed / v_b over tracks > 1.15; size-independent: |t| of the edge "
                 "speed vs radius slope < 2 (needs >= 3 tracks)",
        n_stable_aggregates=len(stable),
        rigid_rotation=(rr["fraction_rigid"] >= 0.5) if rr["fraction_rigid"] is not None else None,
        edge_faster_than_v_b=(em > 1.15) if em is not None else None,
        edge_speed_size_independent=reg["consistent_with_zero"] if reg["n_aggregates"] >= 3 else None,
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        speed_prof = dict(r_over_R_edges=_RBINS, mean_speed_vb=sprof[0] / sprof[1], n_particles=sprof[1])
        strain_prof = dict(r_over_R_edges=_RBINS, mean_strain_energy_J=eprof[0] / eprof[1], n_segments=eprof[1]) \
            if have_strain else None
    if strain_prof is not None:
        s, c = eprof
        inner = s[_RBINS[:-1] < 0.5].sum() / max(c[_RBINS[:-1] < 0.5].sum(), 1)
        outer = s[(_RBINS[:-1] >= 0.5) & (_RBINS[1:] <= 1.0 + 1e-9)].sum() / \
            max(c[(_RBINS[:-1] >= 0.5) & (_RBINS[1:] <= 1.0 + 1e-9)].sum(), 1)
        strain_prof["inner_over_outer"] = inner / outer if outer > 0 else float("nan")
        strain_prof["highest_toward_centre"] = bool(inner > outer) if outer > 0 else None
    summary = dict(
        meta=dict(meta, n_frames_analyzed=n_fr, v_b_um_per_min=v_b,
                  time_range_min=[ts["time_min"][0], ts["time_min"][-1]]),
        parameters=P,
        n_aggregates_final=len(final),
        min_track_frames_effective=min_tf,
        final_time_min=(last_agg_frame[0].t_min if last_agg_frame else None),
        aggregates_final=[pub(a) for a in final],
        tracks=track_out,
        predictions=predictions,
        timeseries=ts,
        cluster_size_distribution=dict(size_bin_edges=sbins, fraction_of_cells=np.array(size_dist),
                                       note="row per analysed frame; column b: fraction of cells in clusters of "
                                            "size in [edges[b], edges[b+1])"),
        speed_histograms=dict(bin_edges_um_per_min=hist_edges, inside_aggregates=h_in, outside_aggregates=h_out,
                              mean_inside=float(s_io[0] / h_in.sum()) if h_in.sum() else None,
                              mean_outside=float(s_io[1] / h_out.sum()) if h_out.sum() else None,
                              note="cell speeds (mean of its particles), counts over all analysed frames; "
                                   "speeds above the last edge are counted in the last bin"),
        speed_profile=speed_prof,
        strain_profile=strain_prof,
        analysis_seconds=time.perf_counter() - t0,
    )
    return summary


def analyze(gsd_path: str, out_dir: str | None = None, every: int = 1, v_b: float | None = None,
            plots: bool = True, **params) -> dict:
    """Analyse a trajectory; write <stem>.analysis.json (and PNG plots) next to it or in out_dir. Returns the summary
    (JSON-clean). v_b: free-cell speed in µm/min; default from the stored scene (cell.speed_um_per_min) or 4."""
    from .trajectory import read_frames, read_scene
    t0 = time.perf_counter()
    scene = read_scene(gsd_path)
    if v_b is None:
        v_b = float((scene.get("cell") or {}).get("speed_um_per_min", 4.0) or 4.0)
    s = analyze_frames(read_frames(gsd_path, every=every), v_b=v_b, **params)
    out_dir = out_dir or os.path.dirname(os.path.abspath(gsd_path))
    os.makedirs(out_dir, exist_ok=True)
    stem = os.path.splitext(os.path.basename(gsd_path))[0]
    s["meta"].update(trajectory=os.path.abspath(gsd_path), every=every, scene_name=scene.get("name"))
    files = []
    if plots:
        files = _plots(s, os.path.join(out_dir, stem + ".analysis"))
    s["plots"] = files
    s["total_seconds"] = time.perf_counter() - t0
    clean = _clean({k: v for k, v in s.items() if not k.startswith("_")})
    path = os.path.join(out_dir, stem + ".analysis.json")
    with open(path, "w") as f:
        json.dump(clean, f, indent=1)
    clean["json"] = path
    return clean


# ------------------------------------------------------------------------------------------------- report
def format_summary(summary: dict) -> str:
    """Short human-readable report of an analyze() summary."""
    m = summary["meta"]
    vb = m["v_b_um_per_min"]
    lines = [f"{m.get('trajectory', 'trajectory')}: {m['n_cells']} cells, box {m['box_um'][0]:g} x "
             f"{m['box_um'][1]:g} µm, {m['n_frames_analyzed']} frames, t = {m['time_range_min'][0]:.1f}-"
             f"{m['time_range_min'][1]:.1f} min, v_b = {vb:g} µm/min"]
    ts = summary["timeseries"]
    if ts["time_min"]:
        lines.append(f"last frame: mean speed {ts['mean_speed_um_per_min'][-1]:.2f} µm/min, "
                     f"{ts['fraction_in_clusters'][-1] * 100:.0f} % of cells in clusters (largest "
                     f"{ts['largest_cluster'][-1]}), {ts['fraction_in_aggregates'][-1] * 100:.0f} % in aggregates, "
                     f"nematic order {ts['nematic_order'][-1]:.2f} (local {_f(ts['local_nematic_order'][-1])})")
    fin = summary["aggregates_final"]
    t = summary.get("final_time_min")
    lines.append(f"{len(fin)} rotating aggregate(s)" + (f" at t = {t:.1f} min" if t is not None else ""))
    if fin:
        lines.append("    centre (µm)        R (µm)  cells  ω (rad/min)  edge (µm/min)  edge/v_b  R²(v∝r)  rigid")
        for a in sorted(fin, key=lambda a: -a["n_cells"]):
            c = a["centre_um"]
            lines.append(f"  ({c[0]:7.1f}, {c[1]:7.1f})  {a['radius_um']:6.1f}  {a['n_cells']:5d}  "
                         f"{_f(a['omega_rad_per_min'], '+8.3f')}     {_f(a['edge_speed_um_per_min'], '6.2f')}"
                         f"        {_f(a['edge_speed_vb'], '5.2f')}    {_f(a['r2_origin'], '5.2f')}   "
                         f"{'yes' if a['rigid'] else 'no'}")
    pr = summary["predictions"]
    st = [tr for tr in summary["tracks"] if tr["stable"]]
    lines.append(f"{len(summary['tracks'])} aggregate track(s), {len(st)} seen in >= "
                 f"{summary.get('min_track_frames_effective', summary['parameters']['min_track_frames'])} frame(s)")
    if pr.get("edge_speed_vb_mean") is not None:
        lines.append(f"edge speed / v_b over tracks: mean {pr['edge_speed_vb_mean']:.2f} "
                     f"(paper: adhesion 1.33, active following up to 4, slime trails ~1)")
    reg = pr["edge_speed_vs_radius_tracks"]
    if reg["n_aggregates"] >= 3 and reg["stderr"] is not None:
        lines.append(f"edge speed vs radius: slope {_f(reg['slope_um_per_min_per_um'], '.3f')} ± "
                     f"{_f(reg['stderr'], '.3f')} µm/min per µm (t = {_f(reg['t'], '.1f')}; "
                     f"{'consistent' if reg['consistent_with_zero'] else 'NOT consistent'} with size-independence), "
                     f"log-log exponent {_f(reg['loglog_exponent'], '.2f')}")
    rr = pr["rigid_rotation"]
    if rr["n_aggregate_frames"]:
        lines.append(f"rigid rotation: {rr['fraction_rigid'] * 100:.0f} % of aggregate-frames rigid, median R² "
                     f"{_f(rr['r2_origin_median'], '.2f')}, median ω_fit/ω_tan "
                     f"{_f(rr['omega_fit_over_omega_tan_median'], '.2f')}")
    sh = summary["speed_histograms"]
    if sh["mean_inside"] is not None:
        lines.append(f"mean cell speed inside aggregates {sh['mean_inside']:.2f}, outside "
                     f"{_f(sh['mean_outside'], '.2f')} µm/min")
    sp = summary.get("strain_profile")
    if sp:
        lines.append(f"strain energy inner (r < R/2) / outer: {_f(sp['inner_over_outer'], '.2f')}")
    if "analysis_seconds" in summary:
        lines.append(f"analysis took {summary.get('total_seconds', summary['analysis_seconds']):.1f} s")
    return "\n".join(lines)


def _f(x, fmt=".2f"):
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def main_analyze(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m taichimyxo analyze",
                                 description="Clusters, rotating aggregates, speed and strain profiles of a trajectory")
    ap.add_argument("trajectory", help="GSD trajectory written by taichimyxo")
    ap.add_argument("--out", default=None, help="output folder (default: next to the trajectory)")
    ap.add_argument("--every", type=int, default=1, help="analyse every K-th frame")
    ap.add_argument("--v-b", type=float, default=None, help="free-cell speed, µm/min (default: from the scene, or 4)")
    ap.add_argument("--no-plots", action="store_true")
    a = ap.parse_args(argv)
    s = analyze(a.trajectory, out_dir=a.out, every=a.every, v_b=a.v_b, plots=not a.no_plots)
    print(format_summary(s))
    print(f"wrote {s['json']}" + "".join(f"\nwrote {p}" for p in s["plots"]))
    return 0


# ------------------------------------------------------------------------------------------------- plots
def _plots(s: dict, base: str) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    files = []
    vb = s["meta"]["v_b_um_per_min"]
    ts = s["timeseries"]
    t = np.array(ts["time_min"])

    # 1. time series
    fig, ax = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    ax[0, 0].plot(t, ts["mean_speed_um_per_min"], label="all cells")
    ax[0, 0].axhline(vb, color="k", ls=":", label="v_b")
    ax[0, 0].set(xlabel="time (min)", ylabel="mean speed (µm/min)", title="speed")
    ax[0, 0].legend()
    for k in ("polar_order", "nematic_order", "local_polar_order", "local_nematic_order"):
        ax[0, 1].plot(t, ts[k], label=k.replace("_", " "))
    ax[0, 1].set(xlabel="time (min)", ylabel="order", ylim=(-0.05, 1.05), title="orientational order")
    ax[0, 1].legend(fontsize=8)
    n = s["meta"]["n_cells"]
    ax[1, 0].plot(t, np.array(ts["largest_cluster"]) / n, label="largest cluster / N")
    ax[1, 0].plot(t, ts["fraction_in_clusters"], label="fraction in clusters (>= 2)")
    ax[1, 0].plot(t, np.array(ts["mean_cluster_size_weighted"]) / n, label="cell-weighted mean size / N")
    ax[1, 0].set(xlabel="time (min)", ylabel="fraction", title="clusters of touching cells")
    ax[1, 0].legend(fontsize=8)
    ax[1, 1].plot(t, ts["n_aggregates"], "C0", label="aggregates")
    ax[1, 1].set(xlabel="time (min)", ylabel="number of aggregates", title="rotating aggregates")
    a2 = ax[1, 1].twinx()
    a2.plot(t, ts["fraction_in_aggregates"], "C1", label="fraction of cells in aggregates")
    a2.set_ylabel("fraction of cells in aggregates", color="C1")
    f = base + ".timeseries.png"
    fig.savefig(f, dpi=90)
    plt.close(fig)
    files.append(f)

    # 2. aggregates: rigid-body test and size independence
    fig, ax = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
    la = s.get("_last_agg")
    if la:
        geo, aggs = la
        big = max(aggs, key=lambda a: a["n_cells"])
        r, sp = big["_scatter"]
        ax[0, 0].scatter(r, sp, s=3, alpha=0.4, label="particles")
        rr = np.linspace(0, r.max(), 50)
        ax[0, 0].plot(rr, big["omega_fit_rad_per_min"] * rr, "r", label=f"ω r, ω = {big['omega_fit_rad_per_min']:.3f}"
                      f" rad/min, R² = {big['r2_origin']:.2f}")
        ax[0, 0].axhline(vb, color="k", ls=":", label="v_b")
        ax[0, 0].axvline(big["radius_um"], color="g", ls="--", label="R")
        ax[0, 0].set(xlabel="distance from centre (µm)", ylabel="speed (µm/min)",
                     title=f"largest aggregate at t = {geo.t_min:.0f} min ({big['n_cells']} cells)")
        ax[0, 0].legend(fontsize=8)
    else:
        ax[0, 0].text(0.5, 0.5, "no aggregates", ha="center", transform=ax[0, 0].transAxes)
    sp_ = s["speed_profile"]
    mid = 0.5 * (_RBINS[1:] + _RBINS[:-1])
    ax[0, 1].plot(mid, sp_["mean_speed_vb"], "o-", label="mean speed / v_b (all aggregates)")
    la_all = [a for tr in s["tracks"] for a in [tr["last"]]]
    if la_all:
        rig = float(np.nanmedian([a["edge_speed_rigid_vb"] for a in la_all]))
        ax[0, 1].plot([0, 1], [0, rig], "r--", label="rigid body ω r (median ω R)")
    ax[0, 1].axhline(1, color="k", ls=":", label="v_b")
    ax[0, 1].set(xlabel="r / R", ylabel="speed / v_b", title="pooled speed profile")
    ax[0, 1].legend(fontsize=8)
    st = [tr for tr in s["tracks"] if tr["stable"]]
    if st:
        R = np.array([tr["mean_radius_um"] for tr in st])
        E = np.array([tr["mean_edge_speed_vb"] for tr in st])
        ax[1, 0].scatter(R, E, c="C0", label="tracks (time means)")
        reg = s["predictions"]["edge_speed_vs_radius_tracks"]
        if reg["slope_um_per_min_per_um"] is not None and math.isfinite(reg["slope_um_per_min_per_um"]):
            rr = np.linspace(R.min(), R.max(), 10)
            ax[1, 0].plot(rr, (reg["intercept_um_per_min"] + reg["slope_um_per_min_per_um"] * rr) / vb, "C0-",
                          label=f"fit slope {reg['slope_um_per_min_per_um']:.3f} ± {_f(reg['stderr'], '.3f')}")
        for name, y, c in (("adhesion 4/3", 4 / 3, "C2"), ("active max 4", 4, "C3"), ("slime ~1", 1, "k")):
            ax[1, 0].axhline(y, color=c, ls=":", label=name)
        ax[1, 0].legend(fontsize=8)
    ax[1, 0].set(xlabel="aggregate radius (µm)", ylabel="edge speed / v_b", title="edge speed vs size")
    for tr in sorted(s["tracks"], key=lambda tr: -tr["n_frames"])[:20]:
        ax[1, 1].plot(tr["series"]["time_min"], np.abs(tr["series"]["omega_rad_per_min"]), ".-", ms=3)
    ax[1, 1].set(xlabel="time (min)", ylabel="|ω| (rad/min)", title="angular speed per track (20 longest)")
    f = base + ".aggregates.png"
    fig.savefig(f, dpi=90)
    plt.close(fig)
    files.append(f)

    # 3. distributions
    fig, ax = plt.subplots(1, 3, figsize=(14, 4), constrained_layout=True)
    h = s["speed_histograms"]
    e = np.asarray(h["bin_edges_um_per_min"])
    for k, lab in (("inside_aggregates", "inside aggregates"), ("outside_aggregates", "outside")):
        c = np.asarray(h[k], float)
        if c.sum():
            ax[0].stairs(c / c.sum() / np.diff(e), e, label=lab)
    ax[0].axvline(vb, color="k", ls=":", label="v_b")
    ax[0].set(xlabel="cell speed (µm/min)", ylabel="density", title="speed distribution (all frames)")
    ax[0].legend()
    cd = s["cluster_size_distribution"]
    fr = np.asarray(cd["fraction_of_cells"])
    ed = np.asarray(cd["size_bin_edges"])
    nfr = len(fr)
    for i, lab in ((0, "first"), (nfr // 2, "middle"), (nfr - 1, "last")):
        ax[1].step(ed[:-1], fr[i], where="post", label=f"{lab} frame (t = {ts['time_min'][i]:.0f} min)")
    ax[1].set(xscale="log", xlabel="cluster size (cells)", ylabel="fraction of cells",
              title="cluster size distribution")
    ax[1].legend(fontsize=8)
    sp_ = s["strain_profile"]
    if sp_ is not None:
        ax[2].plot(mid, sp_["mean_strain_energy_J"], "o-")
        ax[2].set(xlabel="r / R", ylabel="mean segment strain energy (J)", title="strain energy in aggregates")
    else:
        ax[2].text(0.5, 0.5, "strain energy not logged", ha="center", transform=ax[2].transAxes)
        ax[2].set_axis_off()
    f = base + ".distributions.png"
    fig.savefig(f, dpi=90)
    plt.close(fig)
    files.append(f)

    # 4. snapshot of the last frame with aggregates circled
    geo, aggs = s["_last"]
    L = geo.L
    fig, ax = plt.subplots(figsize=(8, 8 * L[1] / L[0] + 0.6), constrained_layout=True)
    shift = np.floor(geo.pos[:, :1] / L) * L
    p = geo.pos - shift
    segs = np.stack([p[:, :-1], p[:, 1:]], axis=2).reshape(-1, 2, 2)
    spd = (0.5 * (geo.pspeed[:, 1:] + geo.pspeed[:, :-1])).ravel()
    out = (segs < 0).any(axis=(1, 2)) | (segs >= L).any(axis=(1, 2))       # periodic copies of crossing segments
    if out.any():
        cs, cv = [segs], [spd]
        for ox in (-L[0], 0.0, L[0]):
            for oy in (-L[1], 0.0, L[1]):
                if ox or oy:
                    cs.append(segs[out] + np.array([ox, oy]))
                    cv.append(spd[out])
        segs, spd = np.concatenate(cs), np.concatenate(cv)
    lw = max(0.3, 8 * 72 * geo.W / L[0] * 0.8)
    lc = LineCollection(segs, array=spd, cmap="jet", norm=plt.Normalize(0, 4 * vb), linewidths=lw)
    ax.add_collection(lc)
    for a in aggs:
        c = a["centre_um"]
        for ox in (-L[0], 0, L[0]):
            for oy in (-L[1], 0, L[1]):
                ax.add_patch(plt.Circle((c[0] + ox, c[1] + oy), a["radius_um"], fill=False, ec="k", lw=1.2))
        ax.plot(*c, "k+", ms=8)
        ax.annotate(f"{a['edge_speed_vb']:.1f} v_b", (c[0] + 0.71 * a["radius_um"], c[1] + 0.71 * a["radius_um"]),
                    xytext=(2, 2), textcoords="offset points", fontsize=7)
    ax.set(xlim=(0, L[0]), ylim=(0, L[1]), aspect="equal", xlabel="x (µm)", ylabel="y (µm)",
           title=f"t = {geo.t_min:.0f} min: {len(aggs)} aggregates (circles: radius R, label: edge speed)")
    fig.colorbar(lc, ax=ax, orientation="horizontal", fraction=0.04, pad=0.06, label="segment speed (µm/min)")
    f = base + ".snapshot.png"
    fig.savefig(f, dpi=90)
    plt.close(fig)
    files.append(f)
    return files


# ------------------------------------------------------------------------------------------------- synthetic data
def synthetic_frames(box=(200.0, 200.0), n_frames=1, dt_s=60.0, disks=(), streams=(), gas=0, gas_speed=4.0,
                     width=0.5, length=5.0, N=8, seed=0, strain=False, t0_s=0.0, jitter_deg=0.0,
                     speed_noise=0.0, gas_avoids_disks=False) -> Iterator[Frame]:
    """Trajectories with known answers (for tests and benchmarks).

    disks: dicts(centre=(x, y), radius=R, omega=rad/min (signed, > 0 counter-clockwise), r_in=1.5, speed=None):
        cells of outline `length` on concentric rings W apart from r_in to R - W/2 (R: the outer edge of the outermost
        ring), head to tail, each an exact arc, particle speeds |omega| r, rotating rigidly; with speed=v every ring
        turns at v / r instead (uniform speed, like a slime-trail aggregate; only the sign of omega is used). Half of
        the cells have k_e = -1 (chain stored tail first). With strain=True, segment strain energy
        1e-18 J x (1 - r/R).
    streams: dicts(origin=(x, y), angle=rad, rows=int, per_row=int, speed=µm/min): straight parallel cells, rows W
        apart, head to tail, translating.
    gas: that many straight cells at random places and angles, moving along their headings at gas_speed; with
        gas_avoids_disks, none starts within R + length of a disk centre (they still cross disks later).
    jitter_deg, speed_noise: disk cells turned about their centres by a random angle of that SD (fixed per cell) and
        particle speeds multiplied by (1 + speed_noise x standard normal), drawn anew each frame."""
    rng = np.random.default_rng(seed)
    L = np.asarray(box, float)
    l0 = (length - width) / (N - 1)
    j = np.arange(N) - 0.5 * (N - 1)
    parts = []   # (kind, data)
    for dk in disks:
        ringr = []
        r = float(dk.get("r_in", 1.5))
        while r <= dk["radius"] - 0.5 * width + 1e-9:
            m = int(2 * math.pi * r // length)
            if m >= 1 and (N - 1) * l0 < 0.95 * 2 * math.pi * r:
                ringr.append((r, m))
            r += width
        rr, th = [], []
        for r, m in ringr:
            th0 = rng.uniform(0, 2 * math.pi)
            for q in range(m):
                rr.append(r)
                th.append(th0 + 2 * math.pi * q / m)
        rr, th = np.array(rr), np.array(th)
        ke = np.where(rng.random(len(rr)) < 0.5, 1, -1).astype(np.int8)
        jit = np.deg2rad(jitter_deg) * rng.standard_normal(len(rr))
        parts.append(("disk", dk, rr, th, ke, jit))
    for sd in streams:
        rows, per = int(sd["rows"]), int(sd["per_row"])
        u = np.array([math.cos(sd["angle"]), math.sin(sd["angle"])])
        v = np.array([-u[1], u[0]])
        a, b = np.meshgrid(np.arange(per), np.arange(rows), indexing="ij")
        c0 = np.asarray(sd["origin"], float) + (a.ravel() * length)[:, None] * u + (b.ravel() * width)[:, None] * v
        parts.append(("stream", sd, c0, u))
    if gas:
        c0 = rng.uniform(0, 1, (gas, 2)) * L
        if gas_avoids_disks and disks:
            for _ in range(1000):
                bad = np.zeros(gas, bool)
                for dk in disks:
                    dd = _mi(c0 - np.asarray(dk["centre"], float), L)
                    bad |= np.hypot(dd[:, 0], dd[:, 1]) < dk["radius"] + length
                if not bad.any():
                    break
                c0[bad] = rng.uniform(0, 1, (int(bad.sum()), 2)) * L
        ang = rng.uniform(0, 2 * math.pi, gas)
        ke = np.where(rng.random(gas) < 0.5, 1, -1).astype(np.int8)
        parts.append(("gas", None, c0, ang, ke))
    for f in range(n_frames):
        t_s = t0_s + f * dt_s
        tm = t_s / 60.0
        P_, K_, S_, E_ = [], [], [], []
        for part in parts:
            if part[0] == "disk":
                _, dk, rr, th, ke, jit = part
                w = float(dk["omega"])
                sgn = 1.0 if w >= 0 else -1.0
                # particle 0 of a k_e = +1 cell leads (largest angle in the sense of motion)
                v_const = dk.get("speed")          # None: rigid rotation; a number: every cell at that speed
                wr = sgn * v_const / rr if v_const is not None else np.full(len(rr), w)
                ang = th[:, None] + (wr * tm)[:, None] + sgn * (-j[None, :]) * (l0 / rr[:, None]) * ke[:, None]
                c = np.asarray(dk["centre"], float)
                pos = c + rr[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
                if jitter_deg:
                    cc = pos.mean(1, keepdims=True)
                    co, si = np.cos(jit)[:, None], np.sin(jit)[:, None]
                    q = pos - cc
                    pos = cc + np.stack([co * q[..., 0] - si * q[..., 1], si * q[..., 0] + co * q[..., 1]], -1)
                spd = np.repeat((np.abs(wr) * rr)[:, None], N, 1)
                if speed_noise:
                    spd = spd * np.clip(1 + speed_noise * rng.standard_normal(spd.shape), 0, None)
                P_.append(pos)
                K_.append(ke)
                S_.append(spd)
                E_.append(np.repeat((1e-18 * np.clip(1 - rr / dk["radius"], 0, None))[:, None], N - 1, 1))
            elif part[0] == "stream":
                _, sd, c0, u = part
                c = c0 + sd["speed"] * tm * u
                pos = c[:, None, :] - (j * l0)[None, :, None] * u     # particle 0 in front
                P_.append(pos)
                K_.append(np.ones(len(c), np.int8))
                S_.append(np.full((len(c), N), float(sd["speed"])))
                E_.append(np.zeros((len(c), N - 1)))
            else:
                _, _, c0, ang, ke = part
                u = np.stack([np.cos(ang), np.sin(ang)], -1)
                c = c0 + gas_speed * tm * u
                pos = c[:, None, :] - (j * l0)[None, :, None] * u[:, None, :] * ke[:, None, None].astype(float)
                P_.append(pos)
                K_.append(ke)
                S_.append(np.full((len(c), N), float(gas_speed)))
                E_.append(np.zeros((len(c), N - 1)))
        pos = np.concatenate(P_) if P_ else np.zeros((0, N, 2))
        pos = pos - np.floor(pos[:, :1] / L) * L
        yield Frame(time_s=t_s, step=f, box=(float(L[0]), float(L[1])), width_um=width, positions=pos,
                    engine_direction=np.concatenate(K_).astype(np.int8),
                    particle_speed=np.concatenate(S_).astype(np.float32),
                    segment_strain=np.concatenate(E_) if strain else None, meta={"name": "synthetic"})


def write_synthetic(path: str, v_b: float = 4.0, **kw) -> str:
    """Write synthetic_frames(**kw) to a GSD trajectory at path."""
    from .trajectory import TrajectoryWriter
    N = kw.get("N", 8)
    scene = {"name": "synthetic", "cell": {"particles": N, "width_um": kw.get("width", 0.5),
                                           "speed_um_per_min": v_b}}
    with TrajectoryWriter(path, scene) as w:
        for fr in synthetic_frames(**kw):
            w.append(fr)
    return path


if __name__ == "__main__":      # pragma: no cover
    sys.exit(main_analyze(sys.argv[1:]))
