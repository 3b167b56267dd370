"""Shared fixtures.

- `ti_session` / `ti_cpu`: Taichi on the CPU with 2 threads (TAICHIMYXO_THREADS, set here) and f64 literals (as
  tests/simtools.py sets them), initialised once per session; `ti_cpu` re-asserts it per test (backend.init is a
  no-op when Taichi is already so), so a test that re-initialised Taichi differently cannot leave the next one with
  dead fields.
- `small_scene(cells=2, box=(20, 20), **sections)`: simtools.build_small_scene, a validated Scene on a small periodic
  box with the movie off; sections are merged over it, e.g. small_scene(3, guiding={"kind": "active"}).
- `make_sim(scene, positions=None, engine_direction=None)`: the scene's Simulation (Simulation, or
  Simulation.from_positions when positions are given), closed (fields freed) after the test.
- `shapes`: simtools' chains to place by hand (cell, arc_cell, ring_radius_for_gap), in µm.
The builders themselves (chains, scenes, simulations) are in tests/simtools.py, the one place they are written.
- marker `slow`: tests that take more than a few seconds.
- marker `gpu`: tests that run on CUDA (tests/test_gpu.py; skipped where there is none).
"""
from __future__ import annotations

import os
from types import SimpleNamespace

import pytest

# Tests run on 2 threads, also where run_scene or a subprocess initialises Taichi itself (backend.init reads this when
# given no thread count), so that nothing re-initialises Taichi with another count and frees live fields.
os.environ.setdefault("TAICHIMYXO_THREADS", "2")


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: slower than a few seconds (still part of the default run)")
    config.addinivalue_line("markers", "keeps_taichi: the module holds Simulations in module-scoped fixtures, so "
                                       "Taichi is not restarted before each of its tests")
    config.addinivalue_line("markers", "gpu: runs on CUDA (skipped with one line where CUDA is not available)")


@pytest.fixture(autouse=True)
def fresh_taichi(request):
    """Taichi restarted before each test (unless its module is marked keeps_taichi), so the fields a test allocates
    get the same ids as in every other test that builds the same configuration. Taichi's offline cache keys a
    compiled kernel by the ids of the fields it touches (taichi/analysis/gen_offline_cache_key.cpp), so a kernel
    compiled once, in any earlier test or run, is loaded instead of compiled again (~1-3 s instead of 10-30 s per
    Simulation): on a clean CI machine that is most of the suite's time."""
    from taichimyxo.runtime import backend
    keeps = request.node.get_closest_marker("keeps_taichi") is not None
    if not keeps:
        backend.reset()
        backend.init("cpu", int(os.environ["TAICHIMYXO_THREADS"]), default_fp="f64")
    # and restarted again before each further Simulation the test builds once the earlier ones are closed (three
    # run_scene calls of one scene: one compile, two cache loads)
    backend.restart_between_simulations(not keeps)
    yield
    backend.restart_between_simulations(False)


@pytest.fixture(scope="session")
def ti_session():
    """Taichi initialised once per session on the CPU (2 threads)."""
    from taichimyxo.runtime import backend
    backend.init("cpu", int(os.environ["TAICHIMYXO_THREADS"]), default_fp="f64")
    return backend


@pytest.fixture
def ti_cpu(ti_session):
    """ti_session, re-asserted per test (a no-op unless another test re-initialised Taichi differently)."""
    ti_session.init("cpu", int(os.environ["TAICHIMYXO_THREADS"]), default_fp="f64")
    return ti_session


@pytest.fixture
def small_scene():
    from simtools import build_small_scene
    return build_small_scene


@pytest.fixture
def make_sim(ti_cpu):
    from taichimyxo.runtime.simulation import Simulation
    made = []

    def make(scene, positions=None, engine_direction=None):
        sim = Simulation(scene) if positions is None else Simulation.from_positions(scene, positions, engine_direction)
        made.append(sim)
        return sim

    yield make
    for sim in made:
        sim.close()


@pytest.fixture
def shapes():
    from simtools import arc_cell, cell, ring_radius_for_gap
    return SimpleNamespace(cell=cell, arc_cell=arc_cell, ring_radius_for_gap=ring_radius_for_gap)
