"""The rigid-body model of a rotating aggregate (taichimyxo/analysis/rigid_body.py) on known answers: the paper's
continuous disk (4/3 v_b, 4 v_b), a ring of bent cells (v_b), a straight rod (the closed form with zeta_n sum s^2),
the drag ratio's role, units, and the guiding pulls against the simulator's own."""
from __future__ import annotations

import math

import numpy as np
import pytest

from taichimyxo.analysis import rigid_body as rb


def dense_disk(R=20.0, dr=0.1, N=8, l0=0.05, clockwise=False):
    """A continuous-like disk: rings dr apart of short cells bent along circles, as many per ring as fit (density
    uniform), all moving the same way round. Returns (positions, engine_direction, outer radius R)."""
    cells = []
    r = dr / 2
    while r < R:
        m = max(1, int(2 * math.pi * r / (N * l0)))
        pos, _ = rb.bent_ring(r, m, N, l0, clockwise=clockwise)
        cells.append(pos)
        r += dr
    pos = np.concatenate(cells)
    return pos, np.ones(len(pos), np.int8), r - dr / 2


@pytest.mark.parametrize("rho", [0.5, 1.0, 2.0])
def test_a_dense_disk_of_cells_along_circles_turns_at_the_papers_four_thirds_v_b(rho):
    pos, ke, R = dense_disk()
    om = rb.rigid_omega(pos, ke, v_b=4.0, drag_ratio_normal=rho, centre=(0, 0))
    assert om * R == pytest.approx(4.0 / 3.0 * 4.0, rel=0.01)
    assert rb.disk_edge_speed("adhesion") == pytest.approx(16 / 3)          # 5.3 µm/min
    assert rb.disk_edge_speed("none") == rb.disk_edge_speed("passive") == rb.disk_edge_speed("adhesion")


def test_a_dense_disk_pulled_at_f_max_turns_at_four_v_b():
    pos, ke, R = dense_disk()
    om = rb.rigid_omega(pos, ke, v_b=4.0, drag_ratio_normal=0.5, guiding_pull_pN=200.0, centre=(0, 0))
    assert om * R == pytest.approx(16.0, rel=0.01)
    assert rb.disk_edge_speed("active") == pytest.approx(16.0)
    assert rb.disk_edge_speed("active", f_max_pN=100.0) == pytest.approx(4 / 3 * 2 * 4.0)
    with pytest.raises(ValueError):
        rb.disk_edge_speed("slime")


def test_clockwise_rotation_is_negative_omega_of_the_same_size():
    pos, ke, R = dense_disk(R=8.0, clockwise=True)
    om = rb.rigid_omega(pos, ke, centre=(0, 0))
    assert om < 0 and -om * R == pytest.approx(16 / 3, rel=0.01)


