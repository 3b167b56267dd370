"""Our trajectories in other tools.

- freud: `freud.box.Box.from_box(frame.configuration.box)` is the 2D periodic box (Lz = 0, taichimyxo.io.trajectory).
- MDAnalysis: its GSD reader reads positions only and counts time in frames. :func:`universe` opens a trajectory
  as an MDAnalysis Universe whose ``ts.time`` is the simulated time in seconds and whose frames carry the
  particles' velocities (µm/min, z = 0; zero in frame 0, where the speed window is empty):

      import taichimyxo.io.interop
      u = taichimyxo.io.interop.universe("videos/S3.gsd")
      for ts in u.trajectory:
          print(ts.time, u.atoms.velocities[:3])

MDAnalysis is not a dependency of taichimyxo (`pip install MDAnalysis`)."""
from __future__ import annotations

import os

import numpy as np


def frame_times(path) -> np.ndarray:
    """Simulated time of every frame, s (log/taichimyxo/time_s; a foreign file: its steps)."""
    import gsd.hoomd
    with gsd.hoomd.open(os.fspath(path), "r") as t:
        out = []
        for f in t:
            logged = f.log.get("taichimyxo/time_s")
            out.append(float(np.asarray(logged).reshape(-1)[0]) if logged is not None else float(f.configuration.step))
    return np.asarray(out)


class _TimeAndVelocities:
    """An MDAnalysis on-the-fly transformation: each frame's simulated time and velocities from the GSD file."""

    def __init__(self, path, times):
        self.path, self.times = os.fspath(path), times

    def __call__(self, ts):
        import gsd.hoomd
        with gsd.hoomd.open(self.path, "r") as t:
            ts.velocities = np.asarray(t[ts.frame].particles.velocity, np.float32)
        ts.data["time"] = float(self.times[ts.frame])
        return ts


def universe(path):
    """The trajectory at `path` as an MDAnalysis Universe: bonds and types from the file, time in simulated seconds,
    velocities in µm/min."""
    import MDAnalysis as mda
    times = frame_times(path)
    dt = float(times[1] - times[0]) if len(times) > 1 else 1.0
    u = mda.Universe(os.fspath(path), dt=dt)           # times between frames; each frame gets its logged time
    u.trajectory.add_transformations(_TimeAndVelocities(path, times))
    return u
