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
