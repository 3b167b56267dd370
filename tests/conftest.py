"""Shared fixtures.

- `ti_session` / `ti_cpu`: Taichi on the CPU with 2 threads (TAICHIMYXO_THREADS, set here), initialised once per
  session; `ti_cpu` re-asserts it per test (backend.init is a no-op when Taichi is already so), so a test that
  re-initialised Taichi differently cannot leave the next one with dead fields.
- `small_scene(cells=2, box=(20, 20), **sections)`: a validated Scene on a small periodic box with the movie off;
  sections are merged over it, e.g. small_scene(3, guiding={"kind": "active"}).
- `make_sim(scene, positions=None, engine_direction=None)`: the scene integrator's Simulation (make_simulation),
  closed (fields freed) after the test.
- `shapes`: chains to place by hand (straight, arc, ring), in µm, for a scene's N and l0.
- marker `slow`: tests that take more than a few seconds.
"""
from __future__ import annotations

import math
import os
from types import SimpleNamespace

import numpy as np
import pytest

from taichimyxo.scene import Scene

# Tests run on 2 threads, also where run_scene or a subprocess initialises Taichi itself (backend.init reads this when
# given no thread count), so that nothing re-initialises Taichi with another count and frees live fields.
os.environ.setdefault("TAICHIMYXO_THREADS", "2")


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: slower than a few seconds (still part of the default run)")


def build_small_scene(cells: int = 2, box=(20.0, 20.0), **sections) -> Scene:
    data = {"domain": {"width_um": float(box[0]), "height_um": float(box[1])},
            "population": {"cells": int(cells)}, "output": {"movie": False}}
    for sec, vals in sections.items():
        data.setdefault(sec, {}).update(vals)
    return Scene.from_dict(data, where="test scene")


@pytest.fixture(scope="session")
def ti_session():
    """Taichi initialised once per session on the CPU (2 threads)."""
    from taichimyxo import backend
    backend.init("cpu", int(os.environ["TAICHIMYXO_THREADS"]))
    return backend


@pytest.fixture
def ti_cpu(ti_session):
    """ti_session, re-asserted per test (a no-op unless another test re-initialised Taichi differently)."""
    ti_session.init("cpu", int(os.environ["TAICHIMYXO_THREADS"]))
    return ti_session


@pytest.fixture
def small_scene():
    return build_small_scene


@pytest.fixture
def make_sim(ti_cpu):
    from taichimyxo.sim import make_simulation
    made = []

    def make(scene, positions=None, engine_direction=None):
        sim = make_simulation(scene, positions=positions, engine_direction=engine_direction)
        made.append(sim)
        return sim

    yield make
    for sim in made:
        sim.close()


def straight(centre, angle, N, l0):
    """Straight chain along u = (cos angle, sin angle), particle 0 at the -u end. Particle 0 is the head when
    k_e = +1, so such a cell moves along -u."""
    u = np.array([math.cos(angle), math.sin(angle)])
    k = np.arange(N) - (N - 1) / 2.0
    return np.asarray(centre, float)[None, :] + k[:, None] * l0 * u[None, :]


def arc(centre, radius, start_angle, N, l0, sense=1):
    """Chain on a circle of `radius` around `centre`, consecutive particles l0 apart (chord), particle 0 at
    start_angle, going counter-clockwise for sense=+1."""
    dphi = 2 * math.asin(min(1.0, l0 / (2 * radius)))
    phi = start_angle + sense * dphi * np.arange(N)
    return np.asarray(centre, float)[None, :] + radius * np.stack([np.cos(phi), np.sin(phi)], axis=1)


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


@pytest.fixture
def shapes():
    return SimpleNamespace(straight=straight, arc=arc, ring_radius_for_gap=ring_radius_for_gap)
