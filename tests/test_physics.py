"""Physics that had no test: the drag ratio, the mass-spring step against the overdamped one, guiding with k_e = -1
and summed over several leaders, slime overwrite and persistence with several cells, overlap as an interaction for
reversal suppression, and a neighbour list that never misses what all pairs would see (docs/model.md terms 1-7)."""
import math

import numpy as np
import pytest

from simtools import build_small_scene, cell, sim_with
from taichimyxo.geometry import min_image
from taichimyxo.simulation import make_simulation

W = 0.5
L0 = 4.5 / 7
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
    sim.run(1)
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
        sim.run(5000)
        out[mass] = sim.positions()
        assert (sim.integrator.v is None) == (mass == 0.0)
        sim.close()
    moved = np.abs(out[0.0] - pos).max()
    assert moved > 0.5                                          # they did collide and travel
    assert np.abs(out[0.125] - out[0.0]).max() < 1e-6
    assert np.abs(out[0.125e6] - out[0.0]).max() < 0.02 * W


@pytest.mark.parametrize("ke", [1, -1])
def test_guiding_pull_acts_on_the_head_for_either_engine_direction(ke):
    """k_e = -1 makes particle N - 1 the head and particle 0 the tail: the pull goes to particle N - 1, toward the
    leader's tail (particle 0 when the leader also has k_e = -1)."""
    g = 0.15
    leader = cell((12.0, 10.0), 180.0)                     # particle 0 at +x
    follower = cell((12.0 - 4.5 - W - g, 10.0), 180.0)
    if ke < 0:                                             # same places, particles numbered the other way round
        leader, follower = leader[::-1].copy(), follower[::-1].copy()
    sim = sim_with(np.stack([leader, follower]), ke=[ke, ke], guiding={"kind": "active"}, run=F64)
    f = sim.forces()
    head = 0 if ke > 0 else -1
    guide = f["total"][1] - f["internal"][1] - f["contact"][1]
    engine = 100.0 / 8 * f["tangent"][1]
    pull = guide - engine
    assert pull[head, 0] == pytest.approx(800.0 * g, rel=1e-6)           # toward the leader, +x
    mask = np.ones(8, bool)
    mask[head] = False
    assert np.abs(pull[mask]).max() < 1e-9
    sim.close()


def test_guiding_sums_over_several_leaders():
    """A follower's head within range of two leaders' tails feels the sum of both pulls (docs/model.md term 5)."""
    follower = cell((6.0, 10.0), 180.0)                    # head (particle 0) at x = 8.25, moving +x
    head = follower[0]
    # two leaders moving +x, their tails (particle 7) just ahead of the head, above and below its axis
    up = cell((0, 0), 180.0 - 30.0)
    up = up - up[-1] + head + np.array([0.62, 0.25])
    down = cell((0, 0), 180.0 + 30.0)
    down = down - down[-1] + head + np.array([0.62, -0.25])
    far = cell((15.0, 3.0), 0.0)
    sim = sim_with(np.stack([follower, up, down]), ke=[1, 1, 1], box=(20.0, 20.0), guiding={"kind": "active"},
                   run=F64)

    def pull(pos):
        sim.set_state(pos, np.ones(3))
        f = sim.forces()
        return (f["total"][0] - f["internal"][0] - f["contact"][0] - 100.0 / 8 * f["tangent"][0])[0]

    both = pull(np.stack([follower, up, down]))
    only_up = pull(np.stack([follower, up, far]))
    only_down = pull(np.stack([follower, far, down]))
    assert np.linalg.norm(only_up) > 10.0 and np.linalg.norm(only_down) > 10.0
    np.testing.assert_allclose(both, only_up + only_down, rtol=1e-9, atol=1e-9)
    assert abs(both[1]) < 0.2 * abs(both[0])               # the lateral pulls nearly cancel, the forward ones add
    sim.close()


