"""Hard cases stay numerically stable at the scene's default step.

Every case runs the explicit integrator at the default step (scene.dt) and asserts, through
taichimyxo.physics.invariants.check_invariants after every window of 1 simulated second (the displayed-speed window):
finite positions; segment lengths within +-20 % of l0; windowed cell-centre speed <= 5 v_b and particle speed
<= 5 v_b (in scenes with guiding or slime, 5 v_b + F_max / (zeta_n v_b) = 37 v_b for particles: one-particle pulls
swing heads faster, and test_particles_faster_than_5_vb_are_physical shows that is the model, not the step);
no two segments of different cells (nor segments of one cell three or more apart) closer than 0.3 W (why 0.3 W:
invariants.py; the contact force there is 7-35 cells' engine force); spring and contact energy that do not keep
growing.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from simtools import arc_cell, build_small_scene, cell, ring_radius_for_gap
from taichimyxo.physics.invariants import Bounds, InvariantMonitor, check_invariants, measure

STIFFNESS = {"very flexible": 1e-18, "flexible": 1e-17, "rigid": 1e-16, "very rigid": 1e-15}
N = 8
W = 0.5
L0 = (5.0 - 0.5) / 7


def _ke(*k):
    return np.array(k, np.int8)


# ------------------------------------------------------------------------------------------- the checker itself
def test_measure_known_states():
    box = (20.0, 20.0)
    a = cell((10, 10), 0.0, N, L0)
    b = cell((10, 10.2), 0.0, N, L0)                  # parallel, 0.2 µm = 0.4 W apart
    m = measure(np.stack([a, b]), box, L0, W, 1e4, 10.0, 1e4)
    assert m["finite"] and m["len_min"] == pytest.approx(1) and m["len_max"] == pytest.approx(1)
    assert m["d_other_min"] == pytest.approx(0.4)
    assert m["e_spring"] == pytest.approx(0, abs=1e-9) and m["e_bend"] == pytest.approx(0, abs=1e-9)
    # overlap 0.3 µm on each of 7 segment pairs (plus the end-neighbour pairs at the same distance)
    assert m["e_contact"] > 7 * 0.5 * 1e4 * 0.3 ** 2
    # across the corner of the box: the same pair, shifted by the box
    m2 = measure(np.stack([a - 10.0, b + 10.0]), box, L0, W, 1e4, 10.0, 1e4)
    assert m2["d_other_min"] == pytest.approx(0.4)
    c = a.copy()
    c[3:] += [0.3 * L0, 0.0]                               # one segment stretched by 30 %
    assert measure(c[None], box, L0, W, 1e4, 10.0, 1e4)["len_max"] == pytest.approx(1.3)
    c[2, 0] = np.nan
    assert not measure(c[None], box, L0, W, 1e4, 10.0, 1e4)["finite"]


def test_checker_catches_an_unstable_step(small_scene, make_sim):
    """The same overlapping pair at 20 ms (beyond the explicit limit, which --force would allow) violates the
    invariants: the checker is not vacuous."""
    sc = small_scene(2, run={"dt_ms": 20.0})
    sim = make_sim(sc, np.stack([cell((10, 10), 0.0, N, L0), cell((10, 10.15), math.degrees(0.1), N, L0)]), _ke(1, -1))
    from taichimyxo.runtime.simulation import NeighbourOverflow
    # the invariant check, or the list build's segment-length check (the same invariant) when a build comes first
    with pytest.raises((AssertionError, NeighbourOverflow), match="violation|non-finite|segment lengths"):
        check_invariants(sim, 200, window_steps=50)


# ------------------------------------------------------------------------------------------------- hard cases
def _relax_then_check(sim, relax_steps, steps, **kw):
    """A start far from mechanical equilibrium (a very rigid cell bent hard) relaxes at a physical speed above
    5 v_b: check the relaxation every 50 steps with the speed bound off, then every invariant."""
    relax = check_invariants(sim, relax_steps, window_steps=50,
                             bounds=Bounds(speed_factor=math.inf, centre_speed_factor=math.inf))
    mon = check_invariants(sim, steps, **kw)
    print("relaxation:", relax.summary())
    print(mon.summary())
    return relax, mon


def test_very_rigid_cells_at_the_default_step(small_scene, make_sim):
    """k_a = 1e-15 N·m (the stiffest bending mode): a strongly bent cell straightening, a head-on collision and a
    head driven into a cell's side at an angle, at the scene's step."""
    sc = small_scene(4, cell={"k_a_N_m": 1e-15})
    th = math.pi / 2 + 0.3                                                  # the 4th cell moves down, tilted
    cells = [arc_cell((6, 6), 1.6, 0.0, N, L0),                              # bent 0.4 rad at every joint
             cell((13.0, 10.0), 0.0, N, L0), cell((13.0 + 4.5 + 0.4, 10.0), 0.0, N, L0),   # heads 0.4 apart
             cell(np.array([13.0, 10.6]) + 0.5 * (N - 1) * L0 * np.array([math.cos(th), math.sin(th)]),
                  math.degrees(th), N, L0)]                   # head 0.6 µm from cell 2's axis (a 0.1 µm gap)
    sim = make_sim(sc, np.stack(cells), _ke(1, -1, 1, 1))
    # The bent cell stores 490 pN·µm and unbends with ~600 pN at its joints: its ends move at ~15 v_b for a while
    # (an overdamped relaxation, the same at dt / 4), so the speed bound starts after it.
    relax, mon = _relax_then_check(sim, 1000, 4000)
    assert relax.records[-1]["e_bend"] < 0.5 * relax.records[0]["e_bend"]   # the bent cell straightened


@pytest.mark.parametrize("k_a,guiding", [(1e-17, "none"), (1e-15, "none"), (1e-17, "active"),
                                         (1e-15, "active")], ids=["S11", "S12", "S13", "S14"])
def test_high_density_aligned_soft_contacts(small_scene, make_sim, k_a, guiding):
    """S11-S14 on a 15 x 15 µm box: aligned start at area fraction 1, k_c = 0.002 N/m."""
    sc = small_scene(0, box=(15.0, 15.0), population={"start": "aligned", "density_cells_per_cm2": 4e7},
                     cell={"k_a_N_m": k_a}, collisions={"k_c_N_per_m": 0.002}, guiding={"kind": guiding})
    sim = make_sim(sc)
    assert sc.n_cells == 90
    print(check_invariants(sim, 4000).summary())


def _head_tail_gap(pos, follower=1, leader=0):
    from taichimyxo.physics.geometry import closest_points
    return float(closest_points(pos[follower, 0], pos[follower, 1], pos[leader, -2], pos[leader, -1])[4]) - W


@pytest.mark.parametrize("kind", ["active", "passive", "adhesion", "particles"])
def test_guiding_at_gap_zero_and_at_the_cutoff(small_scene, make_sim, kind):
    """A follower's head exactly at gap 0, exactly at gap d_g (the pull is zero there: g >= d_g) and just inside
    d_g (the full F_max pull, which drops to zero a hair further out) from the leader's tail, at 30 degrees so the
    pull has a normal part (passive steering acts). Pulled from just inside the cut-off, the follower crosses the
    guiding range toward contact (except passively, where the pull only steers)."""
    guiding = {"kind": "active" if kind == "particles" else kind}
    if kind == "particles":
        guiding["distance"] = "particles"
    sc = small_scene(2, guiding=guiding)
    d_g, f_max = sc.raw["guiding"]["range_um"], sc.raw["guiding"]["f_max_pN"]
    leader = cell((10.0, 10.0), 0.0, N, L0)              # k_e = +1: moves along -x, tail = particle N-1
    u = np.array([math.cos(math.radians(30)), math.sin(math.radians(30))])
    sim = None
    for gap in (0.0, d_g, d_g * (1 - 1e-6)):
        head = leader[-1] + (W + gap) * u
        follower = cell(head + 0.5 * (N - 1) * L0 * np.array([1.0, 0.0]), 0.0, N, L0)   # head = particle 0
        pos = np.stack([leader, follower])
        assert _head_tail_gap(pos) == pytest.approx(gap, abs=1e-12)
        if sim is None:
            sim = make_sim(sc, pos, _ke(1, 1))
        else:
            sim.set_state(pos, _ke(1, 1))
        pull = sim.forces()["total"][1, 0] - [-sc.engine_force / N, 0.0]     # minus the head's engine share
        if gap < d_g:
            expect = min(sc.k_g * gap, f_max)
            if kind == "passive":
                expect *= math.sin(math.radians(30))
            assert np.linalg.norm(pull) == pytest.approx(expect, rel=1e-3, abs=1e-3)
        else:
            assert np.linalg.norm(pull) < 1e-3
        mon = check_invariants(sim, 2000)
        if gap == d_g * (1 - 1e-6) and kind != "passive":
            assert _head_tail_gap(sim.positions()) < 0.3 * d_g      # pulled in: gap ~ d_g exp(-t k_g / (N zeta_t))
        print(f"{kind} gap {gap}: pull {pull}; {mon.summary()}")


@pytest.mark.parametrize("same_direction", [True, False], ids=["same-direction", "opposite"])
@pytest.mark.parametrize("k_c", [0.01, 0.002])
def test_two_cells_exactly_on_top_of_each_other(small_scene, make_sim, same_direction, k_c):
    """Identical positions (segment distance 0 everywhere): the contact normal is undefined, so a fixed rule picks
    one; the cells must separate to beyond 0.3 W within 0.3 s and then behave."""
    sc = small_scene(2, collisions={"k_c_N_per_m": k_c})
    a = cell((10.0, 10.0), math.degrees(0.4), N, L0)
    sim = make_sim(sc, np.stack([a, a.copy()]), _ke(1, 1 if same_direction else -1))
    print(check_invariants(sim, 3000, settle_steps=300).summary())


@pytest.mark.parametrize("layout", ["parallel-sliding", "parallel-same-way", "collinear-head-on",
                                    "collinear-overlapping"])
def test_parallel_and_collinear_segments_in_contact(small_scene, make_sim, layout):
    """Degenerate closest-point geometry: exactly parallel segments side by side (the contact point is the middle
    of the overlap), and exactly collinear segments end to end or lying along each other."""
    sc = small_scene(2)
    a = cell((10.0, 10.0), 0.0, N, L0)
    settle = 0
    if layout == "parallel-sliding":
        pos, ke = np.stack([a, a + [1.0, 0.7 * W]]), _ke(1, -1)
    elif layout == "parallel-same-way":
        pos, ke = np.stack([a, a + [0.0, 0.8 * W]]), _ke(1, 1)
    elif layout == "collinear-head-on":
        # heads 0.8 W apart on one line, moving into each other
        pos, ke = np.stack([a, a - [(N - 1) * L0 + 0.8 * W, 0.0]]), _ke(1, -1)
    else:
        # the second cell's half lies along the first's (segment distance 0), same line
        pos, ke = np.stack([a, a + [0.5 * (N - 1) * L0, 0.0]]), _ke(1, 1)
        settle = 300
    sim = make_sim(sc, pos, ke)
    print(check_invariants(sim, 3000, settle_steps=settle).summary())


@pytest.mark.parametrize("stiffness", ["very flexible", "flexible", "rigid", "very rigid"])
def test_cell_bent_into_a_ring_following_its_own_tail(small_scene, make_sim, stiffness):
    """One cell on a circle whose head is 0.1 µm (gap) behind its own tail, active following of itself. A very rigid
    ring is far from equilibrium (1100 pN on the head): it unbends first (speed bound off for that)."""
    sc = small_scene(1, cell={"k_a_N_m": STIFFNESS[stiffness]}, guiding={"kind": "active", "self": True})
    r = ring_radius_for_gap(N, L0, W + 0.1)
    ring = arc_cell((10.0, 10.0), r, 0.0, N, L0, direction=-1)      # particle 0 = head, moving counter-clockwise
    sim = make_sim(sc, ring[None], _ke(1))
    # the head is pulled toward its own tail
    f = sim.forces()
    assert np.linalg.norm(f["total"][0, 0]) > 0
    if stiffness == "very rigid":
        _relax_then_check(sim, 1000, 3000)
    else:
        print(check_invariants(sim, 4000).summary())


@pytest.mark.parametrize("case", ["rigid-ring", "curling-head"])
def test_particles_faster_than_5_vb_are_physical(small_scene, make_sim, case):
    """The two situations where a particle legitimately exceeds 5 v_b (see invariants.py): a rigid cell spinning as
    a ring on its own tail, and a flexible follower's head curling round a leader's tail. The windowed speeds are
    the same at dt / 4 (to 3 %), so they are the model's dynamics, not an integration artefact; the cells' centres
    stay below 5 v_b."""
    speeds = {}
    for dt_ms in (1.0, 0.25):
        if case == "rigid-ring":
            sc = small_scene(1, cell={"k_a_N_m": 1e-16}, guiding={"kind": "active"}, run={"dt_ms": dt_ms})
            pos = arc_cell((10.0, 10.0), ring_radius_for_gap(N, L0, W + 0.1), 0.0, N, L0, direction=-1)[None]
            ke = _ke(1)
        else:
            sc = small_scene(2, guiding={"kind": "active"}, run={"dt_ms": dt_ms})
            a = cell((10.0, 10.0), 0.0, N, L0)
            pos, ke = np.stack([a, a + [1.0, 0.75 * W]]), _ke(1, -1)
        sim = make_sim(sc, pos, ke)
        mon = InvariantMonitor(sim)
        mon.run(3000 if dt_ms == 1.0 else 12000)
        assert not mon.violations(), mon.violations()
        speeds[dt_ms] = np.array([r["speed_max_vb"] for r in mon.records])
        assert max(r["centre_speed_max_vb"] for r in mon.records) < 5.0
    print(case, speeds)
    assert speeds[1.0].max() > 5.0
    np.testing.assert_allclose(speeds[1.0], speeds[0.25], rtol=0.03)


def test_hairpin_self_contact_of_segments_k_and_k_plus_2(small_scene, make_sim):
    """docs/model.md term 4: non-adjacent segments of one cell collide. Head segment folded back by 170 degrees:
    segments 0 and 2 are 0.11 µm apart (< W), so there must be a contact force."""
    sc = small_scene(1)
    pos = cell((10.0, 10.0), 0.0, N, L0)
    pos[0] = pos[1] + L0 * np.array([math.cos(math.radians(10)), math.sin(math.radians(10))])
    from taichimyxo.physics.geometry import closest_points
    assert closest_points(pos[0], pos[1], pos[2], pos[3])[4] < 0.25 * W
    sim = make_sim(sc, pos[None], _ke(1))
    assert np.abs(sim.forces()["contact"]).sum() > 0


@pytest.mark.parametrize("during", ["contact", "guiding"])
def test_reversal_during_contact_and_during_guiding(small_scene, make_sim, during):
    """Cells reverse (k_e flips, head and tail swap) while in a side contact, or while pulled head to tail."""
    sc = small_scene(3, guiding={"kind": "active"},
                     reversals={"enabled": True, "period_min": 0.02, "period_sd_fraction": 0.0})
    a = cell((10.0, 10.0), 0.0, N, L0)
    if during == "contact":
        pos = np.stack([a, a + [1.0, 0.75 * W], a + [-1.0, -0.75 * W]])
        ke = _ke(1, -1, -1)
    else:
        u = np.array([math.cos(0.4), math.sin(0.4)])
        b = cell(a[-1] + (W + 0.1) * u + [0.5 * (N - 1) * L0, 0.0], 0.0, N, L0)
        c = cell(b[-1] + (W + 0.2) * np.array([1.0, 0.0]) + [0.5 * (N - 1) * L0, 0.0], 0.0, N, L0)
        pos = np.stack([a, b, c])
        ke = _ke(1, 1, 1)
    sim = make_sim(sc, pos, ke)
    # every cell reverses 20 steps from now (mid-contact / mid-pull), then every 1.2 s
    per = sim.model.reversals.rev_period.to_numpy()
    sim.model.reversals.rev_clock.from_numpy((per - 20).astype(np.int32))
    f0 = sim.forces()
    if during == "contact":
        assert np.abs(f0["contact"]).sum() > 0
    else:
        assert np.linalg.norm(f0["total"][1, 0]) > 0
    ke0 = sim.engine_direction().copy()
    mon = check_invariants(sim, 3000)
    assert int(sim.model.reversals.rev_count.to_numpy().min()) >= 2
    assert mon.records[1]["step"] > 20
    assert np.all(sim.engine_direction() == ke0 * (-1) ** sim.model.reversals.rev_count.to_numpy())
    print(mon.summary())


def test_cells_across_the_corner_of_the_box(small_scene, make_sim):
    """Cells whose bodies straddle the corner (0, 0) of the periodic box: a diagonal cell, a parallel neighbour
    touching it through the wrap in x and y, and a perpendicular cell driving its head into its side."""
    sc = small_scene(3, box=(12.0, 12.0), guiding={"kind": "active"})
    u = np.array([1.0, -1.0]) / math.sqrt(2)
    a = cell((0.0, 0.0), 45.0, N, L0)
    b = cell(0.49 * np.array([-1.0, 1.0]) / math.sqrt(2), 45.0, N, L0)   # 0.98 W: touching
    c = cell((0.45 + 0.5 * (N - 1) * L0) * u, -45.0, N, L0)              # head 0.9 W from a
    sim = make_sim(sc, np.stack([a, b, c]), _ke(1, -1, 1))
    pos = sim.positions()
    assert np.all(pos[:, 0] >= 0) and np.any(pos < 0) or np.any(pos > 12.0)             # chains cross the wrap
    f = sim.forces()["contact"]
    assert np.abs(f[0]).sum() > 0 and np.abs(f[1]).sum() > 0 and np.abs(f[2]).sum() > 0
    print(check_invariants(sim, 3000).summary())


@pytest.mark.parametrize("box", [10.0, 10.1], ids=["whole-elements", "partial-element"])
def test_slime_element_at_the_wrap(small_scene, make_sim, box):
    """Slime trails across the periodic boundary: a cell whose rear particle sits exactly on x = 0 = L, depositing
    into the last/first column, and a follower crossing the wrap along that trail (10.1 µm: the grid does not divide
    the box, the wrapping column is narrower)."""
    sc = small_scene(2, box=(box, box), slime={"enabled": True})
    lead = cell((0.0, 5.0), 0.0, N, L0)
    lead -= [lead[0, 0], 0.0]                                   # particle 0 (the rear, k_e = -1) exactly at x = 0
    follow = cell((box - 0.5 * (N - 1) * L0 - 0.6, 5.05), math.degrees(0.1), N, L0)
    sim = make_sim(sc, np.stack([lead, follow]), _ke(-1, -1))   # both move along +x
    sim.advance(1)
    s = sim.model.slime.slime.to_numpy()
    assert np.abs(s[0]).sum() > 0                              # deposited into the first column
    mon = check_invariants(sim, 4000)
    s = sim.model.slime.slime.to_numpy()
    assert np.all(np.isfinite(s))
    n = np.linalg.norm(s, axis=-1)
    assert np.all((n == 0) | (np.abs(n - 1) < 1e-5))           # unit vectors or empty
    print(mon.summary())


@pytest.mark.parametrize("what", ["random-guided", "aligned-full"])
def test_smallest_allowed_domain(small_scene, make_sim, what):
    """A box of two cell lengths: a cell's periodic image is one cell length behind it."""
    if what == "random-guided":
        sc = small_scene(4, box=(10.0, 10.0), guiding={"kind": "active"})
    else:
        sc = small_scene(0, box=(10.0, 10.0), population={"start": "aligned", "density_cells_per_cm2": 4e7},
                         collisions={"k_c_N_per_m": 0.002})
        assert sc.n_cells == 40
    sim = make_sim(sc)
    print(check_invariants(sim, 3000).summary())


