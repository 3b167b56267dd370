"""Trajectories in the GSD file format with the HOOMD schema (readable by OVITO, HOOMD-blue, freud, MDAnalysis).

Schema (docs/trajectory.md):
- configuration.box = [Lx, Ly, 0, 0, 0, 0] µm (Lz = 0: HOOMD's 2D box, so freud takes it as 2D without a warning),
  dimensions = 2, step = integration step; the file is readable by all, as the other outputs (mode 0666 - umask).
- particles.position (Np, 3) float32: HOOMD convention, box centred at the origin, positions in [-L/2, L/2);
  particles.image (Np, 3) int32 so that position + image * L gives every cell's chain unwrapped.
  Particles are stored cell by cell: particle i belongs to cell i // N and is number i % N along it.
  particles.types = ["pole", "body"]: the two end particles of each cell are "pole".
- bonds.group (Nb, 2): the segments, (i, i+1) within each cell; bonds.types = ["segment"]. Given in every frame
  (gsd stores them once, in frame 0, and later frames inherit them, as the HOOMD schema defines).
- particles.velocity (Np, 3) float32, µm/min (z = 0): displacement over the speed window (the same window as the
  speed below, whose value is its norm); absent in frame 0, where the window is empty, and in older files.
- log/particles/speed_um_per_min (Np,) float32: particle speed averaged over the speed window (docs/model.md).
- log/particles/engine_direction (Np,) int8: the cell's k_e (+1: particle 0 of the cell is the head).
- log/bonds/strain_energy_J (Nb,) float32: per-segment strain energy, only when the scene asks for it.
- log/taichimyxo/time_s (1,) float64: simulated time, s (MDAnalysis: taichimyxo.io.interop.universe reads it).
- log/taichimyxo/scene_json (frame 0 only): the fully resolved scene as UTF-8 JSON bytes (uint8 array).
"""
from __future__ import annotations

import json
import os
from typing import Iterator

import numpy as np

from .frame import Frame, unwrap_chains

SCHEMA_VERSION = 1


def _gsd():
    import gsd.hoomd
    return gsd.hoomd


class TrajectoryWriter:
    """Append Frames to a GSD file. Opened lazily on the first frame; `close()` leaves a readable file.

    mode "w" truncates; mode "a" appends (used by --resume)."""

    def __init__(self, path: str, scene_dict: dict | None = None, mode: str = "w"):
        self.path = path
        self.scene_dict = scene_dict or {}
        self.mode = mode
        self._f = None
        self._first = True
        self.frames_written = 0

    def _open(self):
        hoomd = _gsd()
        if self.mode == "a" and os.path.exists(self.path):
            self._f = hoomd.open(self.path, "a")
            self._first = False
        else:
            # gsd creates its files 0640 but keeps an existing file's mode: created here, the file follows the
            # umask like every other output
            os.close(os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666))
            self._f = hoomd.open(self.path, "w")

    def append(self, fr: Frame) -> None:
        if self._f is None:
            self._open()
        hoomd = _gsd()
        n_cells, N = fr.positions.shape[:2]
        Np = n_cells * N
        L = np.array(fr.box, dtype=np.float64)
        p = fr.positions.reshape(Np, 2).astype(np.float64) - L / 2
        img = np.floor((p + L / 2) / L).astype(np.int32)
        wrapped = p - img * L
        g = hoomd.Frame()
        g.configuration.box = [float(L[0]), float(L[1]), 0.0, 0.0, 0.0, 0.0]
        g.configuration.dimensions = 2
        g.configuration.step = int(fr.step)
        g.particles.N = Np
        pos3 = np.zeros((Np, 3), np.float32)
        pos3[:, :2] = wrapped
        g.particles.position = pos3
        im3 = np.zeros((Np, 3), np.int32)
        im3[:, :2] = img
        g.particles.image = im3
        g.particles.types = ["pole", "body"]
        tid = np.ones((n_cells, N), np.uint32)
        tid[:, 0] = 0
        tid[:, -1] = 0
        g.particles.typeid = tid.reshape(-1)
        g.particles.diameter = np.full(Np, fr.width_um, np.float32)
        if fr.particle_velocity is not None:
            v3 = np.zeros((Np, 3), np.float32)
            v3[:, :2] = np.asarray(fr.particle_velocity, np.float32).reshape(Np, 2)
            g.particles.velocity = v3
        # the bonds in every frame: a frame without them would store bonds.N = 0 and readers (OVITO, freud,
        # MDAnalysis) would show none after frame 0. gsd.hoomd writes a chunk only where it differs from frame 0,
        # so later frames inherit frame 0's bonds, as the HOOMD schema defines, at no cost in file size.
        nb = n_cells * (N - 1)
        base = (np.arange(n_cells) * N)[:, None] + np.arange(N - 1)[None, :]
        g.bonds.N = nb
        g.bonds.types = ["segment"]
        g.bonds.typeid = np.zeros(nb, np.uint32)
        g.bonds.group = np.stack([base.reshape(-1), base.reshape(-1) + 1], axis=1).astype(np.uint32)
        if self._first:
            meta = dict(self.scene_dict)
            meta.setdefault("_schema_version", SCHEMA_VERSION)
            meta.setdefault("_width_um", fr.width_um)
            g.log["taichimyxo/scene_json"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8).copy()
        g.log["particles/speed_um_per_min"] = np.asarray(fr.particle_speed, np.float32).reshape(Np)
        g.log["particles/engine_direction"] = np.repeat(np.asarray(fr.engine_direction, np.int8), N)
        if fr.segment_strain is not None:
            g.log["bonds/strain_energy_J"] = np.asarray(fr.segment_strain, np.float32).reshape(-1)
        g.log["taichimyxo/time_s"] = np.array([fr.time_s], np.float64)
        self._f.append(g)
        self._f.flush()
        self._first = False
        self.frames_written += 1

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class TrajectoryError(ValueError):
    """A file that cannot be read as a trajectory of cells, or lacks a logged quantity; one line for the user."""


