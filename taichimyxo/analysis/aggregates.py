"""Circular (rotating) aggregates in one frame: each aggregate is a set of cells circulating about a common centre.

The paper's aggregates are "circular aggregates" whose cells move around a common centre (rigidly with adhesion and
active following, at about v_b with slime trails). A person separates them by the centre each group of cells turns
about, not by which cells touch: two aggregates that touch are two aggregates. The detection does the same, with the
particles' velocities (or speed x forward tangent where a trajectory stores none):

1. Each cell's own rotation centre. The least-squares fit of v = omega x (x - c) to the cell's own particles (8
   velocities, 3 unknowns; closed form: omega = sum x' x v / sum |x'|^2 with x' the particle offsets from the cell's
   centroid, c = centroid + J v_mean / omega, J the +90° turn) is the instantaneous centre of curvature of the cell's
   path: a cell sliding along a circular arc, or turning with a rigid body, has its centre there; a straight cell
   moving straight has none (omega ~ 0, c far away). Cells moving slower than ``min_cell_speed_vb`` v_b, or whose
   centre is farther than the largest radius searched (``max_radius_um``, at most 0.45 of the box), give no centre.
2. Seeds. Own centres (wrapped into the periodic box, counter-clockwise and clockwise separately) are counted within
   ``seed_radius_um`` (1.5 µm = 3 W) of each other with scipy's periodic cKDTree; the point with most neighbours
   (>= ``min_seed_cells``) is a seed (centre: mean of those neighbours), points within twice that radius are used up,
   and so on (a greedy density peak search).
3. Members. Each moving cell joins the seed it circulates about best: it must move tangentially (the angle between its
   velocity and the tangent of the seed's sense below acos(``cos_tangent``) = 36.9°, or its centroid within the core
   radius L/2 of the centre) and its own centre must agree with the seed's (distance <= ``centre_tol`` x its distance
   from the seed, i.e. curvature radius right within a factor ~2); among the seeds it qualifies for, the one with the
   smallest (centre misfit / distance) + (1 - cos of the angle) wins. Of each seed's members only the largest group
   of touching cells (scipy csgraph on the contact pairs) stays, so far cells that happen to point the right way do
   not join.
4. Centres. The centre is refined as the least-squares point on the member particles' normal lines (the lines
   through each particle perpendicular to its velocity), c = argmin sum ((c - x_p) . v_p/|v_p|)^2, speed-free so that
   uniform-speed (slime trail) aggregates are found as well as rigid ones. Steps 3-4 are repeated
   (``refine_iterations``); seeds of one sense whose centres come within ``merge_um`` (2 µm = 4 W), or within
   ``merge_fraction`` of the smaller one's radius, are merged (one aggregate found twice, e.g. its inner and outer
   rings).
5. Accepted when: >= ``min_cells`` (4) cells; the member particles outside the core cover >= ``min_coverage`` (75 %)
   of 16 angular sectors around the centre (a curved stream or an arc covers less); the member particles circulate:
   the mean of sense x cos(angle between velocity and tangent) >= ``min_circulation`` (0.7) and the circulation R^2
   (the fraction of the velocity variance about the mean velocity carried by tangential motion about the centre,
   1 - sum |v - (v.phi)phi|^2 / sum |v - <v>|^2) >= ``min_circulation_r2`` (0.5): a translating group (stream) has
   its variance in the mean, a jammed cluster has random directions; and >= ``min_inside_fraction`` (60 %) of the
   cells whose centroid lies within 0.9 of the members' largest centroid distance, not counting members of other
   groups, are members (a chance vortex in a
   dense, disordered crowd has most cells inside it going other ways). An accepted group lying wholly inside a larger
   one (centre distance + its disk radius <= the larger one's), of either sense, is a swirl within that aggregate and
   is dropped (a person counts the large aggregate once). Then each accepted aggregate takes the
   still-unassigned cells whose centroid lies inside half its outer radius and that touch its members (the slow,
   jammed core a person counts in the aggregate).

Per aggregate: centre (wrapped into the box); radius R = sqrt(2 <r^2> - a^2) over member particles, a = their 2nd
percentile distance (the outer radius of a uniform disk or annulus a..R with the same second moment; a is reported as
the inner radius, and the largest particle distance as R_edge); number of cells; sense; angular speed from tangential
velocities omega_tan = sum r v_t / sum r^2 over member particles (v_t = v . phi-hat, signed, > 0 counter-clockwise,
rad/min); the speed-against-radius fit: particle speed against r, least-squares line through the origin (slope
omega_fit, R^2 = 1 - SS_res / SS_tot about the mean) and with intercept (slope, intercept, R^2, standard error of the
slope with the number of cells as the number of independent samples); the rigidity test, the one the table, the text
and the plots use: the rigidity exponent alpha, the slope of ln speed against ln r over the member particles (1 for
rigid rotation, 0 for cells all at one speed; ``rigid`` when alpha >= 0.5; None when the particles span radii by less
than a factor of 2; aggregate_measure.rigidity_exponent, docs/figures.md "Rigidity"); with velocities, the
least-squares fit of v = omega x (r - c) to the member particles' velocities (``rotation_fit``: omega, centre, R^2;
not a rigidity test: cells all at v_b on circles give R^2 0.89-0.97). Edge speed = mean speed of the outermost ring
of segments, those within one cell width inside R (also as edge_speed / v_b), and the rigid fit's omega x R.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix, csgraph
from scipy.spatial import cKDTree

from ..physics.geometry import min_image
from .aggregate_measure import measure_aggregate
from .cells import CellGeometry
from .clusters import cell_clusters
from .params import fill_cell_defaults, parameters

N_SECTORS = 16


def _wrap(p: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Into [0, L) (np.mod can return L itself for tiny negative numbers; cKDTree refuses it)."""
    p = np.mod(p, L)
    return np.where(p >= L, 0.0, p)


