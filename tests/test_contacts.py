"""The contact law (docs/model.md "Contacts", docs/model.md term 4): continuous and complete.

Each cell is sampled every l0/2 (particles and segment midpoints); each sample is pushed out of every other chain by
w k_c (W - D), D its distance to that chain (w = 1/4, poles 1/2). What must hold (issue: side-by-side cells lost most
of their contact force under the old node-ownership rule):
  - two overlapping straight cells side by side feel a total normal force that changes smoothly with tilt and
    stagger, in f32, mixed and f64, including the tilts where a segment-pair law switches its parallel branch;
  - that force is k_c (W - d) per l0 of overlap length, plus one contact for the two ends of the overlap;
  - a contact at a node shared by two segments counts once; sliding along a straight neighbour gives no tangential
    force (exactly, where no round cap is within reach; within 3 % of the normal force at tilts, caps included);
  - forces are minus the finite-difference gradient of the contact energy written in numpy from its definition
    (taichimyxo.physics.geometry.contact_energy: distance from each sample to the nearest point of each other chain),
    and the strain energy per segment sums to that energy.
One Simulation per precision: configurations are loaded with set_state, so nothing recompiles.
"""
import math

import numpy as np
import pytest

from simtools import cell, contact_energy, fd_gradient, sim_with

# module-scoped Simulations (compiled once, states loaded per test): Taichi is not restarted between tests
pytestmark = pytest.mark.keeps_taichi

L0 = 4.5 / 7
W = 0.5
K_C = 1e4          # pN/µm, the scene default 0.01 N/m
SEP = 0.42         # centre-line distance of the side-by-side pair: overlap W - SEP = 0.08 µm
BOX = (20.0, 20.0)


def side_by_side(tilt_rad=0.0, stagger=0.0, sep=SEP):
    """Cell A horizontal; cell B beside it at `sep`, overlapping A along five segments (less `stagger`), turned by
    `tilt_rad` about the middle of the overlap. Returns positions (2, 8, 2) and the overlap length along the axis."""
    a = cell((10.0, 10.0), 0.0)
    b = cell((10.0 + 2 * L0 + stagger, 10.0 + sep), 0.0)
    pivot = np.array([0.5 * (a[:, 0].max() + b[:, 0].min()), 10.0 + sep])
    c, s = math.cos(tilt_rad), math.sin(tilt_rad)
    b = (b - pivot) @ np.array([[c, -s], [s, c]]).T + pivot
    return np.stack([a, b]), 5 * L0 - stagger


def contact_on(sim, pos, ke=(1, 1)):
    sim.set_state(pos, np.asarray(ke))
    return sim.forces()["contact"]


@pytest.fixture(scope="module", params=["f32", "mixed", "f64"])
def pair_sim(request):
    sim = sim_with(side_by_side()[0], run={"precision": request.param})
    yield sim
    sim.close()


TILTS_DEG = [0.0, math.degrees(1e-6), math.degrees(3e-5), math.degrees(5e-5), 0.003, 0.01, 0.1, 0.5, 1.0, 2.0, 3.0,
             5.0, 7.5, 10.0]
STAGGERS = np.linspace(0.0, L0, 5)


def test_side_by_side_force_is_continuous_in_tilt_and_stagger(pair_sim):
    """Normal force per unit overlap length within 15 % of its value at zero tilt and stagger up to 3 deg, no jump
    anywhere (the old rule jumped 9x at 3e-5 rad in f64, 5e-5 in f32)."""
    F = np.zeros((len(TILTS_DEG), len(STAGGERS)))
    for i, tilt in enumerate(TILTS_DEG):
        for j, st in enumerate(STAGGERS):
            pos, overlap = side_by_side(math.radians(tilt), st)
            fc = contact_on(pair_sim, pos)
            F[i, j] = np.linalg.norm(fc[1].sum(0)) / overlap
            # Newton's third law
            assert np.abs(fc.sum((0, 1))).max() < 1e-4 * np.abs(fc).max()
    ref = F[0, 0]
    assert ref > 0
    small = np.array(TILTS_DEG) <= 3.0
    assert np.abs(F[small] / ref - 1).max() < 0.15, F / ref
    # tilts below a thousandth of a degree change nothing measurable
    tiny = np.array(TILTS_DEG) < 0.001
    np.testing.assert_allclose(F[tiny], F[0][None, :].repeat(tiny.sum(), 0), rtol=1e-4)
    # smooth: neighbouring tilts in the sweep differ by less than their tilt difference allows (no jump)
    fine = [contact_on(pair_sim, side_by_side(math.radians(t), 0.3 * L0)[0])[1].sum(0)[1]
            for t in np.linspace(0.0, 10.0, 81)]
    steps = np.abs(np.diff(fine)) / fine[0]
    assert steps.max() < 0.03, steps.max()


