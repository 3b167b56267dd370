"""Springs and bending are minus the gradient of their energies; periodic contacts; free speed. The contact law has
its own file, test_contacts.py."""
import math

import numpy as np
import pytest

from simtools import arc_cell, bend_energy, cell, fd_gradient, sim_with, spring_energy

F64 = {"run": {"precision": "f64"}}
L0 = 4.5 / 7
W = 0.5


def _wiggly(seed=1):
    rng = np.random.default_rng(seed)
    p = cell((10, 10), 20)
    return p + rng.normal(0, 0.05, p.shape)


def test_springs_and_bending_are_minus_energy_gradient():
    pos = _wiggly()
    sim = sim_with(pos, **F64)
    k_s, k_a = sim.scene.k_s, sim.scene.k_a
    f = sim.forces()["internal"][0]
    g = fd_gradient(lambda p: spring_energy(p, k_s, L0) + bend_energy(p, k_a), pos, h=1e-7)
    np.testing.assert_allclose(f, -g, rtol=1e-5, atol=1e-4 * np.abs(g).max())
    sim.close()


@pytest.mark.parametrize("k_a", [1e-18, 1e-15])
def test_bending_alone_on_an_arc_with_rest_lengths(k_a):
    pos = arc_cell((10, 10), 3.0, 0.0)          # chords exactly l0: springs at rest, only bending acts
    sim = sim_with(pos, cell={"k_a_N_m": k_a}, **F64)
    f = sim.forces()["internal"][0]
    g = fd_gradient(lambda p: bend_energy(p, sim.scene.k_a), pos, h=1e-7)
    assert np.abs(g).max() > 0
    np.testing.assert_allclose(f, -g, rtol=1e-5, atol=1e-6 * np.abs(g).max())
    # bending forces are internal: no net force, no net torque
    assert np.abs(f.sum(0)).max() < 1e-9 * np.abs(f).max()
    torque = np.sum(pos[:, 0] * f[:, 1] - pos[:, 1] * f[:, 0])
    assert abs(torque) < 1e-8 * np.abs(f).max() * 10
    sim.close()


def test_springs_alone_on_a_stretched_straight_chain():
    pos = cell((10, 10), 0.0, l0=L0 * 1.05)       # straight: no bending
    sim = sim_with(pos, **F64)
    f = sim.forces()["internal"][0]
    g = fd_gradient(lambda p: spring_energy(p, sim.scene.k_s, L0), pos, h=1e-7)
    np.testing.assert_allclose(f, -g, rtol=1e-6, atol=1e-6)
    assert f[0, 0] > 0 and f[-1, 0] < 0            # a stretched chain contracts
    sim.close()


def _tip_on_cell(offset_along=0.3, depth=0.1, angle=90.0):
    """Cell A horizontal; cell B's pole particle (particle 0) at `depth` inside A's outline."""
    a = cell((10, 10), 0.0)
    tip = np.array([a[3, 0] + offset_along, 10 + (W - depth)])
    u = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    b = tip[None, :] + np.arange(8)[:, None] * L0 * u[None, :]
    return np.stack([a, b])


@pytest.mark.parametrize("where", ["x_edge", "y_edge", "corner"])
def test_contact_across_the_periodic_boundary_equals_inside(where):
    pos = _tip_on_cell(0.25, 0.12, angle=70.0)
    box = np.array([20.0, 20.0])
    sim = sim_with(pos, **F64)
    ref = sim.forces()["total"]
    sim.close()
    contact_point = pos[1, 0]
    target = {"x_edge": np.array([0.0, 10.0]), "y_edge": np.array([10.0, 0.0]), "corner": np.array([0.0, 0.0])}[where]
    moved = np.mod(pos - contact_point + target, box)
    sim2 = sim_with(moved, **F64)
    got = sim2.forces()["total"]
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    sim2.close()


@pytest.mark.parametrize("ke", [1, -1])
@pytest.mark.parametrize("precision", ["f64", "mixed"])
def test_free_straight_cell_moves_at_v_b(ke, precision):
    pos = cell((7.3, 11.1), 33.0)
    sim = sim_with(pos, ke=[ke], run={"precision": precision, "dt_ms": 1.0})
    sim.snapshot_speed()
    x0 = sim.positions()[0].mean(0)
    sim.advance(3000)
    x1 = sim.positions()[0].mean(0)
    v = np.linalg.norm(x1 - x0) / sim.time * 60.0              # µm/min (no wrap: 0.2 µm travelled)
    assert v == pytest.approx(4.0, rel=0.005)
    heading = (x1 - x0) / np.linalg.norm(x1 - x0)
    axis = pos[0] - pos[-1]
    axis /= np.linalg.norm(axis)
    assert np.dot(heading, axis) * ke > 0.9999              # k_e = +1 moves toward particle 0
    np.testing.assert_allclose(sim.particle_speed(), 4.0, rtol=0.005)
    sim.close()