def check_trajectory(path: str, need_logs: dict | None = None) -> int:
    """Refuse, before any work, a file `render` or `analyze` cannot use: missing, not GSD, not the HOOMD schema,
    no frames, no chains of particles (neither our stored scene nor bonds), or without a logged quantity the caller
    needs (need_logs: {"log/...": "what to do about it"}; checked in the first and the last frame).
    Returns the number of frames."""
    if not os.path.isfile(path):
        raise TrajectoryError(f"trajectory {path} not found")
    try:
        t = _gsd().open(path, "r")
    except (RuntimeError, OSError, ValueError) as e:
        raise TrajectoryError(f"{path} is not a GSD trajectory ({str(e).splitlines()[0] if str(e) else e!r})") \
            from None
    try:
        n = len(t)
        if n == 0:
            raise TrajectoryError(f"{path}: the trajectory has no frames")
        f0 = t[0]
        has_scene = f0.log.get("taichimyxo/scene_json") is not None
        if int(f0.particles.N) == 0 or (not has_scene and int(f0.bonds.N) == 0):
            raise TrajectoryError(f"{path} holds no cells: neither a taichimyxo scene (log/taichimyxo/scene_json) "
                                  f"nor bonds joining its particles into chains")
        for key, fix in (need_logs or {}).items():
            for i in sorted({0, n - 1}):
                if t.file.chunk_exists(frame=i, name=key):
                    continue
                # a log written only in frame 0 is inherited by later frames
                if i > 0 and t.file.chunk_exists(frame=0, name=key):
                    continue
                raise TrajectoryError(f"{path}: frame {i} has no {key}; {fix}")
    except TrajectoryError:
        raise
    except (RuntimeError, OSError, ValueError, KeyError) as e:
        raise TrajectoryError(f"{path} cannot be read as a trajectory ({e})") from None
    finally:
        t.close()
    return n


def read_scene(path: str) -> dict:
    """The resolved scene stored in frame 0 (empty dict for foreign GSD files)."""
    with _gsd().open(path, "r") as t:
        if len(t) == 0:
            return {}
        f0 = t[0]
        raw = f0.log.get("taichimyxo/scene_json")
        return json.loads(bytes(np.asarray(raw, np.uint8)).decode()) if raw is not None else {}