def test_parallel_force_per_overlap_length(pair_sim):
    """Exactly parallel: k_c (W - d) per l0 of overlap, plus about one contact for the two ends of the overlap (the
    poles' extra weight and the samples' fence posts; 0.96-1.07 with the stagger): the numbers docs/decisions.md
    states."""
    for st in (0.0, 0.25 * L0, 0.5 * L0, L0):
        pos, overlap = side_by_side(0.0, st)
        fy = contact_on(pair_sim, pos)[1, :, 1].sum()
        expected = K_C * (W - SEP) * (overlap / L0 + 1.0)
        assert fy == pytest.approx(expected, rel=0.015)


@pytest.fixture(scope="module")
def sim64():
    sim = sim_with(side_by_side()[0], run={"precision": "f64"})
    yield sim
    sim.close()


def _pole_on_cell(offset_along, depth, angle=90.0):
    """Cell A horizontal; cell B's pole (particle 0) `depth` inside A's outline, `offset_along` from A's particle 3."""
    a = cell((10, 10), 0.0)
    tip = np.array([a[3, 0] + offset_along, 10 + (W - depth)])
    u = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    b = tip[None, :] + np.arange(8)[:, None] * L0 * u[None, :]
    return np.stack([a, b])


def test_contact_at_a_shared_node_is_counted_once(sim64):
    """S1 Text defect (A): a pole pressing exactly on the particle shared by two segments of another cell feels the
    pole's contact once (w = 1/2) plus the other cell's particle under it (w = 1/4): 3/4 k_c depth, exactly what it
    feels above the middle of a segment (pole plus the midpoint sample under it), not twice that."""
    depth = 0.1
    on_node = contact_on(sim64, _pole_on_cell(0.0, depth))
    on_mid = contact_on(sim64, _pole_on_cell(0.5 * L0, depth))
    for fc in (on_node, on_mid):
        assert fc[1, 0, 1] == pytest.approx(0.75 * K_C * depth, rel=1e-9)
        assert fc[0, :, 1].sum() == pytest.approx(-0.75 * K_C * depth, rel=1e-9)
        np.testing.assert_allclose(fc[:, :, 0], 0.0, atol=1e-9 * K_C * depth)
    # in between, the pole feels the two nearest samples of A partly: never less than its own half contact, never
    # more than 0.9 of a paper point contact
    for off in np.linspace(0.0, L0, 9):
        fy = contact_on(sim64, _pole_on_cell(off, depth))[1, :, 1].sum()
        assert 0.5 * K_C * depth <= fy <= 0.9 * K_C * depth


def _cap_clear_pair(m, tilt_deg=0.0):
    """B beside A (sep SEP, exactly parallel), B's pole 0.3 µm past one of A's samples (m half-segments along A):
    no sample of either cell lies within reach (sqrt(W^2 - SEP^2) = 0.27 µm) beyond the other's pole, so every
    contact is a sample against a straight side."""
    a = cell((10, 10), 0.0)
    left = a[0, 0] + 0.5 * L0 * m + 0.3
    b = cell((left + 2.25, 10 + SEP), tilt_deg)
    return np.stack([a, b])


