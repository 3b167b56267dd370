"""Short-range guiding (docs/model.md term 5), slime trails (term 6), reversals (term 7), strain energy, and effects
compiled only where a scene uses them."""
import math

import numpy as np
import pytest

from simtools import arc_cell, build_small_scene, cell, sim_with
from taichimyxo.runtime.simulation import Simulation

W = 0.5
L0 = 4.5 / 7
V_B = 4.0    # µm/min


def in_line(gap, leader_x=12.0, y=10.0, lateral=0.0):
    """Leader and follower along +x, both k_e = +1 (particle 0 leads), head-to-tail distance W + gap."""
    leader = cell((leader_x, y), 180.0)                       # particle 0 at +x
    f_centre = leader_x - 4.5 - W - gap
    follower = cell((f_centre, y + lateral), 180.0)
    return np.stack([leader, follower])


def centroid_velocity(sim, steps=20):
    p0 = sim.positions().mean(1)
    t0 = sim.time
    sim.advance(steps)
    return (sim.positions().mean(1) - p0) / (sim.time - t0) * 60.0      # µm/min, (n_cells, 2)


@pytest.mark.parametrize("distance", ["segments", "particles"])
def test_active_following_pulls_the_follower_up_to_3_v_b(distance):
    g = 0.249
    sim = sim_with(in_line(g), guiding={"kind": "active", "distance": distance},
                   run={"precision": "f64", "dt_ms": 1.0})
    v = centroid_velocity(sim, 3)
    expected = (100 + 800 * g) / 100 * V_B             # engine 100 pN + pull k_g g, shared by the whole cell
    assert v[1, 0] == pytest.approx(expected, rel=0.01)
    assert v[1, 0] > 2.9 * V_B
    assert v[0, 0] == pytest.approx(V_B, rel=0.01)     # active following: the leader is not affected
    # over 30 s the follower catches up and stays within guiding range, never overtaking
    gaps = []
    for _ in range(30):
        sim.advance(1000)
        p = sim.positions()
        gaps.append(np.linalg.norm(p[0, -1] - p[1, 0]) - W)
    assert max(gaps) < 0.25 and min(gaps) > -0.05
    sim.close()


def test_adhesion_also_slows_the_leader():
    g = 0.2
    # the leader's net force is a small difference (100 - 160 pN): measure over 0.2 ms, before the gap changes
    sim = sim_with(in_line(g), guiding={"kind": "adhesion"}, run={"precision": "f64", "dt_ms": 0.1})
    v = centroid_velocity(sim, 2)
    assert v[1, 0] == pytest.approx((100 + 800 * g) / 100 * V_B, rel=0.01)
    assert v[0, 0] == pytest.approx((100 - 800 * g) / 100 * V_B, rel=0.01)
    sim.close()


@pytest.mark.parametrize("distance", ["segments", "particles"])
def test_passive_following_turns_but_never_speeds_up(distance):
    sim = sim_with(in_line(0.15, lateral=0.25), guiding={"kind": "passive", "distance": distance},
                   run={"precision": "f64"})
    p = sim.positions()
    heading0 = p[1, 0] - p[1, 1]
    axial = []
    for _ in range(40):
        p0 = sim.positions()
        sim.advance(50)
        p1 = sim.positions()
        axis = p0[1, 0] - p0[1, -1]
        axis /= np.linalg.norm(axis)
        vel = (p1[1].mean(0) - p0[1].mean(0)) / (50 * sim.scene.dt) * 60
        axial.append(np.dot(vel, axis))
    p = sim.positions()
    heading1 = p[1, 0] - p[1, 1]
    turn = math.atan2(heading1[1], heading1[0]) - math.atan2(heading0[1], heading0[0])
    assert turn < -0.01                                 # turned toward the leader's tail (which is at -y)
    assert max(axial) <= V_B * 1.002
    sim.close()


def test_guiding_across_the_periodic_boundary_equals_inside():
    pos = in_line(0.2, lateral=0.1)
    ref = sim_with(pos, guiding={"kind": "adhesion"}, run={"precision": "f64"})
    f_ref = ref.forces()["total"]
    ref.close()
    shift = np.array([20.0, 20.0]) - pos[0, -1] + np.array([0.05, 0.03])     # the leader's tail just inside a corner
    moved = np.mod(pos + shift, 20.0)
    sim = sim_with(moved, guiding={"kind": "adhesion"}, run={"precision": "f64"})
    np.testing.assert_allclose(sim.forces()["total"], f_ref, rtol=1e-9, atol=1e-9)
    sim.close()


