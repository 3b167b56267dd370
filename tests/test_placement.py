"""Initial configurations (taichimyxo/physics/placement.py): density, no overlaps, area fraction, spiral head to tail,
the batched random placement, and what a start that cannot place its cells says."""

import numpy as np
import pytest

from simtools import build_small_scene, cli, error_line
from taichimyxo.io.scene import Scene, defaults
from taichimyxo.physics.geometry import closest_points, min_image, sample_polyline_contacts
from taichimyxo.physics.placement import initial_configuration


def test_random_start_has_the_density_and_no_overlaps():
    sc = Scene.from_dict({"domain": {"width_um": 60.0, "height_um": 60.0}})
    pos, ke = initial_configuration(sc)
    assert len(pos) == round(5e6 * 1e-8 * 60 * 60) == 180
    assert set(np.unique(ke)) == {-1, 1}
    assert min_segment_distance_between_cells(pos, sc.box) >= sc.width
    # uniform: every quadrant holds a fair share of the cells
    centres = np.mod(pos.mean(1), 60.0)
    q = np.histogram2d(centres[:, 0], centres[:, 1], bins=2, range=[[0, 60], [0, 60]])[0]
    assert q.min() > 0.15 * len(pos)
    # straight cells with rest-length segments
    seg = np.linalg.norm(np.diff(pos, axis=1), axis=-1)
    np.testing.assert_allclose(seg, 4.5 / 7, rtol=1e-12)


def test_aligned_start_fills_area_fraction_one():
    """With population.aligned_tilt_deg = 0: rows of cells exactly along x, W apart, their caps just touching."""
    sc = Scene.from_dict({"domain": {"width_um": 20.0, "height_um": 20.0},
                          "population": {"start": "aligned", "density_cells_per_cm2": 4e7, "aligned_tilt_deg": 0.0}})
    pos, ke = initial_configuration(sc)
    n = len(pos)
    assert n * sc.length * sc.width / (20.0 * 20.0) == pytest.approx(1.0)
    # all parallel to x, rows W apart, no overlap deeper than round-off (caps just touch)
    d = np.diff(pos, axis=1)
    assert np.abs(d[:, :, 1]).max() < 1e-12
    rows = np.unique(np.round(pos[:, 0, 1], 9))
    assert np.allclose(np.diff(rows), sc.width)
    for a, b in [(0, 1), (0, 4), (3, 4)]:
        pa, pb = pos[a], pos[b]
        s, t, c1, c2, dist = closest_points(pa[:-1, None], pa[1:, None], pb[None, :-1] + min_image(
            pb[None, :-1] - pa[:-1, None], sc.box) - (pb[None, :-1] - pa[:-1, None]),
            pb[None, 1:] + min_image(pb[None, :-1] - pa[:-1, None], sc.box) - (pb[None, :-1] - pa[:-1, None]))
        assert dist.min() >= sc.width - 1e-9


def test_aligned_start_tilts_each_cell_about_its_centre():
    """The default aligned start turns each cell by its own angle within +- aligned_tilt_deg about the centre the
    untilted start gives it (same rows, same offsets, same polarities), so rows are not exactly one-dimensional;
    the angles spread over the whole range and depend on the seed."""
    base = {"domain": {"width_um": 20.0, "height_um": 20.0},
            "population": {"start": "aligned", "density_cells_per_cm2": 4e7}}
    sc = Scene.from_dict(base)
    flat = Scene.from_dict({**base, "population": {**base["population"], "aligned_tilt_deg": 0.0}})
    assert sc.aligned_tilt_deg == 1.0
    pos, ke = initial_configuration(sc)
    pos0, ke0 = initial_configuration(flat)
    np.testing.assert_array_equal(ke, ke0)
    np.testing.assert_allclose(pos.mean(1), pos0.mean(1), atol=1e-9)
    d = pos[:, -1] - pos[:, 0]
    angle = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    assert np.abs(angle).max() <= 1.0 + 1e-9
    assert angle.min() < -0.8 and angle.max() > 0.8 and np.abs(angle).min() < 0.2
    seg = np.linalg.norm(np.diff(pos, axis=1), axis=-1)
    np.testing.assert_allclose(seg, sc.rest_length, rtol=1e-12)
    other = initial_configuration(Scene.from_dict({**base, "run": {"seed": 2}}))[0]
    assert not np.allclose(np.diff(other, axis=1), np.diff(pos, axis=1))


