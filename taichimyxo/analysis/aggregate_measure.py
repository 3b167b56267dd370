"""What is measured on each rotating aggregate once it is found (aggregates.py finds them; its docstring lists the
quantities and the rigid-body test)."""
from __future__ import annotations

import math

import numpy as np

from .cells import CellGeometry
from .params import R_BINS
from .stats import ols, rigid_rotation_fit

# rigid when the speed grows with the radius at least as r^0.5: nearer rigid rotation (r^1) than one speed (r^0)
RIGID_EXPONENT = 0.5
# the exponent needs particles over at least this ratio of radii (a single ring of cells has none)
MIN_RADIUS_RATIO = 2.0


def rigidity_exponent(r: np.ndarray, speed: np.ndarray, W: float, v_b: float) -> float | None:
    """The rigidity exponent alpha of an aggregate: the least-squares slope of ln(speed) against ln(r) over its
    particles at r >= W (nearer the centre r is within the centre's error), speeds floored at 0.05 v_b (a jammed
    particle has no logarithm). Rigid rotation, v = omega r: alpha = 1; every cell at one speed on circles (slime
    trails, or any flow of cells at v_b): alpha = 0. None when the particles span radii by less than
    MIN_RADIUS_RATIO (docs/figures.md, "Rigidity")."""
    m = r >= W
    if m.sum() < 3 or r[m].max() < MIN_RADIUS_RATIO * r[m].min():
        return None
    x, y = np.log(r[m]), np.log(np.maximum(speed[m], 0.05 * v_b))
    sxx = float(((x - x.mean()) ** 2).sum())
    return float(((x - x.mean()) * (y - y.mean())).sum() / sxx) if sxx > 0 else None


def radial_profile(r_over_R: np.ndarray, weights: np.ndarray):
    """(sum of weights, count) in each r / R bin of R_BINS, values beyond the last edge in the last bin."""
    b = np.clip(np.digitize(r_over_R, R_BINS) - 1, 0, len(R_BINS) - 2)
    return (np.bincount(b, weights=weights, minlength=len(R_BINS) - 1),
            np.bincount(b, minlength=len(R_BINS) - 1).astype(float))


def measure_aggregate(geo: CellGeometry, c: np.ndarray, sense: int, info: dict, P: dict, v_b: float) -> dict:
    """One accepted aggregate measured (the quantities listed at the end of aggregates.py's docstring): centre,
    radii, angular speeds, the rigid-body test, edge speed, rotation fit and the pooled speed / strain profiles.
    info: what the acceptance step found (members, their offsets d and distances r from the centre, R_edge, ...)."""
    mem = info["members"]
    rp = info["d"][:, None, :] + geo.poff[mem]
    rpn = np.hypot(rp[..., 0], rp[..., 1]).ravel()
    vp = geo.vel[mem].reshape(-1, 2)
    rpf = rp.reshape(-1, 2)
    sp = geo.pspeed[mem].ravel()
    m = rpn > 1e-9
    phi = np.stack([-rpf[m, 1], rpf[m, 0]], 1) / rpn[m, None]
    vt = (vp[m] * phi).sum(1)                                     # signed tangential velocity, > 0 CCW
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
    # edge: the outermost ring of segments, one cell width inside the outer radius R (not whole cells: in an
    # aggregate smaller than a cell the centres of the outer cells sit well inside R)
    seg = info["d"][:, None, :] + 0.5 * (geo.poff[mem][:, 1:] + geo.poff[mem][:, :-1])
    rseg = np.hypot(seg[..., 0], seg[..., 1]).ravel()
    sseg = (0.5 * (geo.pspeed[mem][:, 1:] + geo.pspeed[mem][:, :-1])).ravel()
    ring = rseg >= R - geo.W
    edge = float(sseg[ring].mean() if ring.any() else sseg[np.argsort(rseg)[-max(1, len(rseg) // 10):]].mean())
    ratio = omega_fit / abs(omega_tan) if omega_tan and math.isfinite(omega_tan) else float("nan")
    alpha = rigidity_exponent(r_, s_, geo.W, v_b)
    rigid = bool(alpha is not None and alpha >= RIGID_EXPONENT)
    out = dict(
        time_min=geo.t_min, centre_um=[float(c[0]), float(c[1])], radius_um=R, radius_edge_um=info["R_edge"],
        radius_inner_um=a_in, n_cells=int(len(mem)), sense=int(sense),
        omega_rad_per_min=omega_tan, omega_fit_rad_per_min=omega_fit, omega_fit_over_omega_tan=ratio,
        r2_origin=r2_origin, linear_fit=lin, rigidity_exponent=alpha, rigid=rigid,
        edge_speed_um_per_min=edge, edge_speed_vb=edge / v_b,
        edge_speed_rigid_um_per_min=omega_fit * R, edge_speed_rigid_vb=omega_fit * R / v_b,
        mean_speed_um_per_min=float(geo.cspeed[mem].mean()), fraction_circulating=info["f_circ"],
        coverage=info["coverage"], circulation=info["circulation"], circulation_r2=info["circulation_r2"],
        inside_fraction=info["inside_fraction"],
    )
    if geo.pvel is not None:
        # v = omega x (r - c) fitted to the members' particle velocities (positions relative to the detected
        # centre, unwrapped): the rotation's own centre, rate and how rigid it is (R^2)
        fit = rigid_rotation_fit(rpf, geo.pvel[mem].reshape(-1, 2))
        cen = np.mod(np.asarray(c, float) + np.nan_to_num(np.asarray(fit["centre"])), geo.L)
        out["rotation_fit"] = dict(omega_rad_per_min=fit["omega"], r2=fit["r2"],
                                   centre_um=[float(x) for x in cen] if math.isfinite(fit["omega"]) else None)
        if math.isfinite(fit["omega"]):           # the rigid fit's omega at the outer radius
            out["edge_speed_rigid_um_per_min"] = abs(fit["omega"]) * R
            out["edge_speed_rigid_vb"] = abs(fit["omega"]) * R / v_b
    # pooled profiles (not written per aggregate)
    out["_speed_prof"] = radial_profile(rpn / R, sp / v_b)
    out["_scatter"] = (rpn, sp)
    if geo.strain is not None and geo.N > 1:
        sg = info["d"][:, None, :] + 0.5 * (geo.poff[mem][:, 1:] + geo.poff[mem][:, :-1])
        rs = np.hypot(sg[..., 0], sg[..., 1]).ravel() / R
        e = geo.strain[mem].ravel()
        out["_strain_prof"] = radial_profile(rs, e)
        inner, outr = e[rs < 0.5], e[(rs >= 0.5) & (rs <= 1.0)]
        out["strain_inner_over_outer"] = (float(inner.mean() / outr.mean())
                                          if len(inner) and len(outr) and outr.mean() > 0 else float("nan"))
    return out