def _ring(gap=0.1):
    # radius such that the head-to-tail chord across the opening is W + gap
    def opening(R):
        dth = 2 * math.asin(L0 / (2 * R))
        return 2 * R * math.sin((2 * math.pi - 7 * dth) / 2) - (W + gap)
    lo, hi = 0.75, 3.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if opening(mid) < 0 else (lo, mid)
    return arc_cell((10, 10), 0.5 * (lo + hi), 0.0)


@pytest.mark.parametrize("distance", ["segments", "particles"])
def test_a_cell_bent_into_a_ring_follows_its_own_tail(distance):
    pos = _ring(0.1)
    d = np.linalg.norm(pos[0] - pos[-1]) - W
    assert d == pytest.approx(0.1, abs=1e-6)
    f = {}
    for self_ in (True, False):
        sim = sim_with(pos, guiding={"kind": "active", "distance": distance, "self": self_},
                       cell={"k_a_N_m": 1e-18}, run={"precision": "f64"})
        f[self_] = sim.forces()["total"][0, 0]
        sim.close()
    pull = f[True] - f[False]
    towards_tail = (pos[-1] - pos[0]) / np.linalg.norm(pos[-1] - pos[0])
    assert np.linalg.norm(pull) > 0.5 * 800 * 0.1
    assert np.dot(pull, towards_tail) > 0.9 * np.linalg.norm(pull)


@pytest.mark.parametrize("trail_sign", [1.0, -1.0])
def test_a_cell_crossing_a_slime_trail_at_30_degrees_turns_onto_it(trail_sign):
    c = cell((6.0, 8.3), 30.0 + 180.0)          # particle 0 leads toward +30 degrees, 1.5 µm below the trail
    sim = sim_with(c, box=(40.0, 20.0), slime={"enabled": True}, cell={"k_a_N_m": 1e-16},
                   run={"dt_ms": 2.0})
    grid = np.zeros((sim.model.slime.sgx, sim.model.slime.sgy, 2), np.float32)
    rows = slice(int(9.75 / 0.25), int(10.25 / 0.25))
    grid[:, rows, 0] = trail_sign
    sim.model.slime.slime.from_numpy(grid)
    sim.advance(30000)                               # 60 s: the cell reaches the trail and follows it
    p = sim.positions()[0]
    heading = p[0] - p[1]
    angle = math.degrees(math.atan2(heading[1], heading[0]))
    assert abs(angle) < 8.0                      # moving along the trail, in its own (acute) direction
    assert abs(np.mod(p[:, 1].mean(), 20.0) - 10.0) < 0.6
    sim.close()


def test_deposition_writes_the_rear_tangent_under_the_rear_particle():
    c = cell((10.0, 10.0), 37.0)
    for ke in (1, -1):
        sim = sim_with(c, ke=[ke], slime={"enabled": True})
        sim.advance(1)
        p = sim.positions()[0]
        rear, nxt = (p[-1], p[-2]) if ke > 0 else (p[0], p[1])
        t = (nxt - rear) / np.linalg.norm(nxt - rear)
        grid = sim.model.slime.slime.to_numpy()
        ix, iy = (np.floor(np.mod(rear, 20.0) / 0.25)).astype(int)
        np.testing.assert_allclose(grid[ix, iy], t, atol=1e-6)
        assert np.count_nonzero(np.abs(grid).sum(-1)) == 1
        sim.close()


def test_observed_reversal_intervals_match_the_period_distribution():
    T = 3.0                                      # s
    sim = Simulation(build_small_scene(box=(60.0, 60.0), cells=60,
                                            reversals={"enabled": True, "period_min": T / 60}, run={"dt_ms": 2.0}))
    ke_prev = sim.engine_direction()
    last = np.full(60, np.nan)
    intervals = []
    for _ in range(6000):                        # 60 s
        sim.advance(5)
        ke = sim.engine_direction()
        flipped = np.nonzero(ke != ke_prev)[0]
        for c in flipped:
            if not np.isnan(last[c]):
                intervals.append(sim.time - last[c])
            last[c] = sim.time
        ke_prev = ke
    intervals = np.array(intervals)
    assert len(intervals) > 800
    assert intervals.mean() == pytest.approx(T, rel=0.03)
    assert intervals.std() == pytest.approx(0.24 * T, rel=0.12)
    assert intervals.min() >= 0.1 * T - 0.011
    sim.close()


