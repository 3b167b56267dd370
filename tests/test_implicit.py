"""The linearly implicit step (taichimyxo/physics/integrators/imex.py, scene run.integrator = "imex") against the
explicit one.

Every comparison runs the paper's explicit step at a small step (0.5 ms) as the reference and the implicit step at
steps 40-100 times larger. Simulations are built once per module (each compiles its kernels) and reloaded with
set_state for each case.
"""

import numpy as np
import pytest

from simtools import arc_cell, build_small_scene, cell
from taichimyxo.physics.terms.bending import bend_angles
from taichimyxo.runtime.simulation import Simulation

# module-scoped Simulations (compiled once, states loaded per test): Taichi is not restarted between tests
pytestmark = pytest.mark.keeps_taichi

L0 = 4.5 / 7
V_B = 4.0 / 60.0          # µm/s


def _scene(integrator, dt_ms, k_a=1e-17, **sections):
    return build_small_scene(box=(20.0, 20.0), cells=2, cell={"k_a_N_m": k_a},
                 run={"precision": "f64", "integrator": integrator, "dt_ms": dt_ms}, **sections)


def _far():
    """A second cell parked where it touches nothing."""
    return cell((3.0, 3.0), 0.0)


def advance_for(sim, seconds, dt_ms):
    """Advance by `seconds` with step dt_ms (the sim's compiled scene may have another default step)."""
    dt = dt_ms * 1e-3
    sim.advance(int(round(seconds / dt)), dt)
    return sim.positions()


@pytest.fixture(scope="module")
def pair():
    """(explicit, implicit) simulations of two flexible cells; states are loaded per test."""
    pos = np.stack([cell((10.0, 10.0)), _far()])
    ex = Simulation.from_positions(_scene("explicit", 0.5), pos, np.ones(2))
    im = Simulation.from_positions(_scene("imex", 50.0), pos, np.ones(2))
    yield ex, im
    ex.close()
    im.close()


@pytest.mark.parametrize("dt_ms", [10.0, 100.0])
def test_free_straight_cell_moves_at_v_b(pair, dt_ms):
    _, im = pair
    pos = np.stack([cell((10.0, 12.0), 30.0), _far()])
    im.set_state(pos, np.array([1, 1]))
    p = advance_for(im, 20.0, dt_ms)
    d = p[0].mean(0) - pos[0].mean(0)
    speed = np.linalg.norm(d) / 20.0
    assert speed == pytest.approx(V_B, rel=5e-3)
    # exact, in fact: a rigid translation is in the stiffness matrix's null space
    assert speed == pytest.approx(V_B, rel=1e-9)
    # along its axis, head (particle 0) first
    u = pos[0][0] - pos[0][-1]
    assert np.dot(d, u / np.linalg.norm(u)) == pytest.approx(np.linalg.norm(d), rel=1e-9)


def test_bent_cell_relaxes_to_the_same_state(pair):
    ex, im = pair
    pos = np.stack([arc_cell((10.0, 10.0), 3.0, 200.0), _far()])
    ke = np.array([1, 1])
    out = {}
    for name, sim, dt in (("explicit", ex, 0.5), ("imex", im, 50.0)):
        sim.set_state(pos, ke)
        out[name] = advance_for(sim, 40.0, dt)
    pe, pi = out["explicit"][0], out["imex"][0]
    assert np.abs(bend_angles(pi)).max() < 0.5 * np.abs(bend_angles(pos[0])).max()       # it did relax
    assert np.abs(bend_angles(pi) - bend_angles(pe)).max() < 2e-3
    assert np.linalg.norm(pi.mean(0) - pe.mean(0)) < 5e-3                                  # µm after ~2.7 µm
    assert np.abs(np.linalg.norm(np.diff(pi, axis=0), axis=1) / L0 - 1).max() < 1e-3


def test_head_on_jam_is_the_same_fixed_point(pair):
    """Two collinear cells pushing head-on stop where contact balances the engines (F = 0): same state."""
    ex, im = pair
    pos = np.stack([cell((7.0, 10.0)), cell((7.0 + 5.0 - 0.02, 10.0))])
    ke = np.array([-1, 1])          # cell 0 heads +x, cell 1 heads -x
    out = {}
    for name, sim, dt in (("explicit", ex, 0.5), ("imex", im, 50.0)):
        sim.set_state(pos, ke)
        out[name] = advance_for(sim, 10.0, dt)
    np.testing.assert_allclose(out["imex"], out["explicit"], atol=1e-6)
    gap = out["imex"][1, 0, 0] - out["imex"][0, -1, 0]
    assert gap == pytest.approx(0.5 - 100.0 / 1e4, abs=1e-4)      # overlap = F_e / k_c


def _t_push():
    """Cell A (heading +x) hits the middle of cell B (lying along y, heading -y) side-on and pushes it."""
    a = cell((6.0, 10.0), 0.0)
    b = cell((6.0 + 7 * L0 / 2 + 0.5 + 0.01, 10.0), 90.0)
    return np.stack([a, b]), np.array([-1, 1])