def test_aligned_tilt_changes_only_aligned_scenes_hashes():
    """The tilt is read by the aligned start alone: it enters the fingerprint (what a resume and a sweep's finished
    run compare) of aligned scenes and leaves every other scene's as it was."""
    from taichimyxo.sweep.spec import scene_key
    for start, changes in [("aligned", True), ("random", False), ("spiral", False)]:
        pop = {"start": start, "density_cells_per_cm2": 4e7 if start == "aligned" else 5e6}
        a = Scene.from_dict({"domain": {"width_um": 20.0, "height_um": 20.0}, "population": pop})
        b = Scene.from_dict({"domain": {"width_um": 20.0, "height_um": 20.0},
                             "population": {**pop, "aligned_tilt_deg": 2.0}})
        assert (a.fingerprint() != b.fingerprint()) is changes
        assert (scene_key(a) != scene_key(b)) is changes


def test_spiral_start_cells_head_to_tail():
    sc = Scene.from_dict({"domain": {"width_um": 100.0, "height_um": 100.0},
                          "population": {"start": "spiral", "cells": 500, "polarity": "same"}})
    pos, ke = initial_configuration(sc)
    assert (ke == 1).all()
    heads = pos[:, 0]
    tails = pos[:, -1]
    # cell c follows cell c - 1: its head is within guiding range of its leader's tail
    gaps = np.linalg.norm(heads[1:] - tails[:-1], axis=1) - sc.width
    assert gaps.max() < 0.25 and gaps.min() > 0.0
    # leaders inward (the paper's S5 Fig): every head is nearer the axis than its own tail, and every trailing cell
    # is further from the axis than its leader
    axis = np.array(sc.box) / 2
    def r(p):
        return np.linalg.norm(p - axis, axis=-1)
    assert np.all(r(heads) < r(tails))
    assert np.all(np.diff(r(pos.mean(axis=1))) > 0)
    seg = np.linalg.norm(np.diff(pos, axis=1), axis=-1)
    np.testing.assert_allclose(seg, sc.rest_length, rtol=1e-9)
    # turns W apart: neighbouring turns touch but do not overlap by more than 1 % of W
    d = sample_polyline_contacts(pos[:60], sc.box, sc.width)[3]
    assert np.all(d > 0.99 * sc.width)
    # the spiral fits in the box, centred
    assert np.abs(pos.reshape(-1, 2) - 50.0).max() < 50.0


def min_segment_distance_between_cells(pos, box):
    """Smallest segment-segment distance between different cells (periodic), vectorised over cell pairs."""
    n = len(pos)
    i, j = np.triu_indices(n, 1)
    c = pos.mean(1)
    near = np.linalg.norm(min_image(c[j] - c[i], box), axis=1) < 6.0
    i, j = i[near], j[near]
    shift = min_image(pos[j, :1] - pos[i, :1], box) - (pos[j, :1] - pos[i, :1])     # (m, 1, 2)
    a, b = pos[i], pos[j] + shift
    d = closest_points(a[:, :-1, None], a[:, 1:, None], b[:, None, :-1], b[:, None, 1:])[4]
    return d.min() if len(d) else np.inf


# ------------------------------------------------------------------------------------------------ random placement
def unvalidated_scene(box: float, cells: int, **over) -> Scene:
    """A Scene that skips Scene.validate (to hand the placement inputs validation would refuse)."""
    raw = defaults()
    raw["domain"].update(width_um=box, height_um=box)
    raw["population"]["cells"] = cells
    for sec, vals in over.items():
        raw[sec].update(vals)
    return Scene(raw=raw)