def test_slime_is_overwritten_by_the_latest_cell_and_persists():
    """Two cells each run along an older trail laid the other way (antiparallel: it exerts no steering force, whose
    normal component is zero): each rear particle overwrites the elements it passes with its own tangent, and
    every element no rear passes keeps its old vector (MODEL.md term 6: trails persist until overwritten)."""
    def ix(x):
        return int(math.floor(x / 0.25))
    ya, xb = 10.125, 15.125                       # element centres, so round-off cannot move a rear off the row
    a = cell((4.0, ya), 180.0)                    # moving +x along the row, rear from x = 1.75 to 5.75 in 60 s
    b = cell((xb, 12.0), 90.0)                    # moving -y along the column, rear from y = 14.25 to 10.25
    sim = sim_with(np.stack([a, b]), box=(20.0, 20.0), slime={"enabled": True}, run={"dt_ms": 2.0})
    grid = np.zeros((sim.model.slime.sgx, sim.model.slime.sgy, 2), np.float32)
    grid[:, ix(ya)] = (-1.0, 0.0)                 # an older trail along the row, laid toward -x
    grid[ix(xb), :] = (0.0, 1.0)                  # and one along the column, laid toward +y
    sim.model.slime.slime.from_numpy(grid)
    sim.run(30000)                                # 60 s
    g = sim.model.slime.slime.to_numpy()
    for x in (2.5, 3.0, 4.0, 5.0):                # passed by a's rear: overwritten with a's tangent
        np.testing.assert_allclose(g[ix(x), ix(ya)], (1.0, 0.0), atol=2e-3)
    for y in (11.0, 12.0, 13.0, 14.0):            # passed by b's rear
        np.testing.assert_allclose(g[ix(xb), ix(y)], (0.0, -1.0), atol=2e-3)
    for x in (0.5, 9.0, 12.0):                    # never under a rear: the old trail persists
        np.testing.assert_array_equal(g[ix(x), ix(ya)], (-1.0, 0.0))
    for y in (2.0, 6.0, 9.0, 16.0):
        np.testing.assert_array_equal(g[ix(xb), ix(y)], (0.0, 1.0))
    # the cells ran straight (no steering by an antiparallel trail)
    p = sim.positions()
    assert abs(p[0, :, 1].mean() - ya) < 0.05 and abs(p[1, :, 0].mean() - xb) < 0.05
    sim.run(2500)                                 # 5 s more: what was written stays
    g2 = sim.model.slime.slime.to_numpy()
    np.testing.assert_array_equal(g2[ix(3.0), ix(ya)], g[ix(3.0), ix(ya)])
    np.testing.assert_array_equal(g2[ix(xb), ix(13.0)], g[ix(xb), ix(13.0)])
    sim.close()


@pytest.mark.parametrize("gap", [-0.05, 0.0, 0.1])
def test_overlap_counts_as_interaction_for_suppression(gap):
    """Head overlapping the leader's tail (gap <= 0, collisions act and the guiding force is zero) is still a
    head-to-tail interaction: the flag is set on both cells."""
    leader = cell((12.0, 10.0), 180.0)
    follower = cell((12.0 - 4.5 - W - gap, 10.0), 180.0)
    loner = cell((10.0, 17.0), 0.0)
    sim = sim_with(np.stack([leader, follower, loner]), box=(30.0, 30.0), guiding={"kind": "active"},
                   reversals={"enabled": True, "suppression": True}, run=F64)
    sim.forces()
    flags = sim.model.guiding.interacting.to_numpy().any(axis=1)   # per cell: head or tail end
    assert flags[1] != 0 and flags[0] != 0 and flags[2] == 0
    sim.close()


def _list_equals_all_pairs(sc_kw, steps, every=1, turn_deg=0.0):
    """Run sim (the default skin) and, at every `every`-th step, compare its forces (equal to rounding) with those of a
    second simulation whose lists hold every pair in the box (skin wider than the box) at the same positions.
    turn_deg: each cell of the start turned about its centre by a random angle up to that. Returns (sim, worst
    per-step displacement, µm)."""
    n = sc_kw["cells"] * 7
    sim = make_simulation(build_small_scene(**sc_kw))
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
    ref = make_simulation(build_small_scene(**ref_kw), positions=sim.positions(),
                          engine_direction=sim.engine_direction())
    assert ref.neighbours.nbr_n.to_numpy().min() >= n - 3          # every other segment of every cell is listed
    worst = 0.0
    box = sc_kw["box"]
    for i in range(steps):
        x_before = sim.state.x.to_numpy()
        sim.run(1)
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


def test_displayed_speed_window_opens_at_the_previous_frame_when_frames_are_closer(tmp_path):
    """Frames every 3 s with a 10 s speed window: the window opens at the previous frame (so the speed is over the
    last 3 s), not at step 0 (the old behaviour: the net displacement since the start)."""
    from taichimyxo.scene import Scene
    from taichimyxo.scene_run import run_scene
    sc = Scene.from_dict({"scene": {"name": "win"}, "domain": {"width_um": 20.0, "height_um": 20.0},
                          "population": {"cells": 1},
                          "run": {"hours": 0.01, "dt_ms": 2.0, "speed_window_s": 10.0},
                          "output": {"movie": False, "frame_interval_min": 0.05}})
    every = sc.frame_every_steps
    assert every == 1500
    run_scene(sc, out_dir=str(tmp_path), progress=False, stop_after_steps=3 * every + 100)
    ck = np.load(tmp_path / "win.ckpt.npz")
    assert int(ck["step"]) == 3 * every + 100
    assert int(ck["snap_step"]) == 3 * every
