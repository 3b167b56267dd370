"""Circular (rotating) aggregates in one frame: Hough candidates, ring walk, centre refinement, measurement.

Per frame:
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
"""
from __future__ import annotations

import math

import numpy as np

from ..geometry import min_image
from .cells import CellGeometry
from .clusters import cell_clusters
from .params import R_BINS, fill_cell_defaults, parameters
from .stats import binom_tail, ols, rigid_rotation_fit


def _hough_candidates(geo: CellGeometry, voters: np.ndarray, P: dict, Lam: float):
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


def _walk(geo: CellGeometry, c: np.ndarray, sense: int, free: np.ndarray, P: dict, Lam: float):
    """Ring walk and acceptance tests at centre c. Returns (ok, info dict). Tries a 16 µm search radius first and
    repeats with Lam only when the walk reaches it."""
    d = min_image(geo.cen - c, geo.L)
    lam0 = min(Lam, 16.0)
    ok, info = _walk_r(geo, d, sense, free, P, lam0)
    if lam0 < Lam and info is not None and info["R_edge"] >= lam0 - 2 * P["ring_um"]:
        ok, info = _walk_r(geo, d, sense, free, P, Lam)
    return ok, info


def _walk_r(geo: CellGeometry, d: np.ndarray, sense: int, free: np.ndarray, P: dict, Lam: float):
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
    pval = binom_tail(int(circ_c.sum()), n_outer, math.acos(P["cos_tangent"]) / math.pi)
    ok = (f_circ >= P["min_circulating"]) and (len(octs) >= P["min_octants"]) and pval <= P["max_p_value"]
    return ok, dict(members=mem, d=dm, r=rm, circ=circ_c, f_circ=float(f_circ), n_octants=int(len(octs)), p_value=pval,
                    R_edge=float(R_edge), R_inner=float(start * dr))


def _refine(geo: CellGeometry, c: np.ndarray, info: dict) -> np.ndarray | None:
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


def _profile(r_over_R: np.ndarray, weights: np.ndarray):
    """(sum of weights, count) in each r / R bin of R_BINS, values beyond the last edge in the last bin."""
    b = np.clip(np.digitize(r_over_R, R_BINS) - 1, 0, len(R_BINS) - 2)
    return (np.bincount(b, weights=weights, minlength=len(R_BINS) - 1),
            np.bincount(b, minlength=len(R_BINS) - 1).astype(float))


def _measure(geo: CellGeometry, c: np.ndarray, sense: int, info: dict, P: dict, v_b: float) -> dict:
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
    lin = ols(r_, s_)
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
    if geo.pvel is not None:
        # v = omega x (r - c) fitted to the members' particle velocities (positions relative to the detected
        # centre, unwrapped): the rotation's own centre, rate and how rigid it is (R^2)
        fit = rigid_rotation_fit(rpf, geo.pvel[mem].reshape(-1, 2))
        cen = np.mod(np.asarray(c, float) + np.nan_to_num(np.asarray(fit["centre"])), geo.L)
        out["rotation_fit"] = dict(omega_rad_per_min=fit["omega"], r2=fit["r2"],
                                   centre_um=[float(x) for x in cen] if math.isfinite(fit["omega"]) else None)
    # pooled profiles (not written per aggregate)
    out["_speed_prof"] = _profile(rpn / R, sp / v_b)
    out["_scatter"] = (rpn, sp)
    if geo.strain is not None and geo.N > 1:
        sg = info["d"][:, None, :] + 0.5 * (geo.poff[mem][:, 1:] + geo.poff[mem][:, :-1])
        rs = np.hypot(sg[..., 0], sg[..., 1]).ravel() / R
        e = geo.strain[mem].ravel()
        out["_strain_prof"] = _profile(rs, e)
        inner, outr = e[rs < 0.5], e[(rs >= 0.5) & (rs <= 1.0)]
        out["strain_inner_over_outer"] = (float(inner.mean() / outr.mean())
                                          if len(inner) and len(outr) and outr.mean() > 0 else float("nan"))
    return out


def find_aggregates(geo_or_frame, clusters=None, v_b: float = 4.0, **params) -> list[dict]:
    """Detect circulating aggregates in one frame (see the module docstring for the criteria).

    geo_or_frame: a Frame (or its CellGeometry); clusters: (labels, sizes) of touching cells, computed when None.
    Returns a list of aggregate dicts (centre_um, radius_um, n_cells, omega_rad_per_min, edge_speed_vb, ...), each
    with the member cell indices under "_members"."""
    geo = geo_or_frame if isinstance(geo_or_frame, CellGeometry) else CellGeometry(geo_or_frame)
    P = fill_cell_defaults(parameters(**params), geo)
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
            dd = min_image(fc - c, geo.L)
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
            moved = np.hypot(*min_image(c2 - c, geo.L))
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