@pytest.mark.parametrize("suppression", [True, False])
def test_suppression_skips_reversals_during_head_to_tail_interaction_only(suppression):
    pair = in_line(0.1, leader_x=10.0)
    loner = cell((10.0, 18.0), 0.0)[None]
    sim = sim_with(np.concatenate([pair, loner]), box=(30.0, 30.0), guiding={"kind": "active"},
                   reversals={"enabled": True, "period_min": 1.0 / 60, "suppression": suppression})
    flips = np.zeros(3, int)
    prev = sim.engine_direction()
    for _ in range(500):                          # 5 s
        sim.advance(10)
        ke = sim.engine_direction()
        flips += ke != prev
        prev = ke
    assert flips[2] >= 3                          # the free cell reverses about every second
    if suppression:
        assert flips[0] == 0 and flips[1] == 0    # leader and follower interact the whole time
    else:
        assert flips[0] >= 2 and flips[1] >= 2
    sim.close()


def test_strain_energy_of_a_known_overlap_is_split_in_halves():
    """A pole pressed into a cell's side: every contact is between a sample of one cell and a segment of the other,
    and each contact's energy goes half to each side, so the pole's segment holds half of the total and the other
    cell the other half; the total is the contact energy (numpy, from its definition)."""
    from simtools import contact_energy
    a = cell((10, 10), 0.0)
    depth = 0.12
    tip = np.array([a[3, 0] + 0.3, 10 + W - depth])
    b = tip[None, :] + np.arange(8)[:, None] * np.array([0.0, L0])[None, :]
    pos = np.stack([a, b])
    sim = sim_with(pos, output={"strain": True}, run={"precision": "f64"})
    e = sim.segment_strain()
    total = contact_energy(pos, (20.0, 20.0), W, sim.scene.k_c) * 1e-18          # J
    assert total > 0.5 * 0.5 * sim.scene.k_c * depth ** 2 * 1e-18                 # at least the pole's own contact
    assert e.sum() == pytest.approx(total, rel=1e-9)
    assert e[1, 0] == pytest.approx(total / 2, rel=1e-9)
    assert e[1, 1:].sum() == 0.0
    assert e[0].sum() == pytest.approx(total / 2, rel=1e-9)
    sim.close()


EFFECT_FIELDS = {"g_head", "g_tail", "interacting", "rev_clock", "rev_period", "rev_count", "slime", "slime_claim",
                 "strain_seg", "v"}


@pytest.mark.parametrize("name,expected", [
    ("S1", set()),
    ("S2", {"g_head"}),
    ("S4", {"g_head", "g_tail"}),
    ("S8", {"g_head", "strain_seg"}),
    ("S15", {"g_head", "interacting", "rev_clock", "rev_period", "rev_count"}),
    ("S17", {"slime", "slime_claim"}),
])
def test_only_the_effects_a_scene_uses_are_allocated(name, expected):
    from taichimyxo.io.scene import Scene
    sc = Scene.load(name, {"domain": {"width_um": 20.0, "height_um": 20.0}, "population": {"cells": 4},
                           "output": {"movie": False}})
    sim = Simulation(sc)
    have = {k for k in sim.allocated_fields() if k in EFFECT_FIELDS}
    assert have == expected
    units = {u.name for u in sim.model.units}             # an effect's unit exists only when the scene uses it
    assert ("slime" in units) == ("slime" in expected)
    assert ("reversals" in units) == ("rev_clock" in expected)
    assert ("strain" in units) == ("strain_seg" in expected)
    assert ("head_to_tail" in units) == bool(expected & {"g_head", "interacting"})
    assert sim.integrator.v is None
    sim.close()


F64 = {"precision": "f64"}


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
    sim.advance(30000)                            # 60 s
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
    sim.advance(2500)                             # 5 s more: what was written stays
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
    flags = sim.model.head_to_tail.interacting.to_numpy().any(axis=1)   # per cell: head or tail end
    assert flags[1] != 0 and flags[0] != 0 and flags[2] == 0
    sim.close()