@pytest.mark.parametrize("m", [2, 3, 4, 5, 6, 7, 8])
def test_sliding_along_a_straight_neighbour_feels_no_tangential_force(sim64, m):
    """S1 Text defect (B): at every offset along the neighbour, the contact force is normal and its size is the
    count of samples over the other cell's side times w k_c (W - d)."""
    pos = _cap_clear_pair(m)
    fc = contact_on(sim64, pos)
    fy = fc[1, :, 1].sum()
    np.testing.assert_allclose(fc[:, :, 0], 0.0, atol=1e-9 * fy)
    # samples (every l0/2) of each cell lying over the other's extent, with their weights
    def xs(c):
        return np.concatenate([c[:, 0], 0.5 * (c[1:, 0] + c[:-1, 0])])
    ws = np.concatenate([[0.5], np.full(6, 0.25), [0.5], np.full(7, 0.25)])
    a, b = pos
    over_b = (xs(a) >= b[:, 0].min() - 1e-12) & (xs(a) <= b[:, 0].max() + 1e-12)
    over_a = (xs(b) >= a[:, 0].min() - 1e-12) & (xs(b) <= a[:, 0].max() + 1e-12)
    expected = K_C * (W - SEP) * (ws[over_b].sum() + ws[over_a].sum())
    assert fy == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("tilt_deg", [0.0, 0.5, 1.0, 3.0])
def test_sliding_at_a_tilt_feels_only_the_caps(pair_sim, tilt_deg):
    """Tilted, and wherever the poles are: the force along the neighbour's axis stays below 3 % of the normal force
    (what remains is the round caps pushing a cell that slides past the other's pole)."""
    for shift in np.linspace(0.0, L0, 9):
        a = cell((10, 10), 0.0)
        b = cell((10 + 1.3 + shift, 10 + SEP), tilt_deg)
        f = contact_on(pair_sim, np.stack([a, b]))[1].sum(0)
        assert f[1] > 0.5 * K_C * (W - SEP) * 4
        assert abs(f[0]) < 0.03 * f[1]


FD_CASES = [(t, st) for t in (0.0, 1e-6, math.radians(1.0), math.radians(3.0), math.radians(10.0))
            for st in (0.0, 0.37 * L0)]


@pytest.mark.parametrize("case", ["pole_interior", "pole_on_node", "tilted_crossing"] +
                         [f"side_{i}" for i in range(len(FD_CASES))])
def test_contact_forces_are_minus_energy_gradient(sim64, case):
    if case == "pole_interior":
        pos = _pole_on_cell(0.3, 0.1)
    elif case == "pole_on_node":
        pos = _pole_on_cell(0.0, 0.1)
    elif case == "tilted_crossing":
        pos = _pole_on_cell(0.2, 0.15, angle=60.0)
    else:
        tilt, st = FD_CASES[int(case.split("_")[1])]
        pos = side_by_side(tilt, st)[0]
    fc = contact_on(sim64, pos)
    g = fd_gradient(lambda p: contact_energy(p, BOX, W, K_C), pos, h=1e-7)
    assert np.abs(g).max() > 0, "configuration must have contacts"
    np.testing.assert_allclose(fc, -g, rtol=1e-5, atol=1e-5 * np.abs(g).max())


def test_strain_energy_is_the_contact_energy_per_segment(small_scene, make_sim):
    """A dense aligned patch: the per-segment strain energy (S8, Fig 2F, Fig 4B) sums to the contact energy."""
    from taichimyxo.physics.placement import initial_configuration
    sc = small_scene(0, box=(10.0, 10.0), population={"start": "aligned", "density_cells_per_cm2": 4e7},
                     output={"strain": True, "movie": False}, run={"precision": "f64"})
    pos, ke = initial_configuration(sc)
    rng = np.random.default_rng(3)
    pos = pos + rng.normal(0.0, 0.03, pos.shape)          # pressed into each other here and there
    sim = make_sim(sc, positions=pos, engine_direction=ke)
    strain = sim.segment_strain()                           # J
    e = contact_energy(sim.positions(), sc.box, sc.width, sc.k_c) * 1e-18
    assert e > 0
    assert strain.sum() == pytest.approx(e, rel=1e-9)
    # the numpy twin a figure uses where a run did not log strain: the same energy per cell, and per segment but
    # where a sample nearest to a node presses the segment on either side of it (a tie the kernel and numpy round
    # apart: the same energy, on the neighbouring segment)
    from taichimyxo.physics.geometry import segment_strain
    twin = segment_strain(sim.positions(), sc.box, sc.width, sc.k_c) * 1e-18
    np.testing.assert_allclose(twin.sum(1), strain.sum(1), rtol=1e-9, atol=1e-12 * strain.max())
    same = np.isclose(twin, strain, rtol=1e-9, atol=1e-12 * strain.max())
    assert (twin > 0).sum() > 20 and same.mean() > 0.9, same.mean()