def cell_rotation_centres(geo: CellGeometry):
    """Each cell's own rotation: (omega (n,), centre (n, 2) wrapped, offset from the centroid (n, 2), radius (n,)).
    The least-squares v = omega x (x - c) over the cell's particles (see the module docstring, step 1)."""
    x = geo.poff
    v = geo.vel
    inertia = (x * x).sum((1, 2))
    cross = (x[..., 0] * v[..., 1] - x[..., 1] * v[..., 0]).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        om = np.where(inertia > 0, cross / np.where(inertia > 0, inertia, 1.0), 0.0)
        off = np.stack([-geo.cvel[:, 1], geo.cvel[:, 0]], 1) / om[:, None]
    off = np.where(np.isfinite(off), off, np.inf)
    rad = np.hypot(off[:, 0], off[:, 1])
    ok = np.isfinite(rad)
    cen = np.full_like(off, np.nan)
    cen[ok] = _wrap(geo.cen[ok] + off[ok], geo.L)
    return om, cen, off, rad


def _seeds(pts: np.ndarray, L: np.ndarray, rho: float, min_n: int, max_seeds: int) -> list[np.ndarray]:
    if len(pts) < min_n:
        return []
    pts = _wrap(pts, L)
    tree = cKDTree(pts, boxsize=L)
    cnt = tree.query_ball_point(pts, rho, return_length=True)
    used = np.zeros(len(pts), bool)
    out = []
    for q in np.argsort(-cnt, kind="stable"):
        if cnt[q] < min_n or len(out) >= max_seeds:
            break
        if used[q]:
            continue
        nb = tree.query_ball_point(pts[q], rho)
        if len(nb) < min_n:
            continue
        c = pts[q] + min_image(pts[nb] - pts[q], L).mean(0)
        out.append(_wrap(c, L))
        used[tree.query_ball_point(pts[q], 2.0 * rho)] = True
    return out


