"""Building a simulation, step by step (taichimyxo.api.Simulation does all three; run_scene times the last):
the start state (a checkpoint's, given positions, or placed by the scene's start, before Taichi starts), Taichi
for the scene's precision, and the simulation of the scene's integrator."""
from __future__ import annotations

from .scene import Scene, SceneError


def initial_state(scene: Scene, checkpoint: dict | None = None, positions=None, engine_direction=None,
                  progress=None):
    """(positions, engine_direction): a checkpoint's, the ones given, or placed by the scene's start (before Taichi
    starts: a density the start cannot place is a SceneError). progress: called (placed, n, tries) while placing."""
    if checkpoint is not None:
        return checkpoint["x"], checkpoint["ke"]
    if positions is not None:
        return positions, engine_direction
    from .init import PlacementError, initial_configuration
    try:
        return initial_configuration(scene, progress=progress)
    except PlacementError as e:
        raise SceneError(f"population: the {scene.start!r} start cannot place the cells ({e}); lower "
                         f"population.density_cells_per_cm2 or population.cells, or enlarge the domain"
                         f"{scene.preview_note()}") from None


def init_backend(scene: Scene, arch: str = "cpu", threads: int | None = None) -> str:
    """Taichi on `arch` (an unavailable GPU falls back to the CPU) with the scene's precision; the arch used."""
    from . import backend
    return backend.init(arch, threads, default_fp="f64" if scene.precision == "f64" else None)


def build_simulation(scene: Scene, positions, engine_direction, checkpoint: dict | None = None):
    """The simulation of the scene's integrator from these positions (Taichi initialised), at the checkpoint's
    state when one is given."""
    from .simulation import make_simulation
    sim = make_simulation(scene, positions=positions, engine_direction=engine_direction)
    if checkpoint is not None:
        sim.load_checkpoint(checkpoint)
    return sim