def test_pushing_cells_move_at_the_right_speed(pair):
    """No spurious drag: contacts are coupled in the implicit solve, so A and B move together as the explicit
    step says (A pushes B sideways at ~2/3 v_b: A's tangential drag plus B's normal drag)."""
    ex, im = pair
    pos, ke = _t_push()
    out = {}
    for name, sim, dt in (("explicit", ex, 0.5), ("imex", im, 50.0)):
        sim.set_state(pos, ke)
        out[name] = advance_for(sim, 20.0, dt)
    dA = {k: p[0, :, 0].mean() - pos[0, :, 0].mean() for k, p in out.items()}
    dB = {k: p[1, :, 0].mean() - pos[1, :, 0].mean() for k, p in out.items()}
    assert dA["explicit"] > 0.5 * (2 / 3) * V_B * 20.0                   # it did push for most of the time
    assert dA["imex"] == pytest.approx(dA["explicit"], rel=0.01)
    assert dB["imex"] == pytest.approx(dB["explicit"], rel=0.01)


def test_one_sided_contact_drag_is_wrong():
    """The error the coupled solve avoids: each cell treating its contacts implicitly as if the other body were
    fixed (contacts='diagonal') adds a drag dt k_c to bodies that push each other: at 50 ms A is > 5 % slow."""
    pos, ke = _t_push()
    sim = Simulation.from_positions(_scene("imex", 50.0), pos, ke, contacts="diagonal")
    try:
        p = advance_for(sim, 20.0, 50.0)
    finally:
        sim.close()
    dA = p[0, :, 0].mean() - pos[0, :, 0].mean()
    assert dA < 0.95 * 0.9909         # the explicit reference moves A by 0.9909 µm (test above)


@pytest.fixture(scope="module")
def rigid_pair():
    pos = np.stack([cell((10.0, 10.0)), _far()])
    ex = Simulation.from_positions(_scene("explicit", 10.0, k_a=1e-15), pos, np.ones(2))
    im = Simulation.from_positions(_scene("imex", 10.0, k_a=1e-15), pos, np.ones(2))
    yield ex, im
    ex.close()
    im.close()


def test_very_rigid_cells_stable_where_explicit_blows_up(rigid_pair):
    """k_a = 1e-15 N m: bending rate 16 k_a / (l0^2 zeta_n) ~ 400 /s, so the explicit step fails at 10 ms while the
    implicit one straightens the cell smoothly, at 10 ms and at 100 ms."""
    ex, im = rigid_pair
    pos = np.stack([arc_cell((10.0, 10.0), 4.0, 200.0), _far()])
    ke = np.array([1, 1])
    ex.set_state(pos, ke)
    from taichimyxo.runtime.simulation import NeighbourOverflow
    try:
        p = advance_for(ex, 0.5, 10.0)
        lengths = np.linalg.norm(np.diff(p[0], axis=0), axis=1) / L0
        blew_up = not np.all(np.isfinite(p)) or np.abs(lengths - 1).max() > 0.2 or np.abs(bend_angles(p[0])).max() > 1.0
    except NeighbourOverflow as e:              # a list build found segments beyond 1.5 l0, and stopped the run
        blew_up = "segment lengths" in str(e)
    assert blew_up
    for dt in (10.0, 100.0):
        im.set_state(pos, ke)
        p = advance_for(im, 5.0, dt)
        lengths = np.linalg.norm(np.diff(p[0], axis=0), axis=1) / L0
        assert np.all(np.isfinite(p))
        assert np.abs(lengths - 1).max() < 0.01
        assert np.abs(bend_angles(p[0])).max() < 0.05          # straight (it started at 0.16 rad per joint)
        d = np.linalg.norm(p[0].mean(0) - pos[0].mean(0))
        assert d == pytest.approx(V_B * 5.0, rel=0.1)


def test_imex_explicit_is_imex_with_explicit_contacts(pair):
    """run.integrator = "imex-explicit" (what sweeps and scene files can name) is the imex step with contacts
    explicit: no contact records, its own stability limits (30 ms at k_c = 0.002 N/m), and a push side-on that
    moves the cells as the explicit reference does; a contradicting contacts option is refused."""
    from taichimyxo.physics.integrators import records_contacts
    from taichimyxo.physics.stability import stable_limit_ms
    scene = _scene("imex-explicit", 5.0)
    assert not records_contacts(scene)
    assert stable_limit_ms(_scene("imex-explicit", 5.0, collisions={"k_c_N_per_m": 0.002})) == 30.0
    with pytest.raises(ValueError, match="contradicts"):
        Simulation.from_positions(scene, *_t_push(), contacts="coupled")
    ex, _ = pair
    pos, ke = _t_push()
    ex.set_state(pos, ke)
    ref = advance_for(ex, 20.0, 0.5)
    sim = Simulation.from_positions(scene, pos, ke)
    try:
        assert sim.integrator.contacts == "explicit"
        p = advance_for(sim, 20.0, 5.0)
    finally:
        sim.close()
    for c in (0, 1):
        moved, moved_ref = p[c, :, 0].mean() - pos[c, :, 0].mean(), ref[c, :, 0].mean() - pos[c, :, 0].mean()
        assert moved == pytest.approx(moved_ref, rel=0.02)