def _assign(geo, C, S, own_c, own_ok, moving, P, Lam):
    """Step 3 without the contact pruning: the label (index into C, or -1) of each cell."""
    n, L = geo.n, geo.L
    lab = np.full(n, -1, np.int64)
    K = len(C)
    if K == 0 or n == 0:
        return lab
    tree = cKDTree(_wrap(geo.cen, L), boxsize=L)
    lists = tree.query_ball_point(_wrap(np.asarray(C), L), Lam)
    kk = np.repeat(np.arange(K), [len(x) for x in lists])
    if len(kk) == 0:
        return lab
    ii = np.concatenate([np.asarray(x, np.int64) for x in lists])
    d = min_image(geo.cen[ii] - C[kk], L)
    r = np.hypot(d[:, 0], d[:, 1])
    rs = np.where(r > 0, r, 1.0)
    sp = np.hypot(geo.cvel[:, 0], geo.cvel[:, 1])
    vh = geo.cvel / np.where(sp > 0, sp, 1.0)[:, None]
    a = S[kk] * (vh[ii, 0] * -d[:, 1] + vh[ii, 1] * d[:, 0]) / rs
    e = np.full(len(ii), np.inf)
    ok = own_ok[ii]
    if ok.any():
        de = min_image(own_c[ii[ok]] - C[kk[ok]], L)
        e[ok] = np.hypot(de[:, 0], de[:, 1])
    core = P["core_radius_um"]
    rel = e / np.maximum(r, core)
    in_core = r < core
    elig = (moving[ii] & (a >= P["cos_tangent"]) & (rel <= P["centre_tol"])) | in_core
    cost = np.where(in_core, r / core, np.minimum(rel, 2.0) + (1.0 - a))
    ii, kk, cost = ii[elig], kk[elig], cost[elig]
    order = np.lexsort((cost, ii))
    ii, kk = ii[order], kk[order]
    first = np.ones(len(ii), bool)
    first[1:] = ii[1:] != ii[:-1]
    lab[ii[first]] = kk[first]
    return lab


def _largest_touching(lab: np.ndarray, ci: np.ndarray, cj: np.ndarray) -> np.ndarray:
    """Keep, per label, only its largest group of touching cells (others -> -1)."""
    n = len(lab)
    m = (lab[ci] == lab[cj]) & (lab[ci] >= 0)
    g = coo_matrix((np.ones(int(m.sum())), (ci[m], cj[m])), shape=(n, n))
    comp = csgraph.connected_components(g, directed=False)[1]
    mem = np.nonzero(lab >= 0)[0]
    if len(mem) == 0:
        return lab
    key = lab[mem].astype(np.int64) * n + comp[mem]
    uk, cnt = np.unique(key, return_counts=True)
    best = {}
    for k_, c_ in zip(uk.tolist(), cnt.tolist()):
        l_ = k_ // n
        if c_ > best.get(l_, (0, -1))[0]:
            best[l_] = (c_, k_)
    keep = np.isin(key, [v[1] for v in best.values()])
    out = np.full(n, -1, np.int64)
    out[mem[keep]] = lab[mem[keep]]
    return out


def _particles(geo, cells: np.ndarray, c: np.ndarray):
    """Member particles relative to centre c: offsets (k, N, 2) (unwrapped per cell), distances, velocities."""
    dc = min_image(geo.cen[cells] - c, geo.L)
    rp = dc[:, None, :] + geo.poff[cells]
    return dc, rp, np.hypot(rp[..., 0], rp[..., 1]), geo.vel[cells]


