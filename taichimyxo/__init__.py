"""taichimyxo: flexible-rod myxobacteria simulator on Taichi (Janulevicius et al., PLOS Comput Biol 2015).

The Python API (taichimyxo.interface.api), for notebooks and scripts:

    import taichimyxo as tm
    scene = tm.load_scene("S3", set={"domain.width_um": 30, "domain.height_um": 30}, seed=2)
    sim = tm.Simulation(scene)
    traj = tm.writers.Trajectory("out/S3.gsd", trigger=tm.Periodic(minutes=1))
    tm.run(sim, minutes=3, writers=[traj])
    image = tm.render_frame(sim.frame(), color="speed")

`import taichimyxo` stays light (no Taichi): the names below are imported on first use, Taichi with the first
Simulation.
"""
__version__ = "0.1.0"

import os as _os

_os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "false")   # keep stdout for our own output

# name -> module that defines it (imported on first use)
_LAZY = {
    "load_scene": "interface.api", "Simulation": "runtime.simulation", "run": "interface.api",
    "render_frame": "interface.api", "render_movie": "interface.api", "run_scene": "interface.api",
    "analyze": "interface.api", "claims": "interface.api", "Periodic": "runtime.triggers",
    "WallClock": "runtime.triggers", "Frame": "io.frame", "Scene": "io.scene", "SceneError": "io.scene",
    "Run": "runtime.run_loop", "drive": "runtime.run_loop", "load_sweep": "sweep", "run_sweep": "sweep",
    "read_tracks": "io.tracks", "tracks_report": "interface.tracks_api",
}
# tm.NAME -> the submodule (tm.writers, tm.api, ...)
_SUBMODULES = {"writers": "io.writers", "triggers": "runtime.triggers", "run_loop": "runtime.run_loop",
               "api": "interface.api", "render": "render", "trajectory": "io.trajectory"}

__all__ = sorted(_LAZY) + list(_SUBMODULES)


def __getattr__(name):
    import importlib
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(f".{_SUBMODULES[name]}", __name__)
    else:
        raise AttributeError(f"module 'taichimyxo' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