def _frame_from_gsd(g, N: int, width: float, meta: dict, has_velocity: bool = False) -> Frame:
    L = np.array(g.configuration.box[:2], dtype=np.float64)
    Np = int(g.particles.N)
    pos = g.particles.position[:, :2].astype(np.float64) + g.particles.image[:, :2] * L + L / 2
    n_cells = Np // N
    pos = unwrap_chains(pos.reshape(n_cells, N, 2), L)
    spd = g.log.get("particles/speed_um_per_min")
    spd = np.zeros((n_cells, N), np.float32) if spd is None else np.asarray(spd, np.float32).reshape(n_cells, N)
    ke = g.log.get("particles/engine_direction")
    ke = np.ones(n_cells, np.int8) if ke is None else np.asarray(ke, np.int8).reshape(n_cells, N)[:, 0].copy()
    vel = None
    if has_velocity:
        vel = np.asarray(g.particles.velocity, np.float32)[:, :2].reshape(n_cells, N, 2).copy()
    st = g.log.get("bonds/strain_energy_J")
    st = None if st is None else np.asarray(st, np.float64).reshape(n_cells, N - 1)
    t = g.log.get("taichimyxo/time_s")
    t = float(np.asarray(t).reshape(-1)[0]) if t is not None else float(g.configuration.step)
    return Frame(time_s=t, step=int(g.configuration.step), box=(float(L[0]), float(L[1])), width_um=width,
                 positions=pos, engine_direction=ke, particle_speed=spd, segment_strain=st, meta=meta,
                 particle_velocity=vel)


def trim_after(path: str, step: int) -> int:
    """Drop the frames after `step` (a resume point: frames a run wrote past its last checkpoint before it was
    killed or its disk filled), rewriting the file through a temporary one so it stays readable throughout; the
    run's events table loses its rows after `step` too. Returns the frames dropped."""
    hoomd = _gsd()
    import gsd.fl
    with gsd.fl.open(path, "r") as g:          # the steps alone, not every frame's particles
        steps = [int(g.read_chunk(i, "configuration/step")[0]) if g.chunk_exists(i, "configuration/step") else 0
                 for i in range(g.nframes)]     # step 0, the default, is not stored
    keep = sum(1 for s in steps if s <= step)
    if keep < len(steps):
        tmp = path + ".trim.tmp"
        with hoomd.open(path, "r") as t, hoomd.open(tmp, "w") as out:
            for i in range(keep):
                f = t[i]
                if i > 0:
                    f.log.pop("taichimyxo/scene_json", None)    # frame 0's, which reading repeats
                out.append(f)
        os.replace(tmp, path)
    from .event_table import events_path
    ev = events_path(path)
    if os.path.isfile(ev):
        with open(ev, encoding="utf-8") as f:
            lines = f.readlines()
        kept = lines[:1] + [ln for ln in lines[1:] if int(ln.split(",")[1]) <= step]
        if len(kept) < len(lines):
            with open(ev + ".tmp", "w", encoding="utf-8") as f:
                f.writelines(kept)
            os.replace(ev + ".tmp", ev)
    return len(steps) - keep


def count_frames(path: str) -> int:
    with _gsd().open(path, "r") as t:
        return len(t)


def read_frames(path: str, every: int = 1, start: int = 0) -> Iterator[Frame]:
    """Yield the Frames of a GSD trajectory (ours, or any HOOMD-schema file of linear chains of equal length,
    given `particles_per_cell` in the stored scene)."""
    meta = read_scene(path)
    with _gsd().open(path, "r") as t:
        if len(t) == 0:
            return
        N = int(meta.get("cell", {}).get("particles", 0)) or _guess_chain_length(t[0])
        width = float(meta.get("_width_um", meta.get("cell", {}).get("width_um", 0.5)))
        for i in range(start, len(t), max(1, every)):
            # a frame stores velocity unless it is the default (zero); a later frame without the chunk inherits
            # frame 0's, as the HOOMD schema defines (gsd.hoomd returns it)
            has_v = any(t.file.chunk_exists(frame=j, name="particles/velocity") for j in (i, 0))
            yield _frame_from_gsd(t[i], N, width, meta, has_velocity=has_v)


def _guess_chain_length(g) -> int:
    grp = np.asarray(g.bonds.group)
    if len(grp) == 0:
        return 1
    # chains are consecutive; a chain ends where the next bond does not start at the previous bond's end
    breaks = np.nonzero(grp[1:, 0] != grp[:-1, 1])[0]
    return int(breaks[0] + 2) if len(breaks) else int(g.particles.N)