def _normal_lines_centre(rp: np.ndarray, v: np.ndarray, w: np.ndarray | None = None):
    """Offset of the least-squares point on the lines through rp perpendicular to v: argmin sum ((c - x).u)^2."""
    rp = rp.reshape(-1, 2)
    v = v.reshape(-1, 2)
    s = np.hypot(v[:, 0], v[:, 1])
    keep = s > 0 if w is None else (s > 0) & w.reshape(-1)
    if keep.sum() < 3:
        return None
    u = v[keep] / s[keep, None]
    M = u.T @ u
    rhs = u.T @ (u * rp[keep]).sum(1)
    ev = np.linalg.eigvalsh(M)
    if ev[0] <= 0.05 * ev[1]:
        return None
    return np.linalg.solve(M, rhs)


def _refine(geo, C, S, lab, P):
    """Step 4: each label's centre on its members' normal lines (cells in the core left out); the radius."""
    C2, R = C.copy(), np.zeros(len(C))
    for k in range(len(C)):
        cells = np.nonzero(lab == k)[0]
        if len(cells) == 0:
            continue
        dc, rp, rpn, v = _particles(geo, cells, C[k])
        outer = (np.hypot(dc[:, 0], dc[:, 1]) >= P["core_radius_um"])[:, None] & np.ones(geo.N, bool)
        off = _normal_lines_centre(rp, v, outer if outer.sum() >= 3 * geo.N else None)
        if off is not None and np.hypot(*off) < P["core_radius_um"] + rpn.max():
            C2[k] = _wrap(C[k] + off, geo.L)
        R[k] = float(rpn.max())
    return C2, R


def _circulation(geo, c, sense, cells):
    """Mean sense x cos(angle between velocity and tangent) over the cells' moving particles farther than W from c."""
    dc, rp, rpn, v = _particles(geo, cells, c)
    rpf, vf, rr = rp.reshape(-1, 2), v.reshape(-1, 2), rpn.ravel()
    spd = np.hypot(vf[:, 0], vf[:, 1])
    m = (rr > geo.W) & (spd > 0)
    if not m.any():
        return 0.0
    return float((sense * (vf[m, 0] * -rpf[m, 1] + vf[m, 1] * rpf[m, 0]) / (rr[m] * spd[m])).mean())


def _merge(geo, C, S, R, lab, P):
    """Step 4's merge: two groups of one sense whose extents overlap are one aggregate when each of them circulates
    about their union's least-squares centre (circulation >= ``merge_circulation``), e.g. sectors or rings of one
    aggregate
    seeded twice; two aggregates of one sense side by side are not (near their contact the cells of each move
    across the joint circle). Closest pairs first. Returns (C, S, lab) with the merged groups relabelled."""
    C, lab = C.copy(), lab.copy()
    alive = np.bincount(lab[lab >= 0], minlength=len(C)) > 0
    pairs = []
    for k in range(len(C)):
        for l_ in range(k + 1, len(C)):
            if alive[k] and alive[l_] and S[k] == S[l_]:
                dist = float(np.hypot(*min_image(C[l_] - C[k], geo.L)))
                if dist < R[k] + R[l_]:
                    pairs.append((dist, k, l_))
    pairs.sort()
    for dist, k, l_ in pairs:
        if not (alive[k] and alive[l_]):
            continue
        cells = np.nonzero((lab == k) | (lab == l_))[0]
        nk, nl = (lab[cells] == k).sum(), (lab[cells] == l_).sum()
        c0 = C[k] + min_image(C[l_] - C[k], geo.L) * nl / (nk + nl)
        dc, rp, rpn, v = _particles(geo, cells, c0)
        off = _normal_lines_centre(rp, v)
        cj = _wrap(c0 + off, geo.L) if off is not None else _wrap(c0, geo.L)
        if min(_circulation(geo, cj, S[k], np.nonzero(lab == q)[0]) for q in (k, l_)) >= P["merge_circulation"]:
            keep, drop = (k, l_) if nk >= nl else (l_, k)
            lab[lab == drop] = keep
            C[keep] = cj
            R[keep] = float(_particles(geo, cells, cj)[2].max())
            alive[drop] = False
    idx = np.nonzero(alive)[0]
    remap = np.full(len(C), -1, np.int64)
    remap[idx] = np.arange(len(idx))
    lab = np.where(lab >= 0, remap[np.maximum(lab, 0)], -1)
    return C[idx], S[idx], lab


