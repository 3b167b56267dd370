"""Helpers for building small simulations in tests: the one set of chain, scene and simulation builders (conftest.py's
fixtures use them), and numpy reference energies with a finite-difference gradient.

Importing it initialises Taichi on the CPU with f64 literals, so f64 scenes are exact to ~1e-12."""
import math

import numpy as np

from taichimyxo.io.scene import Scene
from taichimyxo.physics.placement import straight_cell
from taichimyxo.runtime import backend

backend.init("cpu", default_fp="f64")      # f64 constants, so f64 scenes are exact to ~1e-12


# ---------------------------------------------------------------- chains, scenes and simulations placed by hand
L0 = 4.5 / 7            # rest length of the default cell (L = 5 µm, W = 0.5 µm, N = 8: (L - W) / (N - 1))


def cell(centre, angle_deg=0.0, N=8, l0=L0):
    """Straight chain centred on `centre` along u = (cos, sin)(angle_deg), particle 0 at the -u end. Particle 0 is
    the head when k_e = +1, so such a cell moves along -u."""
    return straight_cell(np.asarray(centre, float), math.radians(angle_deg), N, l0)


def arc_cell(centre, radius, start_deg, N=8, l0=L0, direction=1):
    """Particles on a circle of `radius` around `centre`, consecutive particles l0 apart (chord), particle 0 at
    start_deg, going counter-clockwise for direction=+1."""
    dth = 2 * math.asin(min(1.0, l0 / (2 * radius))) * direction
    th = math.radians(start_deg) + dth * np.arange(N)
    return np.stack([centre[0] + radius * np.cos(th), centre[1] + radius * np.sin(th)], axis=1)


def ring_radius_for_gap(N, l0, gap_chord):
    """Radius of a circle on which N particles l0 apart leave a chord `gap_chord` between the two ends."""
    lo, hi = l0 / 2 + 1e-9, 100.0
    for _ in range(200):
        r = 0.5 * (lo + hi)
        used = (N - 1) * 2 * math.asin(min(1.0, l0 / (2 * r)))
        rest = 2 * math.pi - used
        chord = 2 * r * math.sin(rest / 2) if rest > 0 else -1.0
        if chord < gap_chord:
            lo = r
        else:
            hi = r
    return 0.5 * (lo + hi)


def build_small_scene(cells: int = 2, box=(20.0, 20.0), **sections) -> Scene:
    """A validated Scene on a small periodic box with the movie off; sections are merged over it, e.g.
    build_small_scene(3, guiding={"kind": "active"})."""
    data = {"domain": {"width_um": float(box[0]), "height_um": float(box[1])},
            "population": {"cells": int(cells)}, "output": {"movie": False}}
    for sec, vals in sections.items():
        data.setdefault(sec, {}).update(vals)
    return Scene.from_dict(data, where="test scene")


def sim_with(positions, ke=None, box=(20.0, 20.0), **sections):
    """The scene integrator's simulation of the given chains ((N, 2) or (n, N, 2)), k_e = +1 by default. Not closed
    after the test: use the make_sim fixture for that."""
    from taichimyxo.runtime.simulation import Simulation
    pos = np.asarray(positions, float)
    if pos.ndim == 2:
        pos = pos[None]
    ke = np.ones(len(pos), int) if ke is None else np.asarray(ke)
    return Simulation.from_positions(build_small_scene(len(pos), box=box, **sections), pos, ke)


# --------------------------------------------------------------- numpy reference energies (docs/model.md terms 1, 2, 4)
# each lives with its term; the contact energy is written from the definition (sample to nearest point of each other
# chain, global minimum), without the kernels' local nearest-segment rule
from taichimyxo.physics.terms.bending import energy as bend_energy  # noqa: E402,F401
from taichimyxo.physics.terms.contacts import energy as contact_energy  # noqa: E402,F401
from taichimyxo.physics.terms.springs import energy as spring_energy  # noqa: E402,F401


def fd_gradient(fun, pos, h=1e-6):
    g = np.zeros_like(pos)
    it = np.nditer(pos, flags=["multi_index"])
    for _ in it:
        i = it.multi_index
        p = pos.copy()
        p[i] += h
        ep = fun(p)
        p[i] -= 2 * h
        em = fun(p)
        g[i] = (ep - em) / (2 * h)
    return g


# --------------------------------------------------------------- the command line, as a user runs it
import os  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

REPO = Path(__file__).resolve().parent.parent


def cli(*args, cwd=None):
    env = dict(os.environ, TAICHIMYXO_THREADS="2")
    return subprocess.run([sys.executable, "-m", "taichimyxo", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or REPO, env=env, timeout=600)


def error_line(p, code=2):
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == code, (p.returncode, p.stderr, p.stdout)
    assert "Traceback" not in p.stderr + p.stdout, p.stderr
    errors = [ln for ln in lines if ln.startswith("taichimyxo: error: ")]
    assert len(errors) == 1, p.stderr
    return errors[0]
