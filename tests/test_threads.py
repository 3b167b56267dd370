"""Determinism: the same seed gives the same run, bit for bit, on one and two threads (gather, don't scatter;
counter-based randomness), with guiding, slime, reversals and the step controller."""
import os
import subprocess
import sys

import numpy as np
import pytest

RUN = r"""
import numpy as np, sys
from taichimyxo.runtime import backend
backend.init("cpu", threads=int(sys.argv[1]))
from taichimyxo.io.scene import Scene
from taichimyxo.runtime.simulation import Simulation
sc = Scene.from_dict({"domain": {"width_um": 40.0, "height_um": 40.0}, "population": {"cells": 120},
                      "guiding": {"kind": sys.argv[3]}, "reversals": {"enabled": True, "period_min": 0.05},
                      "slime": {"enabled": sys.argv[3] == "none"}, "run": {"step_control": sys.argv[4]}})
sim = Simulation(sc)
sim.advance(400)
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


def test_the_spread_order_visits_every_cell_once_and_spreads_each_threads_share():
    """The CPU's parallel loops visit cells in the order i * stride mod n (taichimyxo/runtime/launch.py): a
    permutation for every n, and each contiguous half of the loop takes about half of every part of the index range
    (the imbalance it exists for: one part of the range holding more contacts)."""
    from taichimyxo.runtime.launch import spread_stride
    for n in list(range(1, 400)) + [1440, 2000, 4096, 10007]:
        k = spread_stride(n)
        order = (np.arange(n) * k) % n
        assert len(np.unique(order)) == n
    n = 2000
    order = (np.arange(n) * spread_stride(n)) % n
    first_half = order[: n // 2]
    for part in range(10):                  # each tenth of the cells: about half of it in the first thread's share
        inside = np.count_nonzero((first_half >= part * n // 10) & (first_half < (part + 1) * n // 10))
        assert abs(inside - n // 20) <= n // 100