def test_single_cell(small_scene, make_sim):
    """A single free cell moves straight at v_b (self-following on: its own tail is far away)."""
    sc = small_scene(1, guiding={"kind": "active"})
    sim = make_sim(sc, cell((10.0, 10.0), math.degrees(0.7), N, L0)[None], _ke(1))
    mon = check_invariants(sim, 2000)
    assert mon.records[-1]["speed_max_vb"] == pytest.approx(1.0, rel=1e-3)


# ------------------------------------------------------------------------------------------- property tests
@pytest.fixture
def sim_cache(ti_session):
    """Simulations by compile-time configuration, reused across the test's examples (closed at its end)."""
    cache: dict = {}
    yield cache
    for sim in cache.values():
        sim.close()


@pytest.mark.slow                   # ~15 s with warm kernel caches, ~55 s cold (12 compile-time configurations)
# derandomize: the same 12 examples each run, so their kernels come from Taichi's offline cache (~1 s instead of
# ~3 s per new compile-time configuration) and a failure reproduces exactly.
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(n=st.integers(2, 6), stiffness=st.sampled_from(sorted(STIFFNESS)), k_c=st.sampled_from([0.01, 0.002]),
       guiding=st.sampled_from(["none", "passive", "active", "adhesion"]), seed=st.integers(0, 2 ** 16),
       crowd=st.booleans())
def test_random_small_configurations_stay_bounded(sim_cache, n, stiffness, k_c, guiding, seed, crowd):
    """2-6 cells placed at random without overlap on a 10 x 10 µm box (crowd) or 12 x 12 µm, any paper stiffness,
    either k_c and any guiding kind: 1000 steps at the default step keep every invariant. One Simulation per
    compile-time configuration; new positions are loaded with set_state."""
    from taichimyxo.physics.placement import random_start
    from taichimyxo.runtime.simulation import Simulation
    box = 10.0 if crowd else 12.0
    sc = build_small_scene(n, box=(box, box), cell={"k_a_N_m": STIFFNESS[stiffness]},
                           collisions={"k_c_N_per_m": k_c}, guiding={"kind": guiding}, run={"seed": seed})
    pos, ke = random_start(sc)
    key = (n, box, stiffness, k_c, guiding)
    sim = sim_cache.get(key)
    if sim is None:
        sim = sim_cache[key] = Simulation.from_positions(sc, pos, ke)
    else:
        sim.set_state(pos, ke)
    check_invariants(sim, 1000)