# ---------------------------------------------------------------- decisions the paper leaves open (docs/decisions.md)
@pytest.mark.parametrize("pull_on", ["head_particle", "head_segment"])
def test_the_pull_acts_on_the_head_particle_or_is_shared_by_the_head_segment(pull_on):
    """Straight cells in line at rest length, gap 0.2 µm: the only force beside the engine's equal shares is the pull
    k_g g = 160 pN, all on the follower's head particle or half on each particle of its head segment."""
    g = 0.2
    sim = sim_with(in_line(g), guiding={"kind": "active", "pull_on": pull_on}, run={"precision": "f64"})
    f = sim.forces()["total"][1, :, 0]                   # follower, x (the pull's direction)
    extra = f - f[4]                                     # less the engine's share (particle 4 bears no pull)
    pull = 800 * g
    if pull_on == "head_particle":
        assert extra[:2] == pytest.approx([pull, 0.0], abs=1e-6)
    else:
        assert extra[:2] == pytest.approx([pull / 2, pull / 2], abs=1e-6)
    assert extra[2:] == pytest.approx(np.zeros(6), abs=1e-6)
    assert extra.sum() == pytest.approx(pull, rel=1e-9)  # the cell's total is the same either way
    sim.close()


@pytest.mark.parametrize("reaction_on", ["tail_particle", "tail_segment"])
def test_the_adhesion_reaction_acts_on_the_tail_particle_or_is_shared_by_the_tail_segment(reaction_on):
    g = 0.2
    sim = sim_with(in_line(g), guiding={"kind": "adhesion", "reaction_on": reaction_on}, run={"precision": "f64"})
    f = sim.forces()["total"][0, :, 0]                   # leader: particle 7 is its tail
    extra = f - f[3]
    pull = 800 * g
    if reaction_on == "tail_particle":
        assert extra[6:] == pytest.approx([0.0, -pull], abs=1e-6)
    else:
        assert extra[6:] == pytest.approx([-pull / 2, -pull / 2], abs=1e-6)
    assert extra[:6] == pytest.approx(np.zeros(6), abs=1e-6)
    sim.close()


@pytest.mark.parametrize("contacts", ["head_or_tail", "head"])
def test_suppression_holds_both_cells_of_a_contact_or_only_the_follower(contacts):
    pair = in_line(0.1, leader_x=10.0)
    sim = sim_with(pair, box=(30.0, 30.0), guiding={"kind": "active"},
                   reversals={"enabled": True, "period_min": 1.0 / 60, "suppression": True,
                              "suppression_contacts": contacts})
    flips = np.zeros(2, int)
    prev = sim.engine_direction()
    for _ in range(300):                          # 3 s, periods of about 1 s
        sim.advance(10)
        ke = sim.engine_direction()
        flips += ke != prev
        prev = ke
        if contacts == "head" and flips[0]:
            break                                 # the leader turned round: the pair has come apart
    assert flips[1] == 0                          # the follower's head is in contact until the leader turns
    if contacts == "head_or_tail":
        assert flips[0] == 0
    else:
        assert flips[0] >= 1                      # the leader's tail is followed, yet it reverses
    sim.close()


@pytest.mark.parametrize("wait", ["period", "contact_end"])
def test_a_held_reversal_waits_a_new_period_or_only_until_the_contact_ends(wait):
    """A follower held in contact past its period (10 s periods, 12 s in contact); its leader is then taken away.
    contact_end: the reversal, still due, fires at the next step; period: it waits for the clock's next turn."""
    T_min = 10.0 / 60
    sim = sim_with(in_line(0.1, leader_x=10.0), box=(40.0, 40.0), guiding={"kind": "active"},
                   reversals={"enabled": True, "period_min": T_min, "period_sd_fraction": 0.0,
                              "suppression": True, "suppressed_wait": wait}, run={"dt_ms": 2.0})
    sim.advance(6000)                             # 12 s: at least one reversal of each cell held
    assert (sim.engine_direction() == 1).all()
    p = sim.positions()
    p[0] += np.array([0.0, 15.0])                 # the leader moved 15 µm aside: no contact
    sim.set_state(p, sim.engine_direction())
    sim.advance(2)
    flipped = sim.engine_direction()[1] == -1
    assert flipped == (wait == "contact_end")
    sim.close()
