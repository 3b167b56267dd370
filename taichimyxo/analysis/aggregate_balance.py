"""Why a rotating aggregate turns at the speed it does: the torque balance of each aggregate a frame holds, split
into the factors that take the ideal disk's edge speed to the measured one (docs/measures.md, "The torque balance
of an aggregate").

For the member particles of one aggregate, about its centre (p = x - c, torques positive counter-clockwise), the
torque identity of rigid_body.py holds for any motion: the drag torque of the measured velocities,
sum p x (zeta . v), equals the torque of every force that does not act between two members. Those are

- ``drive``: the engines (F_e / N along each particle's axis) and the guiding pulls of active and passive following
  on the members' heads (no reaction: they drive), plus adhesion's pairs between two members (internal, only their
  small lever remains);
- ``adhesion_outside``: adhesion's pull and reaction where one end of the pair is not a member (a member's head held
  by an outside cell's tail, or an outside cell hanging on a member's tail);
- ``contacts_outside``: the rest, the contacts with cells that are not members (what the identity leaves).

``against``: the fraction of member particles whose axis points against the rotation (their engines brake it);
``bend_deg``: the members' median total bend, the sum of the angles between consecutive segments (0 for a straight
cell: an aggregate of straight cells is a polygon).

With D = sum zeta_t (p x u)^2 + zeta_n (p x n)^2 the rotational drag, the rigid-body model of the aggregate alone
(S2 Text on this very arrangement of cells) turns at omega_model = drive / D; the whole torque would turn it rigidly
at omega_balance = drag torque / D; it turns at omega_measured = sum r v_t / sum r^2 (its members' tangential
velocities about the centre). The edge speed chain, each factor a measurement:

    measured edge / disk  =  arrangement  x  outside  x  rotation  x  edge profile

with disk the ideal disk's edge speed (rigid_body.disk_edge_speed: (4/3) v_b, or 4 v_b for active following).
arrangement = omega_model r_edge / disk (cells not along circles, finite rods, pulls) = profile (the engines of
cells laid along circles at these radii, over the disk's (4/3) v_b: 1 for a uniform disk, 3/4 for one ring) x
alignment_torque (the engines' torque over that of cells along circles) x alignment_drag (zeta_t sum r^2 / D) x
pulls (the drive over the engines' torque, over the disk's 1 + F_max / F_e for active following);
outside = omega_balance / omega_model (torque lost to or gained from outside cells), rotation = omega_measured /
omega_balance (1 when the aggregate turns rigidly; the identity is exact, so only non-rigid motion moves it), edge
profile = measured edge speed / (omega_measured r_edge) (below 1 when the edge lags the rigid rotation). r_edge is
the mean distance of the edge segments, the outermost ring within one cell width inside R, as the measured edge
speed averages them.

Needs frames with particle velocities (the trajectories the simulator writes today); the pulls are those of the
default guiding reading (distance between segments, pull on the head particle, reaction on the tail particle).
"""
from __future__ import annotations

import numpy as np

from ..physics.geometry import min_image
from . import rigid_body as rb
from .cells import CellGeometry

# what summarise() takes the median of, in the order the tables show them
FACTORS = ("edge_speed", "model_edge_speed", "arrangement", "profile", "alignment_torque", "alignment_drag", "pulls",
           "outside", "rotation", "edge_profile", "against", "bend_deg")


def balance_params(scene) -> dict:
    """What the balance needs from a resolved Scene."""
    cell = scene.raw["cell"]
    if scene.guiding != "none" and (scene.guiding_by_particles or scene.guiding_pull_shared
                                    or scene.adhesion_reaction_shared):
        raise ValueError("aggregate_balance: only the default guiding reading (segments, head particle, tail "
                         "particle) is modelled")
    return dict(kind=scene.guiding, drag_ratio_normal=float(cell["drag_ratio_normal"]), v_b=scene.v_b_um_per_min,
                engine_force_pN=scene.engine_force, d_g=scene.guiding_range, f_max_pN=scene.guiding_f_max,
                self_follow=scene.guiding_self)