def _one_try_at_a_time(scene):
    """The random start as it was first written: one try per loop, 7 x 7 sub-segments per pair (the reference the
    batched placement must reproduce exactly)."""
    import math

    from taichimyxo.physics import rng
    from taichimyxo.physics.geometry import closest_points, min_image
    from taichimyxo.physics.placement import straight_cell
    n, N, l0, W = scene.n_cells, scene.N, scene.rest_length, scene.width
    box = np.array(scene.box)
    draws = rng.Stream(scene.seed, rng.STREAM_PLACE)
    pos, centres = np.zeros((n, N, 2)), np.zeros((n, 2))
    placed = 0
    while placed < n:
        r = draws.next(3)
        c, ang = r[:2] * box, r[2] * 2 * math.pi
        cell = straight_cell(c, ang, N, l0)
        if placed:
            shift = min_image(centres[:placed] - c, box) - (centres[:placed] - c)
            others = pos[:placed] + shift[:, None, :]
            d = closest_points(cell[:-1][None, :, None], cell[1:][None, :, None], others[:, None, :-1],
                               others[:, None, 1:])[4]
            if np.any(d < W):
                continue
        pos[placed], centres[placed] = cell, c
        placed += 1
    return pos


@pytest.mark.parametrize("box,cells,seed", [(30.0, 60, 2), (40.0, 200, 7), (12.0, 3, 5)])
def test_batched_random_placement_places_the_same_cells(box, cells, seed):
    from taichimyxo.physics.placement import random_start
    sc = build_small_scene(cells, box=(box, box), run={"seed": seed})
    assert np.array_equal(random_start(sc)[0], _one_try_at_a_time(sc))


def test_random_placement_gives_up_within_its_budget():
    """0.6 of the area cannot be placed at random: the placement stops after its budget of tries, not never."""
    from taichimyxo.physics.placement import PlacementError, random_start
    sc = unvalidated_scene(30.0, 216)                                   # area fraction 0.6
    seen = []
    with pytest.raises(PlacementError, match="gave up after 20800 tries"):
        random_start(sc, max_tries_per_cell=50, progress=lambda placed, n, tries: seen.append(tries))
    assert seen and seen[-1] <= 50 * 216 + 10_000


def test_random_start_above_what_it_places_is_refused_before_placing(tmp_path):
    """The issue's 490 cells in 50 x 50 µm (area fraction 0.49): one line at once, not a silent hang."""
    line = error_line(cli("scene", "S1", "--no-movie", "--out", tmp_path / "o", "--set", "domain.width_um=50",
                          "--set", "domain.height_um=50", "--set", "population.cells=490"))
    assert "population.cells = 490 covers 0.49" in line and "'random' start can place at most 0.40" in line
    assert not (tmp_path / "o").exists()


def test_preview_leaves_set_values_alone_and_says_what_it_scaled(tmp_path):
    """The issue's `--preview --set population.cells=7800`: the cells the user set are not scaled; the error says
    what --preview did scale, and from what."""
    line = error_line(cli("scene", "S1", "--preview", "--no-movie", "--out", tmp_path / "o",
                          "--set", "population.cells=7800"))
    assert "population.cells = 7800" in line
    assert "--preview scaled domain.width_um from 200 to 50, domain.height_um from 200 to 50" in line
    sc = Scene.load("S1", {"population": {"cells": 100}, "domain": {"width_um": 80.0}}, preview=True)
    assert (sc.n_cells, sc.box) == (100, (80.0, 50.0))
    assert set(sc.preview_scaled) >= {"domain.height_um", "run.hours"} and "domain.width_um" not in sc.preview_scaled


