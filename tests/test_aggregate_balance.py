"""The torque balance of an aggregate (taichimyxo/analysis/aggregate_balance.py) on known answers: a rigid ring of
bent cells (the arrangement factor in closed form, nothing outside), an outside cell hanging on a member's tail by
adhesion (its torque by hand), and two rings at one speed (the edge lags the rigid rotation by a known factor)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from taichimyxo.analysis import aggregate_balance as ab
from taichimyxo.analysis import rigid_body as rb
from taichimyxo.analysis.cells import CellGeometry
from taichimyxo.io.frame import Frame

BOX, C = (100.0, 100.0), np.array([50.0, 50.0])
V_B, N, L0, W = 4.0, 8, 4.5 / 7, 0.5
P = dict(kind="adhesion", drag_ratio_normal=0.5, v_b=V_B, engine_force_pN=100.0, d_g=0.25, f_max_pN=200.0,
         self_follow=True)


def frame(pos, ke, vel):
    vel = np.asarray(vel, float)
    return Frame(time_s=0.0, step=0, box=BOX, width_um=W, positions=np.asarray(pos, float),
                 engine_direction=np.asarray(ke, np.int8), particle_speed=np.hypot(vel[..., 0], vel[..., 1]),
                 particle_velocity=vel)


def rigid(pos, omega):
    p = np.asarray(pos, float) - C
    return omega * np.stack([-p[..., 1], p[..., 0]], -1)


def ring(r, n):
    pos, ke = rb.bent_ring(r, n, N, L0, centre=tuple(C))
    return pos, ke, 2.0 * math.asin(L0 / (2 * r))


def one(fr, members, R, edge, **kw):
    geo = CellGeometry(fr)
    q = dict(P, **kw)
    pairs = ab.frame_pairs(geo, q["kind"], q["d_g"], q["f_max_pN"], q["self_follow"])
    return ab.balance(geo, members, C, edge, R, pairs, q["kind"], q["drag_ratio_normal"], q["v_b"],
                      q["engine_force_pN"], q["f_max_pN"])


def test_a_rigid_ring_of_bent_cells_alone_turns_as_the_model_and_its_arrangement_is_a_ring_s():
    r = 5.0
    pos, ke, dphi = ring(r, 3)                  # wide gaps: no guiding pair
    b0 = one(frame(pos, ke, np.zeros_like(pos)), [0, 1, 2], r, 0.0)
    om = b0["omega_model"]
    r_edge = r * math.cos(dphi / 2)            # the segments' midpoints
    b = one(frame(pos, ke, rigid(pos, om)), [0, 1, 2], r, abs(om) * r_edge)
    assert om * r == pytest.approx(V_B, rel=0.02)          # a ring of cells along a circle: omega r = v_b
    assert b["outside"] == pytest.approx(1.0, abs=1e-9)
    assert b["rotation"] == pytest.approx(1.0, abs=1e-9)
    assert b["edge_profile"] == pytest.approx(1.0, abs=1e-9)
    assert b["contacts_outside"] == pytest.approx(0.0, abs=1e-9 * abs(b["drive"]))
    # cells laid along circles at one radius: three quarters of the disk's (4/3) v_b at the edge ring's radius
    assert b["profile"] == pytest.approx(0.75 * r_edge / r, rel=1e-9)
    # the end particles' axes are their end segments' chords, cos(dphi / 2) off the tangent; the inner ones tangent
    assert b["alignment_torque"] == pytest.approx((N - 2 + 2 * math.cos(dphi / 2)) / N, rel=1e-9)
    assert b["arrangement"] == pytest.approx(b["model_edge_speed"] / b["disk_edge_speed"], rel=1e-12)
    assert b["against"] == 0.0
    assert b["bend_deg"] == pytest.approx(math.degrees((N - 2) * dphi), rel=1e-9)
    assert b["arrangement"] == pytest.approx(b["profile"] * b["alignment_torque"] * b["alignment_drag"] * b["pulls"])
    ke[2] = -1                                 # one cell turned round: its engine brakes the other two
    b = one(frame(pos, ke, np.zeros_like(pos)), [0, 1, 2], r, 0.0)
    assert b["against"] == pytest.approx(1 / 3)
    assert b["alignment_torque"] == pytest.approx((N - 2 + 2 * math.cos(dphi / 2)) / N / 3, rel=1e-9)


def test_an_outside_cell_hanging_on_a_members_tail_by_adhesion_brakes_the_aggregate_by_its_torque():
    r = 5.0
    pos, ke, _ = ring(r, 3)
    tail = pos[0, -1]
    back = pos[0, -1] - pos[0, -2]
    back /= np.linalg.norm(back)
    gap = 0.1
    head = tail + (W + gap) * back             # the outside cell's head behind member 0's tail, pointing at it
    out = head[None, :] + back[None, :] * L0 * np.arange(N)[:, None]
    allpos = np.concatenate([pos, out[None]])
    allke = np.concatenate([ke, [1]])
    f = (200.0 / 0.25) * gap * (-back)          # the pull on the outside head, toward the tail; minus it on the tail
    by_hand = -float(rb._cross(tail - C, f))
    b0 = one(frame(allpos, allke, np.zeros_like(allpos)), [0, 1, 2], r, 0.0)
    assert b0["adhesion_outside"] == pytest.approx(by_hand, rel=1e-9)
    om = (b0["drive"] + by_hand) / (b0["drive"] / b0["omega_model"])
    b = one(frame(allpos, allke, rigid(allpos, om)), [0, 1, 2], r, 1.0)
    assert b["outside"] == pytest.approx((b0["drive"] + by_hand) / b0["drive"], rel=1e-9)
    assert b["outside"] < 1.0                  # hanging on a tail, behind the rotation: a brake
    assert b["contacts_outside"] == pytest.approx(0.0, abs=1e-9 * abs(b["drive"]))
    # the same cell with active following pulls only its own head: nothing acts on the members
    assert one(frame(allpos, allke, np.zeros_like(allpos)), [0, 1, 2], r, 0.0, kind="active")["adhesion_outside"] == 0


def test_two_rings_at_one_speed_turn_by_their_torque_and_their_edge_lags_the_rigid_rotation():
    r1, r2 = 2.0, 5.0
    p1, k1, _ = ring(r1, 1)
    p2, k2, dphi2 = ring(r2, 3)
    pos = np.concatenate([p1, p2])
    ke = np.concatenate([k1, k2])
    p = pos - C
    rr = np.hypot(p[..., 0], p[..., 1])
    vel = V_B * np.stack([-p[..., 1], p[..., 0]], -1) / rr[..., None]          # every particle at v_b, on circles
    b = one(frame(pos, ke, vel), [0, 1, 2, 3], r2, V_B)
    om_meas = V_B * rr.sum() / (rr ** 2).sum()
    assert b["omega_measured"] == pytest.approx(om_meas, rel=1e-9)
    assert b["edge_profile"] == pytest.approx(V_B / (om_meas * r2 * math.cos(dphi2 / 2)), rel=1e-9)
    assert b["edge_profile"] < 1.0


def test_a_frame_without_velocities_is_refused_by_name():
    pos, ke, _ = ring(5.0, 3)
    fr = frame(pos, ke, np.zeros_like(pos))
    fr.particle_velocity = None
    with pytest.raises(ValueError, match="no particle velocities"):
        ab.frame_balances(fr, [], P)


def test_the_summary_takes_medians_and_signs_the_outside_torques_against_the_rotation():
    rows = [dict(radius_um=4.0, edge_speed=1.0, model_edge_speed=2.0, arrangement=0.5, profile=1.0,
                 alignment_torque=0.5, alignment_drag=1.0, pulls=1.0, bend_deg=0.0, outside=0.9, rotation=1.0,
                 edge_profile=1.0,
                 against=0.0, drive=s * 10.0, adhesion_outside=-s * 1.0, contacts_outside=-s * 0.5) for s in (1, -1)]
    rows.append(dict(rows[0], radius_um=1.0, arrangement=9.0))
    s = ab.summarise(rows, min_radius_um=3.0)
    assert s["n"] == 2 and s["arrangement"][0] == 0.5
    assert s["adhesion_outside_over_drive"] == pytest.approx(-0.1)
    assert s["contacts_outside_over_drive"] == pytest.approx(-0.05)


def test_active_following_of_an_outside_leader_drives_the_member_by_its_pull():
    r = 5.0
    pos, ke, _ = ring(r, 3)
    head = pos[0, 0]
    fwd = pos[0, 0] - pos[0, 1]
    fwd /= np.linalg.norm(fwd)
    gap = 0.1
    tail = head + (W + gap) * fwd               # an outside leader's tail just ahead of member 0's head
    lead = tail[None, :] + fwd[None, :] * L0 * (N - 1 - np.arange(N))[:, None]
    allpos = np.concatenate([pos, lead[None]])
    allke = np.concatenate([ke, [1]])
    b0 = one(frame(allpos, allke, np.zeros_like(allpos)), [0, 1, 2], r, 0.0)
    b = one(frame(allpos, allke, np.zeros_like(allpos)), [0, 1, 2], r, 0.0, kind="active")
    by_hand = float(rb._cross(head - C, (200.0 / 0.25) * gap * fwd))
    assert b["drive"] - b0["drive"] == pytest.approx(by_hand, rel=1e-9)     # adhesion: the same pull is outside
    assert b0["adhesion_outside"] == pytest.approx(by_hand, rel=1e-9)
    assert b["pulls"] == pytest.approx(b["drive"] / b0["drive"] / 3.0, rel=1e-9)   # the disk's 1 + F_max / F_e = 3


def test_the_summary_keeps_a_radius_window_and_ranks_the_edge_speed_against_the_alignment():
    base = dict(model_edge_speed=1.0, arrangement=0.5, profile=1.0, alignment_drag=1.0, pulls=1.0, bend_deg=0.0,
                outside=1.0, rotation=1.0, edge_profile=1.0, against=0.0, drive=1.0, adhesion_outside=0.0,
                contacts_outside=0.0)
    rows = [dict(base, radius_um=3.0 + k, edge_speed=1.0 + k, alignment_torque=0.1 * (k + 1)) for k in range(5)]
    assert ab.summarise(rows)["rho_edge_alignment"] == pytest.approx(1.0)
    s = ab.summarise(rows, 4.0, 6.0)
    assert s["n"] == 2 and s["edge_speed"][0] == pytest.approx(2.5)
    rows[0]["alignment_torque"] = 9.0            # the slowest now best aligned: the ranks no longer agree
    assert ab.summarise(rows)["rho_edge_alignment"] == pytest.approx(0.0)