def _accept(geo, c, sense, cells, P, others=None):
    """Step 5 on one group of cells. Returns (ok, info)."""
    dc, rp, rpn, v = _particles(geo, cells, c)
    rpf, vf, rr = rp.reshape(-1, 2), v.reshape(-1, 2), rpn.ravel()
    spd = np.hypot(vf[:, 0], vf[:, 1])
    m = rr > geo.W
    phi = np.stack([-rpf[m, 1], rpf[m, 0]], 1) / rr[m, None]
    vt = (vf[m] * phi).sum(1)
    sec = np.unique((((np.arctan2(rpf[m, 1], rpf[m, 0]) + math.pi) / (2 * math.pi)) * N_SECTORS).astype(int)
                    % N_SECTORS)
    coverage = len(sec) / N_SECTORS
    mv = spd[m] > 0
    circulation = float((sense * vt[mv] / spd[m][mv]).mean()) if mv.any() else 0.0
    vm = vf[m]
    sst = float(((vm - vm.mean(0)) ** 2).sum()) if len(vm) else 0.0
    ssr = float(((vm - vt[:, None] * phi) ** 2).sum())
    r2c = 1.0 - ssr / sst if sst > 0 else float("nan")
    rc = np.hypot(dc[:, 0], dc[:, 1])
    sp_c = np.hypot(geo.cvel[cells, 0], geo.cvel[cells, 1])
    a_c = sense * (geo.cvel[cells, 0] * -dc[:, 1] + geo.cvel[cells, 1] * dc[:, 0]) / np.maximum(rc * sp_c, 1e-12)
    outer = rc >= P["core_radius_um"]
    circ = outer & (a_c >= P["cos_tangent"])
    # the cells a person sees inside the aggregate mostly circulate: members among all cells whose centroid lies
    # within 0.9 of the members' largest centroid distance (a chance vortex in a dense disordered crowd fails this)
    dall = min_image(geo.cen - c, geo.L)
    inside = np.hypot(dall[:, 0], dall[:, 1]) < max(0.9 * rc.max(), geo.W)
    if others is not None:
        inside &= ~others
    f_in = float(np.isin(np.nonzero(inside)[0], cells).sum() / max(inside.sum(), 1))
    ok = (len(cells) >= P["min_cells"] and coverage >= P["min_coverage"] and circulation >= P["min_circulation"]
          and math.isfinite(r2c) and r2c >= P["min_circulation_r2"] and f_in >= P["min_inside_fraction"])
    return ok, dict(members=cells, d=dc, r=rc, circ=circ,
                    f_circ=float(circ.sum() / outer.sum()) if outer.any() else 1.0,
                    coverage=coverage, circulation=circulation, circulation_r2=r2c, inside_fraction=f_in,
                    R_edge=float(rr.max()), R_inner=float(rr.min()), R_disk=_disk_radius(rr))


def _disk_radius(rr: np.ndarray) -> float:
    """Outer radius of the uniform disk or annulus with the particles' second moment (see measure_aggregate)."""
    a = float(np.percentile(rr, 2.0))
    return math.sqrt(max(2.0 * float((rr * rr).mean()) - a * a, 0.0))


def _drop_nested(accepted, C, L):
    """Accepted groups lying wholly inside a larger one (centre distance + own disk radius <= the larger one's disk
    radius), either sense: swirls within an aggregate, which a person counts as part of it, not as aggregates."""
    order = sorted(range(len(accepted)), key=lambda q: -accepted[q][1]["R_disk"])
    kept = []
    for q in order:
        k, info = accepted[q]
        inside = any(float(np.hypot(*min_image(C[k] - C[j], L))) + info["R_disk"] <= ij["R_disk"]
                     for j, ij in kept)
        if not inside:
            kept.append((k, info))
    return sorted(kept, key=lambda x: x[0])