def test_dense_feasible_start_shows_placement_progress(tmp_path):
    """126 cells in 30 x 30 µm (area fraction 0.35): placed, with progress on stderr, and the run's progress is
    plain lines (stderr is a pipe here), simulated time with its unit."""
    out = tmp_path / "o"
    p = cli("scene", "S1", "--no-movie", "--out", out, "--set", "domain.width_um=30", "--set", "domain.height_um=30",
            "--set", "population.cells=126", "--hours", "0.0002")
    assert p.returncode == 0, p.stderr
    assert "taichimyxo: placing 126 cells at random (area fraction 0.35)" in p.stderr
    assert "taichimyxo: placed 126 of 126 cells" in p.stderr
    assert "\r" not in p.stderr
    progress = [ln for ln in p.stderr.splitlines() if ln.startswith("S1: ")]
    # a run this short ends within its first chunk, which compiles the kernels: no rate is measured, so no ETA
    assert progress and all(" simulated (" in ln and (ln.endswith(" left") or " ..." in ln) for ln in progress)
    assert not any(ln.endswith(" left") for ln in progress)
    assert progress[-1].startswith("S1: 0.7 s of 0.7 s simulated (100 %)")


def test_dense_non_guided_rows_leave_their_lanes_only_from_a_tilted_start(small_scene, make_sim):
    """S11 on a 10 x 10 µm box (40 cells at area fraction 1, k_c = 0.002 N/m, no guiding, 2 ms): from exactly
    parallel rows every force lies along the row and no particle ever leaves its row's line; from the default start
    (each cell turned by up to 1 degree) cells pushing head on buckle, and within a minute a cell has moved further
    across than the row spacing, as the paper's S11 shows no pattern (docs/model.md "Initial configurations")."""
    sc = small_scene(0, box=(10.0, 10.0), population={"start": "aligned", "density_cells_per_cm2": 4e7},
                     collisions={"k_c_N_per_m": 0.002}, run={"dt_ms": 2.0})
    flat = initial_configuration(sc.with_overrides({"population": {"aligned_tilt_deg": 0.0}}))
    tilted = initial_configuration(sc)
    sim = make_sim(sc, *flat)
    steps = int(round(30.0 / sc.dt))
    sim.advance(steps)
    assert np.array_equal(sim.positions()[..., 1], flat[0][..., 1])      # exactly on its row's line, every particle
    assert np.abs(sim.positions()[..., 0] - flat[0][..., 0]).max() > 0.1  # while cells did move along it
    sim.set_state(*tilted)
    sim.advance(2 * steps)
    across = sim.positions()[..., 1].mean(1) - tilted[0][..., 1].mean(1)
    across = np.abs(np.mod(across + 5.0, 10.0) - 5.0)                      # periodic: the nearer image
    assert across.max() > sc.width and across.mean() > 0.1                # cells left their rows


def test_cell_length_read_as_the_chain_makes_the_outline_longer_by_one_width():
    """cell.length_reading (docs/decisions.md): 5 µm as the outline is a chain of 4.5 µm; as the chain, an outline of
    5.5 µm, so the random start's segments are 5/7 µm and the area fraction counts the longer outline."""
    outline = Scene.from_dict({"domain": {"width_um": 60.0, "height_um": 60.0}})
    chain = Scene.from_dict({"domain": {"width_um": 60.0, "height_um": 60.0}, "cell": {"length_reading": "chain"}})
    assert outline.rest_length == pytest.approx(4.5 / 7) and chain.rest_length == pytest.approx(5.0 / 7)
    assert chain.length == pytest.approx(5.5) and chain.area_fraction == pytest.approx(outline.area_fraction * 1.1)
    pos, _ = initial_configuration(chain)
    seg = np.linalg.norm(np.diff(pos, axis=1), axis=-1)
    np.testing.assert_allclose(seg, 5.0 / 7, rtol=1e-12)
    assert min_segment_distance_between_cells(pos, chain.box) >= chain.width
