"""The equation of motion (docs/model.md): drag is anisotropic, the normal drag half the tangential one, so one step
moves particles along a cell at F_e / (N zeta_t) and across it at f_n / zeta_n; and the mass-spring step
(run.mass_pg > 0) reproduces the overdamped run of colliding, guided cells, for a bacterium's real mass and for one
a million times heavier."""
import numpy as np
import pytest

from simtools import cell, sim_with

W = 0.5
F64 = {"precision": "f64"}


def test_normal_drag_is_half_the_tangential_drag():
    """One step of two parallel overlapping cells: along the axis each particle moves at F_e / (N zeta_t) = v_b, across
    it at f_n / zeta_n with zeta_n = zeta_t / 2 (docs/model.md, cell.drag_ratio_normal); zeta_n = 2 zeta_t would move
    them four times less."""
    a = cell((10.0, 10.0), 0.0)
    b = cell((10.0, 10.42), 0.0)
    sim = sim_with(np.stack([a, b]), ke=[1, 1], run={**F64, "dt_ms": 0.1})
    f = sim.forces()
    fc = f["contact"]
    assert np.abs(fc[:, :, 1]).max() > 100.0
    x0 = sim.positions()
    sim.advance(1)
    dx = sim.positions() - x0
    dt = sim.scene.dt
    zeta_t = sim.scene.zeta_t
    assert sim.scene.zeta_n == pytest.approx(0.5 * zeta_t)
    # straight cells along x: the tangent of every particle is -x for k_e = +1 (particle 0 leads toward -x)
    np.testing.assert_allclose(dx[:, :, 0], -dt * (100.0 / 8) / zeta_t, rtol=1e-9)
    np.testing.assert_allclose(dx[:, :, 1], dt * fc[:, :, 1] / (0.5 * zeta_t), rtol=1e-9, atol=1e-15)
    sim.close()


def _collision_and_guiding():
    """Three cells: a pair in head-to-tail guiding range and a third crossing into the follower's side."""
    leader = cell((12.0, 10.0), 180.0)
    follower = cell((12.0 - 4.5 - W - 0.15, 10.1), 180.0)
    crosser = cell((9.0, 12.6), 270.0)
    return np.stack([leader, follower, crosser])


@pytest.mark.slow
def test_mass_spring_step_reproduces_the_overdamped_run():
    """docs/model.md: any m > 0 must not change the results. A bacterium weighs about 1 pg (0.125 pg per particle): its
    inertial time m / zeta ~ 1e-12 s is nine orders below the step, and 10 s of colliding, guided cells end where
    the overdamped run ends. Even a particle a million times heavier (inertial time 0.7 ms, a third of the step)
    stays within 2 % of a cell width."""
    pos = _collision_and_guiding()
    out = {}
    for mass in (0.0, 0.125, 0.125e6):
        sim = sim_with(pos, guiding={"kind": "active"}, run={**F64, "dt_ms": 2.0, "mass_pg": mass})
        sim.advance(5000)
        out[mass] = sim.positions()
        assert (sim.integrator.v is None) == (mass == 0.0)
        sim.close()
    moved = np.abs(out[0.0] - pos).max()
    assert moved > 0.5                                          # they did collide and travel
    assert np.abs(out[0.125] - out[0.0]).max() < 1e-6
    assert np.abs(out[0.125e6] - out[0.0]).max() < 0.02 * W