def find_aggregates(geo_or_frame, clusters=None, v_b: float = 4.0, **params) -> list[dict]:
    """Detect circulating aggregates in one frame (see the module docstring for the criteria).

    geo_or_frame: a Frame (or its CellGeometry); clusters: (labels, sizes, pair_i, pair_j) of touching cells as
    cell_clusters returns them, computed when None. Returns a list of aggregate dicts (centre_um, radius_um, n_cells,
    omega_rad_per_min, edge_speed_vb, rotation_fit, ...), each with the member cell indices under "_members"."""
    geo = geo_or_frame if isinstance(geo_or_frame, CellGeometry) else CellGeometry(geo_or_frame)
    P = fill_cell_defaults(parameters(**params), geo)
    if clusters is None or len(clusters) < 4:
        clusters = cell_clusters(geo.pos, geo.L, geo.W, P["contact_tol_um"])
    ci, cj = clusters[2], clusters[3]
    L = geo.L
    Lam = min(P["max_radius_um"], 0.45 * float(L.min()))
    om, own_c, off, rad = cell_rotation_centres(geo)
    spd = np.hypot(geo.cvel[:, 0], geo.cvel[:, 1])
    moving = spd >= P["min_cell_speed_vb"] * v_b
    own_ok = moving & np.isfinite(rad) & (rad <= Lam)
    seeds, senses = [], []
    for s in (1, -1):
        sel = own_ok & (np.sign(om) == s)
        for c in _seeds(own_c[sel], L, P["seed_radius_um"], P["min_seed_cells"], P["max_seeds"]):
            seeds.append(c)
            senses.append(s)
    if not seeds:
        return []
    C, S = np.array(seeds), np.array(senses)
    lab = np.full(geo.n, -1, np.int64)
    for _ in range(P["refine_iterations"]):
        lab = _largest_touching(_assign(geo, C, S, own_c, own_ok, moving, P, Lam), ci, cj)
        C, R = _refine(geo, C, S, lab, P)
        C, S, lab = _merge(geo, C, S, R, lab, P)
        if len(C) == 0:
            return []
    lab = _largest_touching(_assign(geo, C, S, own_c, own_ok, moving, P, Lam), ci, cj)
    accepted = []
    for k in range(len(C)):
        cells = np.nonzero(lab == k)[0]
        if len(cells) < P["min_cells"]:
            continue
        ok, info = _accept(geo, C[k], int(S[k]), cells, P, others=(lab >= 0) & (lab != k))
        if ok:
            accepted.append((k, info))
    accepted = _drop_nested(accepted, C, L)
    # the enclosed core: unassigned cells inside half the outer radius that touch a member
    free = np.ones(geo.n, bool)
    for k, info in accepted:
        free[info["members"]] = False
    found = []
    for k, info in accepted:
        mem = info["members"]
        inm = np.zeros(geo.n, bool)
        inm[mem] = True
        touch = np.zeros(geo.n, bool)
        touch[cj[inm[ci]]] = True
        touch[ci[inm[cj]]] = True
        cand = np.nonzero(free & touch)[0]
        if len(cand):
            dd = min_image(geo.cen[cand] - C[k], L)
            add = cand[np.hypot(dd[:, 0], dd[:, 1]) < 0.5 * info["R_edge"]]
            if len(add):
                free[add] = False
                ok, info = _accept(geo, C[k], int(S[k]), np.concatenate([mem, add]), P,
                                   others=(lab >= 0) & (lab != k))
                info["accepted_with_core"] = ok
        agg = measure_aggregate(geo, C[k], int(S[k]), info, P, v_b)
        agg["_members"] = info["members"]
        found.append(agg)
    return found
