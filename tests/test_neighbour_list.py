"""The neighbour lists never miss what all pairs would see: at every compared step the forces from the lists
(contacts by true segment distance within W + skin, guiding partners per cell end) equal, to rounding in f64, those of
a second simulation whose lists hold every pair in the box, for very flexible, actively following cells with swinging
heads and for a dense (area fraction 0.83) jammed start, through several rebuilds from real displacements."""
import numpy as np
import pytest

from simtools import build_small_scene
from taichimyxo.physics.geometry import min_image
from taichimyxo.runtime.simulation import Simulation

F64 = {"precision": "f64"}


def _list_equals_all_pairs(sc_kw, steps, every=1, turn_deg=0.0):
    """Run sim (the default skin) and, at every `every`-th step, compare its forces (equal to rounding) with those of a
    second simulation whose lists hold every pair in the box (skin wider than the box) at the same positions.
    turn_deg: each cell of the start turned about its centre by a random angle up to that. Returns (sim, worst
    per-step displacement, µm)."""
    n = sc_kw["cells"] * 7
    sim = Simulation(build_small_scene(**sc_kw))
    if turn_deg:
        pos = sim.positions()
        ang = np.radians(np.random.default_rng(0).uniform(-turn_deg, turn_deg, len(pos)))
        c, s_ = np.cos(ang)[:, None], np.sin(ang)[:, None]
        mid = pos.mean(1, keepdims=True)
        d = pos - mid
        pos = mid + np.stack([c * d[..., 0] - s_ * d[..., 1], s_ * d[..., 0] + c * d[..., 1]], -1)
        sim.set_state(pos, sim.engine_direction())
    ref_kw = dict(sc_kw)
    ref_kw["run"] = {**sc_kw["run"], "skin_um": 25.0, "max_neighbours": n}
    ref = Simulation.from_positions(build_small_scene(**ref_kw), sim.positions(), sim.engine_direction())
    assert ref.neighbours.nbr_n.to_numpy().min() >= n - 3          # every other segment of every cell is listed
    worst = 0.0
    box = sc_kw["box"]
    for i in range(steps):
        x_before = sim.state.x.to_numpy()
        sim.advance(1)
        d = min_image(sim.state.x.to_numpy() - x_before, box)
        worst = max(worst, float(np.linalg.norm(d, axis=1).max()))
        if i % every:
            continue
        ref.state.x.from_numpy(sim.state.x.to_numpy())
        ref.state.ke.from_numpy(sim.state.ke.to_numpy())
        fs, fr = sim.forces(), ref.forces()
        # equal to rounding (1e-10 pN: a contact 1e-14 µm deep): the two lists' kernels are compiled for different
        # capacities, and a CPU with FMA may fuse a multiply-add in one and not the other; a missed contact is pN
        np.testing.assert_allclose(fs["contact"], fr["contact"], rtol=1e-12, atol=1e-10)
        np.testing.assert_allclose(fs["total"], fr["total"], rtol=1e-12, atol=1e-10)
    ref.close()
    return sim, worst


@pytest.mark.slow
def test_neighbour_list_never_misses_what_all_pairs_see():
    """Very flexible, actively following cells, crowded, heads swinging: at every step the forces from the lists
    (contacts by true distance within W + skin, guiding partners per cell end) equal those from lists holding every
    pair in the box, equal to rounding in f64. The lists are rebuilt from real displacements, not from an assumed top
    speed."""
    sc_kw = dict(box=(15.0, 15.0), cells=14, cell={"k_a_N_m": 1e-18}, guiding={"kind": "active"},
                 run={**F64, "dt_ms": 2.0})
    sim, worst = _list_equals_all_pairs(sc_kw, 1500)                # 3 s
    assert sim.rebuilds >= 3                                        # the list was rebuilt during the run
    assert worst > 3 * sim.scene.v_b * sim.scene.dt                 # heads did swing faster than cells move
    sim.close()


@pytest.mark.slow
def test_contact_list_never_misses_a_contact_in_a_dense_run():
    """Area fraction 0.83: the aligned start (S11's) with every cell turned by up to 4 deg, random polarity, so cells
    crash into their neighbours and push past each other: over 3 s the
    contact list by true segment distance gives the same forces as the all-pairs list at every fifth step, equal to
    rounding in f64, through several rebuilds."""
    sc_kw = dict(box=(12.0, 12.0), cells=48, population={"start": "aligned"}, run={**F64, "dt_ms": 2.0})
    sim, worst = _list_equals_all_pairs(sc_kw, 1500, every=5, turn_deg=4.0)
    f = sim.forces()["contact"]
    assert np.count_nonzero(np.abs(f).sum(-1)) > 0.3 * f.shape[0] * f.shape[1]   # most particles in contact
    assert sim.rebuilds >= 2
    sim.close()