def frame_pairs(geo: CellGeometry, kind: str, d_g: float, f_max_pN: float, self_follow: bool):
    """The frame's guiding pairs (follower, leader, force on the follower's head (k, 2) pN); passive keeps only the
    part normal to the head's axis, as terms/guiding.py."""
    if kind == "none":
        return np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2))
    fi, lj, f, _ = rb.guiding_pairs(geo.pos, geo.ke, geo.L, geo.W, d_g, f_max_pN, self_follow)
    if kind == "passive":
        uh = rb.cell_axes(geo.pos, geo.ke)[np.arange(geo.n), rb._head_index(geo.ke, geo.N)][fi]
        f = f - (f * uh).sum(1, keepdims=True) * uh
    return fi, lj, f


def balance(geo: CellGeometry, members, centre, edge_speed: float, radius_um: float, pairs, kind: str,
            drag_ratio_normal: float, v_b: float, engine_force_pN: float, f_max_pN: float = rb.F_MAX) -> dict:
    """The torque balance of one aggregate (module docstring): members (cell indices), centre (µm, in the box),
    its measured edge speed and outer radius R, the frame's guiding pairs (frame_pairs)."""
    mem = np.asarray(members, int)
    c = np.asarray(centre, float)
    d = min_image(geo.cen[mem] - c, geo.L)
    x = d[:, None, :] + geo.poff[mem]                           # member particles about the centre
    ke = geo.ke[mem]
    N = geo.N
    u = rb.cell_axes(x, ke)
    zt, _ = rb.drag_coefficients(v_b, engine_force_pN, N, drag_ratio_normal)
    alone = rb.rigid_motion(x, ke, v_b, drag_ratio_normal, engine_force_pN, centre=(0.0, 0.0))
    engine, D = alone["drive_torque"], alone["rotational_drag"]       # the engines' torque, the rotational drag
    drive = engine
    v = geo.vel[mem]
    drag = rb.drag_torque(x, ke, v, v_b, drag_ratio_normal, engine_force_pN, centre=(0.0, 0.0))
    # guiding: each pair's force on a member's head (and adhesion's reaction on a member's tail)
    where = np.full(geo.n, -1)
    where[mem] = np.arange(len(mem))
    fi, lj, f = pairs
    hi, ti_ = rb._head_index(ke, N), rb._tail_index(ke, N)
    adh_out = 0.0
    mf, ml = where[fi] >= 0, where[lj] >= 0
    if len(fi):
        on_head = rb._cross(x[where[fi[mf]], hi[where[fi[mf]]]], f[mf])
        if kind == "adhesion":
            on_tail = -rb._cross(x[where[lj[ml]], ti_[where[lj[ml]]]], f[ml])
            drive += float(on_head[ml[mf]].sum() + on_tail[mf[ml]].sum())
            adh_out = float(on_head[~ml[mf]].sum() + on_tail[~mf[ml]].sum())
        else:
            drive += float(on_head.sum())
    r = np.hypot(x[..., 0], x[..., 1])
    phi = np.stack([-x[..., 1], x[..., 0]], -1) / np.maximum(r, 1e-12)[..., None]
    om_meas = float((r * (v * phi).sum(-1)).sum() / (r * r).sum())
    sense = 1.0 if drive >= 0 else -1.0
    against = float((sense * (phi * u).sum(-1) < 0).mean())       # particles whose engine opposes the rotation
    dx = np.diff(x, axis=1)
    bend = np.degrees(np.abs(np.arctan2(rb._cross(dx[:, :-1], dx[:, 1:]), (dx[:, :-1] * dx[:, 1:]).sum(-1)))).sum(1)
    seg = 0.5 * (x[:, 1:] + x[:, :-1])
    rseg = np.hypot(seg[..., 0], seg[..., 1]).ravel()
    ring = rseg >= radius_um - geo.W
    r_edge = float(rseg[ring].mean() if ring.any() else rseg.max())
    om_model, om_bal = drive / D, drag / D
    # the arrangement split: cells laid along circles at these radii would turn at om_aligned
    f_e = engine_force_pN / N
    om_aligned = f_e * float(r.sum()) / (zt * float((r * r).sum()))
    disk = rb.disk_edge_speed(kind, v_b, f_max_pN, engine_force_pN)
    disk_engines = rb.disk_edge_speed("none", v_b)
    return dict(n_cells=int(len(mem)), radius_um=float(radius_um), edge_speed=float(edge_speed),
                model_edge_speed=abs(om_model) * r_edge, r_edge_um=r_edge, disk_edge_speed=disk,
                omega_model=om_model, omega_balance=om_bal, omega_measured=om_meas,
                arrangement=abs(om_model) * r_edge / disk, profile=om_aligned * r_edge / disk_engines,
                alignment_torque=abs(engine) / (f_e * float(r.sum())), alignment_drag=zt * float((r * r).sum()) / D,
                pulls=(drive / engine if engine else float("nan")) * disk_engines / disk,
                outside=om_bal / om_model if om_model else float("nan"),
                rotation=om_meas / om_bal if om_bal else float("nan"),
                edge_profile=float(edge_speed) / (abs(om_meas) * r_edge) if om_meas else float("nan"),
                against=against, bend_deg=float(np.median(bend)), drive=drive, adhesion_outside=adh_out,
                contacts_outside=drag - drive - adh_out, drag_torque=drag)


