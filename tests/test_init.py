"""Initial configurations: density, no overlaps, area fraction, spiral head to tail; thread-independent runs."""
import os
import subprocess
import sys

import numpy as np
import pytest

from taichimyxo.geometry import closest_points, min_image, sample_polyline_contacts
from taichimyxo.init import initial_configuration
from taichimyxo.scene import Scene


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
    sc = Scene.from_dict({"domain": {"width_um": 20.0, "height_um": 20.0},
                          "population": {"start": "aligned", "density_cells_per_cm2": 4e7}})
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


RUN = r"""
import numpy as np, sys
from taichimyxo import backend
backend.init("cpu", threads=int(sys.argv[1]))
from taichimyxo.scene import Scene
from taichimyxo.simulation import make_simulation
sc = Scene.from_dict({"domain": {"width_um": 40.0, "height_um": 40.0}, "population": {"cells": 120},
                      "guiding": {"kind": sys.argv[3]}, "reversals": {"enabled": True, "period_min": 0.05},
                      "slime": {"enabled": sys.argv[3] == "none"}, "run": {"step_control": sys.argv[4]}})
sim = make_simulation(sc)
sim.run(400)
np.save(sys.argv[2], sim.state.x.to_numpy())
"""


@pytest.mark.parametrize("guiding,control", [("adhesion", "fixed"), ("none", "fixed"), ("active", "error")])
def test_same_seed_same_run_on_one_and_two_threads(tmp_path, guiding, control):
    outs = []
    env = dict(os.environ, TAICHIMYXO_SERIAL_BELOW="0")       # force parallel loops even for this small system
    for threads in (1, 2):
        f = tmp_path / f"x{threads}.npy"
        subprocess.run([sys.executable, "-c", RUN, str(threads), str(f), guiding, control], check=True, env=env,
                       capture_output=True)
        outs.append(np.load(f))
    assert np.array_equal(outs[0], outs[1])