@pytest.mark.parametrize("rho", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("n_cells", [1, 3, 7])
def test_a_ring_of_cells_bent_along_a_circle_moves_at_v_b_whatever_the_drag_ratio(rho, n_cells):
    r = 6.0
    pos, ke = rb.bent_ring(r, n_cells)
    om = rb.rigid_omega(pos, ke, v_b=4.0, drag_ratio_normal=rho, centre=(0, 0))
    # the poles' axes are chords, off the tangent by half a segment's angle: (l0 / 2r)^2 / 2 ~ 1e-3
    assert om * r == pytest.approx(4.0, rel=2e-3)
    # units: rad/min, scaling with v_b, not with the engine force (zeta_t scales with it)
    assert rb.rigid_omega(pos, ke, v_b=8.0, drag_ratio_normal=rho, centre=(0, 0)) == pytest.approx(2 * om)
    assert rb.rigid_omega(pos, ke, v_b=4.0, drag_ratio_normal=rho, engine_force_pN=50.0, centre=(0, 0)) == \
        pytest.approx(om)
    assert om == pytest.approx(4.0 / 6.0, rel=2e-3)                  # 0.667 rad/min for v_b = 4 µm/min, r = 6 µm


@pytest.mark.parametrize("rho", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("h", [0.5, 2.0, 7.0])
def test_a_straight_rod_turns_at_the_closed_form_with_the_normal_drag_of_its_length(rho, h):
    N, l0, v_b, Fe = 8, 4.5 / 7, 4.0, 100.0
    pos, s = rb.straight_rod(h, phi=0.3)
    om = rb.rigid_omega(pos[None], [1], v_b=v_b, drag_ratio_normal=rho, engine_force_pN=Fe, centre=(0, 0))
    f = Fe / N
    zt = f / v_b
    expected = N * f * h / (zt * N * h * h + rho * zt * (s * s).sum())
    assert om == pytest.approx(expected, rel=1e-12)
    assert (s * s).sum() == pytest.approx(N * rb.rod_sigma2(N, l0))
    # the drag ratio lowers omega for chords; engine direction -1 (particle N-1 the head) reverses it
    assert rb.rigid_omega(pos[None], [1], drag_ratio_normal=2 * rho, centre=(0, 0)) < om
    assert rb.rigid_omega(pos[None, ::-1], [-1], v_b=v_b, drag_ratio_normal=rho, centre=(0, 0)) == \
        pytest.approx(om)
    # a pull on the head along its axis adds F_g h to the drive
    om_p = rb.rigid_omega(pos[None], [1], v_b=v_b, drag_ratio_normal=rho, guiding_pull_pN=50.0, centre=(0, 0))
    assert om_p == pytest.approx(om * (1 + 50.0 / Fe))


def test_the_drag_ratio_matters_for_chords_and_not_for_circles():
    pos, ke = rb.bent_ring(5.0, 3)
    on_circle = [rb.rigid_omega(pos, ke, drag_ratio_normal=r, centre=(0, 0)) for r in (0.5, 1.0, 2.0)]
    assert max(on_circle) / min(on_circle) < 1.003
    chords = [rb.rod_ring_edge_speed(5.0, r)["edge_speed"] for r in (0.5, 1.0, 2.0)]
    assert chords[0] > chords[1] > chords[2]
    assert chords[2] / chords[0] < 0.85                              # at R = L the drag ratio costs > 15 %


def test_rings_of_rods_approach_the_disk_and_their_closed_form():
    for rho in (0.5, 1.0, 2.0):
        big = rb.rod_ring_edge_speed(50.0, rho)
        assert big["ratio_to_disk"] == pytest.approx(1.0, abs=0.01)
        for R in (5.0, 10.0, 20.0):
            ring = rb.rod_ring_edge_speed(R, rho)
            closed = rb.rod_disk_edge_speed(R, rho)
            assert ring["edge_speed"] == pytest.approx(closed["edge_speed"], rel=0.04)
            assert ring["R_um"] == pytest.approx(R, abs=1e-9)
    # active at F_max scales the same geometry by 1 + F_max / F_e
    assert rb.rod_ring_edge_speed(10.0, 1.0, "active")["edge_speed"] == \
        pytest.approx(3 * rb.rod_ring_edge_speed(10.0, 1.0)["edge_speed"])
    rows = rb.edge_speed_table(R_over_L=(1.0, 4.0))
    assert len(rows) == 6 and all(0.3 < r["rings_ratio"] < 1.2 for r in rows)
    with pytest.raises(ValueError):
        rb.rod_rings(2.0)


def test_free_translation_and_the_torque_identity_on_a_rigid_motion():
    pos, ke, _ = rb.rod_rings(8.0)
    fixed = rb.rigid_motion(pos, ke, drag_ratio_normal=1.0, centre=(0, 0))
    free = rb.rigid_motion(pos, ke, drag_ratio_normal=1.0, centre=(0, 0), translate=True)
    assert free["omega"] == pytest.approx(fixed["omega"], rel=0.02)
    assert np.hypot(*free["velocity"]) < 0.05
    # velocities of the rigid rotation give a drag torque equal to the drive torque
    p = pos - 0.0
    v = fixed["omega"] * np.stack([-p[..., 1], p[..., 0]], axis=-1)
    assert rb.drag_torque(pos, ke, v, drag_ratio_normal=1.0, centre=(0, 0)) == pytest.approx(fixed["drive_torque"])
    # a single rod: free to translate it moves at v_b along itself and does not turn
    rod, _ = rb.straight_rod(3.0)
    one = rb.rigid_motion(rod[None], [1], centre=(0, 0), translate=True)
    assert abs(one["omega"]) < 1e-12 and np.hypot(*one["velocity"]) == pytest.approx(4.0)


def test_guiding_pulls_follow_the_guiding_law():
    W, dg, Fmax = 0.5, 0.25, 200.0
    lead, _ = rb.straight_rod(0.0, 0.0)                 # along +y round the origin: head at top
    lead = lead + np.array([0.0, 0.0])
    for g, want in [(0.05, 40.0), (0.2, 160.0), (0.3, 0.0), (-0.1, 0.0)]:
        follower = lead - np.array([0.0, (lead[0, 1] - lead[-1, 1]) + W + g])
        pull, gap = rb.guiding_pulls(np.stack([lead, follower]), [1, 1], W=W, d_g=dg, f_max_pN=Fmax)
        assert np.linalg.norm(pull[1]) == pytest.approx(want, abs=1e-9)
        if want:
            assert pull[1, 1] > 0 and gap[1] == pytest.approx(g)
        assert np.linalg.norm(pull[0]) == 0.0


def test_spiral_prediction_of_a_small_spiral():
    from taichimyxo.io.scene import Scene
    sc = Scene.load("S9", {"domain": {"width_um": 40, "height_um": 40}, "population": {"cells": 110}})
    p = rb.spiral_prediction(sc)
    assert p["n_cells"] == 110 and 9.0 < p["R_um"] < 11.5
    assert p["omega"] < 0                                # heads inward along the spiral: clockwise
    assert p["edge_speed_no_pull"] == pytest.approx(16 / 3, rel=0.1)
    assert p["edge_speed_no_pull"] < p["edge_speed"] < p["edge_speed_fmax"] <= 16.0 * 1.05
    # the start's gaps are 0.05 µm, a pull of k_g g = 40 pN per leader
    assert 30.0 < p["mean_start_pull_pN"] < 80.0


def test_guiding_pulls_match_the_simulators_on_a_spiral_start():
    """The numpy guiding law against terms/guiding.py on the same start (one compile, ~10-20 s)."""
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime.simulation import Simulation
    sc = Scene.load("S9", {"domain": {"width_um": 30, "height_um": 30}, "population": {"cells": 19}})
    sim = Simulation(sc)
    try:
        sim.forces()
        g_sim = sim.model.head_to_tail.g_head.to_numpy()
        pos, ke = sim.positions(), sim.engine_direction()
    finally:
        sim.close()
    pull, _ = rb.guiding_pulls(pos, ke, sc.box, sc.width, sc.guiding_range, sc.guiding_f_max)
    np.testing.assert_allclose(pull, g_sim, atol=2e-3 * sc.guiding_f_max)
    assert (np.linalg.norm(g_sim, axis=1) > 0).sum() >= 10