def frame_balances(frame, aggregates, params: dict) -> list[dict]:
    """balance() of every aggregate find_aggregates returned for `frame` (dicts with _members, centre_um,
    radius_um, edge_speed_um_per_min). The frame must carry particle velocities."""
    if frame.particle_velocity is None:
        raise ValueError("aggregate_balance: the frame has no particle velocities (a trajectory written before "
                         "they were logged)")
    geo = CellGeometry(frame)
    pairs = frame_pairs(geo, params["kind"], params["d_g"], params["f_max_pN"], params["self_follow"])
    return [balance(geo, a["_members"], a["centre_um"], a["edge_speed_um_per_min"], a["radius_um"], pairs,
                    params["kind"], params["drag_ratio_normal"], params["v_b"], params["engine_force_pN"],
                    params["f_max_pN"])
            for a in aggregates]


def summarise(rows: list[dict], min_radius_um: float = 0.0, max_radius_um: float = float("inf")) -> dict:
    """Medians (and quartiles) of each factor over the aggregates with min_radius_um <= R < max_radius_um, the
    torques as fractions of the drive (summed over aggregates, signed so that a drag on the rotation is negative),
    and the Spearman rank correlation of the measured edge speed with the alignment (torque) across aggregates."""
    from scipy.stats import spearmanr
    rows = [r for r in rows if min_radius_um <= r["radius_um"] < max_radius_um]
    out = dict(n=len(rows))
    if not rows:
        return out
    for k in FACTORS:
        a = np.array([r[k] for r in rows], float)
        a = a[np.isfinite(a)]
        out[k] = [float(q) for q in np.percentile(a, [50, 25, 75])] if len(a) else [float("nan")] * 3
    sense = np.sign([r["drive"] for r in rows])
    drive = float((sense * [r["drive"] for r in rows]).sum())
    for k in ("adhesion_outside", "contacts_outside"):
        out[k + "_over_drive"] = float((sense * [r[k] for r in rows]).sum()) / drive if drive else float("nan")
    e, al = np.array([r["edge_speed"] for r in rows]), np.array([r["alignment_torque"] for r in rows])
    ok = np.isfinite(e) & np.isfinite(al)
    out["rho_edge_alignment"] = (float(spearmanr(e[ok], al[ok]).statistic) if ok.sum() >= 3 and np.ptp(e[ok]) > 0
                                 and np.ptp(al[ok]) > 0 else float("nan"))
    return out
