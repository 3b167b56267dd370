"""Writers: the outputs of a run, each a small object with a trigger, attached to the run loop
(:func:`taichimyxo.runtime.run_loop.drive`) the way HOOMD-blue attaches ``hoomd.write.GSD(trigger=...)``.

    import taichimyxo as tm
    traj = tm.writers.Trajectory("out/S3.gsd", trigger=tm.Periodic(minutes=1))
    movie = tm.writers.Movie("out/S3.mp4", trigger=tm.Periodic(minutes=1), color="speed")
    tm.run(sim, minutes=30, writers=[tm.writers.InvariantCheck(), traj, movie])

- :class:`Trajectory`: GSD frames (HOOMD schema, taichimyxo.io.trajectory); appends when written again after a close.
- :class:`Movie`: an MP4 (taichimyxo.render.VideoWriter).
- :class:`FigurePanel`: the last frame as a PNG figure panel, when the run completes.
- :class:`Checkpoint`: the full state (npz) on its wall-clock trigger, on interruption and on a broken invariant;
  removed when the run completes (``remove_when_completed``).
- :class:`Summary`: the JSON run summary, when the run ends (any status).
- :class:`InvariantCheck`: no trigger of its own: checks every frame the run makes (finite positions, segment
  lengths, windowed speeds) and the positions between frames; a broken invariant stops the run (status "failed").
- :class:`ProgressLine`: the one status line on stderr.

A writer's hooks, all optional (see :class:`Writer`): ``start(run)`` before the first step, ``write(run)`` when its
trigger fires (``run.frame`` is the Frame of that step), ``after_chunk(run)`` after every chunk of steps,
``close()`` when the run ends (any status), ``finish(run)`` after every writer is closed. ``final=True``: also
write at the last step of the run. A new output is a new Writer subclass here; the run loop does not change.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

from ..runtime.run_loop import InvariantBroken
from ..runtime.status_line import Progress
from ..runtime.triggers import WallClock

SUMMARY_VERSION = 1


class Writer:
    trigger = None      # Periodic: write at the steps it fires; WallClock: asked between chunks; None: every frame
    final = False       # also write at the last step of the run
    order = 0           # writers act in this order, then in the order given (the invariant check first)

    def start(self, run) -> None:
        pass

    def write(self, run) -> None:
        pass

    def after_chunk(self, run) -> None:
        pass

    def close(self) -> None:
        pass

    def finish(self, run) -> None:
        pass


class Trajectory(Writer):
    """GSD trajectory (HOOMD schema) of the frames at `trigger`; append=True continues an existing file."""

    def __init__(self, path, trigger, *, final: bool = False, append: bool = False):
        self.path, self.trigger, self.final = Path(path), trigger, final
        self.mode = "a" if append else "w"
        self._w = None

    def start(self, run) -> None:
        if self._w is None:
            from .trajectory import TrajectoryWriter
            scene_dict = run.sim.scene.to_dict()
            scene_dict["_fingerprint"] = run.sim.scene.fingerprint()
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._w = TrajectoryWriter(str(self.path), scene_dict, mode=self.mode)

    def write(self, run) -> None:
        self._w.append(run.frame)

    def close(self) -> None:
        if self._w is not None:
            self._w.close()
            self._w.mode = "a"      # written again (a next run of the same simulation): append


class Movie(Writer):
    """MP4 movie of the frames at `trigger` (H.264, fragmented: playable while written). size: the largest frame
    (the movie takes the domain's aspect ratio); render_options: taichimyxo.render.Renderer's (title, vmin,
    vmax, free_speed, ...). A movie cannot be continued once closed: drive(..., close=False) keeps it open."""

    def __init__(self, path, trigger, *, final: bool = False, color: str = "speed", size=(1920, 1080),
                 fps: float = 30, **render_options):
        from ..render import VideoWriter
        self.path, self.trigger, self.final = Path(path), trigger, final
        self.video = VideoWriter(str(path), size=size, fps=fps, color=color, **render_options)

    def append_frames(self, frames) -> None:
        """Add frames made elsewhere (e.g. a trajectory's, when a resumed run rebuilds its movie)."""
        for fr in frames:
            self.video.append(fr)

    def write(self, run) -> None:
        self.video.append(run.frame)

    def close(self) -> None:
        self.video.close()


class FigurePanel(Writer):
    """The run's last frame as a PNG figure panel (the panel `render` writes too), when the run completes."""

    def __init__(self, path, *, color: str = "speed", **render_options):
        self.path, self.color, self.render_options = Path(path), color, render_options

    def finish(self, run) -> None:
        if run.completed:
            from ..render import write_png
            write_png(run.last_frame if run.last_frame is not None else run.sim.frame(), str(self.path),
                      color=self.color, **self.render_options)


def scene_render_options(scene) -> dict:
    """The colouring and labels a scene's movie and panel use (output.color, its range, v_b, the scene name)."""
    return dict(color=scene.color, title=scene.name,
                free_speed=scene.v_b_um_per_min, **scene.color_range)


# ------------------------------------------------------------------------------------------------ checkpoints
class Checkpoint(Writer):
    """The full state as npz (positions, speed window, clocks, slime; see Simulation.get_checkpoint) with the
    scene's fingerprint and the run's wall-time totals up to that state (session_totals; `before`: the earlier
    sessions' totals, previous_sessions; by default those of the checkpoint the simulation was loaded from): on
    `trigger` (wall clock), on interruption and on a broken invariant. Written atomically (a temporary file, then
    renamed). A session killed without a summary resumes from here with its wall time up to the checkpoint counted."""

    def __init__(self, path, trigger=None, *, remove_when_completed: bool = True, before: dict | None = None):
        self.path = Path(path)
        self.trigger = trigger if trigger is not None else WallClock(seconds=300)
        self.remove_when_completed = remove_when_completed
        self.before = dict(before) if before is not None else None

    def start(self, run) -> None:
        if self.before is None:
            self.before = dict(run.sim.sessions_before)
        if hasattr(self.trigger, "restart"):
            self.trigger.restart()

    def write(self, run) -> None:
        write_checkpoint(run.sim, self.path, session_totals(self.before, sum(run.wall_by_hour), run.wall_by_hour))

    def finish(self, run) -> None:
        if run.status in ("interrupted", "failed"):
            write_checkpoint(run.sim, self.path, session_totals(self.before, run.wall_seconds, run.wall_by_hour))
        elif run.status == "completed" and self.remove_when_completed and self.path.is_file():
            self.path.unlink()
        # no_space: the last checkpoint stays the resume point (the trajectory may lack this state's frame)


def write_checkpoint(sim, path: Path, totals: dict | None = None) -> None:
    """totals: the run's wall-time totals up to this state (session_totals), stored beside it."""
    import numpy as np
    st = sim.get_checkpoint()
    st["fingerprint"] = np.array(sim.scene.fingerprint())
    for k, v in (totals or {}).items():
        st[k] = np.asarray(v, np.int64 if k == "sessions" else np.float64)
    tmp = path.with_name(path.name + ".tmp.npz")
    try:
        np.savez(tmp, **st)
    except OSError:
        tmp.unlink(missing_ok=True)         # a full disk: the previous checkpoint stays whole
        raise
    os.replace(tmp, path)


def read_checkpoint(path, scene) -> dict:
    """A checkpoint's arrays, refused (ValueError) when it was written for different scene parameters."""
    import zipfile

    import numpy as np
    try:
        ckpt = dict(np.load(path, allow_pickle=False))
    except FileNotFoundError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise ValueError(f"{path} cannot be read ({type(e).__name__}: {e}; cut short or corrupted); it is left as "
                         f"it is: --overwrite to start the run again") from None
    if "fingerprint" not in ckpt:
        raise ValueError(f"{path} is not a taichimyxo checkpoint (it has no fingerprint); it is left as it is: "
                         f"--overwrite to start the run again")
    if str(ckpt.get("fingerprint")) != scene.fingerprint():
        raise ValueError(f"{path} was written for different scene parameters")
    if "step" not in ckpt:
        raise ValueError(f"{path} is not a whole checkpoint (it has no step); it is left as it is: --overwrite to "
                         f"start the run again")
    return ckpt


# ------------------------------------------------------------------------------------------------ invariants
# Checked at every frame (positions and windowed speeds already copied for the frame, so the check is nearly free).
# Looser than the tests' bounds (invariants.Bounds: lengths within 20 %) so a healthy long run is never stopped,
# yet any explicit-Euler blow-up crosses them within a frame or two.
from ..physics.geometry import SEGMENT_LENGTH_TOL  # noqa: E402  (one bound: frames and the neighbour grid)


def check_positions(pos, scene) -> str | None:
    """The first invariant the positions (n_cells, N, 2) break, as a phrase, or None: all finite, every segment
    within 1 +- SEGMENT_LENGTH_TOL of l0."""
    import numpy as np
    if not np.all(np.isfinite(pos)):
        return "non-finite positions"
    from ..physics.invariants import segment_lengths
    ln = segment_lengths(pos) / scene.rest_length
    lo, hi = float(ln.min(initial=1.0)), float(ln.max(initial=1.0))
    if lo < 1 - SEGMENT_LENGTH_TOL or hi > 1 + SEGMENT_LENGTH_TOL:
        return f"segment lengths {lo:.2f}..{hi:.2f} l0 outside 1 +- {SEGMENT_LENGTH_TOL} l0"
    return None


def check_frame(fr, scene, speed_bound_vb: float, check_speed: bool) -> str | None:
    """check_positions, and every windowed particle speed within the physical bound (speed_bound_vb v_b, from
    invariants.Bounds.for_scene). check_speed: the frame's speeds were averaged over the full speed window."""
    import numpy as np
    broken = check_positions(fr.positions, scene)
    if broken is not None:
        return broken
    if check_speed:
        v_b = scene.v_b_um_per_min
        sp = np.asarray(fr.particle_speed, np.float64)
        top = float(sp.max(initial=0.0)) / v_b if np.all(np.isfinite(sp)) else math.inf
        if top > speed_bound_vb:
            return f"particle speed {top:.3g} v_b above the physical bound {speed_bound_vb:.3g} v_b"
    return None


class InvariantCheck(Writer):
    """At every frame: check_frame (speeds only when averaged over the full window); after every chunk that ends
    between frames (at most chunk_steps apart): check_positions, so a blow-up is stopped before NaNs reach the
    neighbour list, however far apart the frames are. A broken invariant raises InvariantBroken: the run stops
    with status "failed"."""
    order = -1

    def __init__(self, speed_bound_vb: float | None = None):
        self.speed_bound = speed_bound_vb
        self._checked = None

    def start(self, run) -> None:
        if self.speed_bound is None:
            from ..physics.invariants import Bounds
            self.speed_bound = Bounds.for_scene(run.sim.scene).speed_factor

    def write(self, run) -> None:
        fr = run.frame
        self._checked = fr.step
        broken = check_frame(fr, run.sim.scene, self.speed_bound, run.full_window and fr.step > 0)
        if broken is not None:
            raise InvariantBroken(broken)

    def after_chunk(self, run) -> None:
        if self._checked != run.step:
            broken = check_positions(run.sim.positions(), run.sim.scene)
            if broken is not None:
                raise InvariantBroken(broken)


# ------------------------------------------------------------------------------------------------ progress, summary
class ProgressLine(Writer):
    """The one status line on stderr (taichimyxo.runtime.status_line.Progress), from the start to `total_steps`."""

    def __init__(self, name: str, total_steps: int, stream=None):
        self.name, self.total, self.stream = name, total_steps, stream
        self.bar, self._run = None, None

    def start(self, run) -> None:
        from ..runtime.status_line import starting_note
        self._run = run
        self.bar = Progress(self.name, self.total, run.sim.scene.dt, run.step, stream=self.stream,
                            starting=starting_note(run.sim.scene))
        self.bar.update(run.step, force=True)

    def after_chunk(self, run) -> None:
        first = self.bar.measured_from is None
        self.bar.update(run.step, force=first)        # the first chunk compiled the kernels: say it is done
        if first and self.bar.measured_from is not None:
            from ..runtime.status_line import remember_first_chunk
            remember_first_chunk(run.sim.scene, self.bar.first_chunk_seconds())

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close(self._run.step)
            self.bar = None


# what a checkpoint stores beside the state: how long the run took to reach it, not part of the state
SESSION_KEYS = ("wall_seconds_total", "sessions", "wall_seconds_by_hour")


def session_totals(before: dict, wall: float, by_hour: list) -> dict:
    """The run's totals over its sessions: the earlier ones' (`before`, previous_sessions) and this one's so far."""
    return {"wall_seconds_total": before.get("wall_seconds_total", 0.0) + wall,
            "sessions": before.get("sessions", 0) + 1,
            "wall_seconds_by_hour": _add_lists(before.get("wall_seconds_by_hour", []), by_hour)}


def checkpoint_totals(checkpoint: dict) -> dict:
    """The wall-time totals a checkpoint stored (session_totals), or {} for one written before it stored them."""
    if "wall_seconds_total" not in checkpoint:
        return {}
    return {"wall_seconds_total": float(checkpoint["wall_seconds_total"]),
            "sessions": int(checkpoint["sessions"]),
            "wall_seconds_by_hour": [float(w) for w in checkpoint["wall_seconds_by_hour"]]}


def previous_sessions(path: Path, scene, checkpoint: dict | None = None) -> dict:
    """Totals of the earlier sessions of this run: those stored in the checkpoint it resumes from (its wall time up
    to that state, even when the session was killed), else those of the summary an interrupted session wrote."""
    stored = checkpoint_totals(checkpoint) if checkpoint is not None else {}
    if stored:
        return stored
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(d, dict) or d.get("fingerprint") != scene.fingerprint() or d.get("completed"):
        return {}
    return {"wall_seconds_total": float(d.get("wall_seconds_total", d.get("wall_seconds", 0.0))),
            "sessions": int(d.get("sessions", 1)),
            "wall_seconds_by_hour": [float(w) for w in d.get("wall_seconds_by_hour", [])]}


def _add_lists(a: list, b: list) -> list:
    n = max(len(a), len(b))
    return [round((a[i] if i < len(a) else 0.0) + (b[i] if i < len(b) else 0.0), 3) for i in range(n)]


def _load_average() -> float | None:
    """The machine's 1-minute load average when the summary is written: a rate is only comparable at a like load."""
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:
        return None


class Summary(Writer):
    """The JSON run summary, written when the run ends (any status). files: the outputs to list (name -> Path);
    checkpoint: the checkpoint's path, listed when the run did not complete; resumed: this session continued an
    interrupted one. The totals add the earlier sessions': `before` (previous_sessions), else those of the
    checkpoint the simulation was loaded from, else, when resumed, those of the summary it wrote. setup_seconds,
    arch: how the simulation was built. started_from: "placement" (the scene's own start) or "given state"
    (run_scene's start_state), recorded as the summary's "started_from"."""
    order = 1

    def __init__(self, path, *, files: dict | None = None, checkpoint=None, resumed: bool = False,
                 setup_seconds: float = 0.0, arch: str = "cpu", before: dict | None = None,
                 started_from: str = "placement"):
        self.path, self.files, self.checkpoint = Path(path), dict(files or {}), checkpoint
        self.resumed, self.setup_seconds, self.arch, self.before = resumed, setup_seconds, arch, before
        self.started_from = started_from
        self.summary = None

    def finish(self, run) -> None:
        before = self.before if self.before is not None else (
            run.sim.sessions_before or (previous_sessions(self.path, run.sim.scene) if self.resumed else {}))
        self.summary = run_summary(run, self.files, self.checkpoint, before, self.setup_seconds, self.arch)
        self.summary["started_from"] = self.started_from
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            tmp.write_text(json.dumps(self.summary, indent=1))
        except OSError:
            tmp.unlink(missing_ok=True)     # the summary before it stays whole
            raise
        os.replace(tmp, self.path)


def run_summary(run, files: dict, checkpoint, before: dict, setup_s: float, arch: str) -> dict:
    from ..runtime import backend
    sim = run.sim
    scene = sim.scene
    status, wall = run.status, run.wall_seconds
    totals = session_totals(before, wall, run.wall_by_hour)
    summary = {
        "summary_version": SUMMARY_VERSION,
        "scene": scene.name, "title": scene.title, "paper_figure": scene.paper_figure,
        "seed": scene.seed, "fingerprint": scene.fingerprint(), "completed": status == "completed",
        "status": status, "cells": scene.n_cells, "particles": sim.n_p, "segments": sim.n_s,
        "box_um": list(scene.box), "dt_s": scene.dt,
        # totals since the start of the run (over every session, when it was interrupted and resumed)
        "steps": sim.step_count, "simulated_seconds": sim.time,
        "wall_seconds_total": totals["wall_seconds_total"], "sessions": totals["sessions"],
        # this session (this process) alone: the rate pairs its steps with its wall time
        "steps_this_session": sim.step_count - run.start_step,
        "simulated_seconds_this_session": (sim.step_count - run.start_step) * scene.dt,
        "wall_seconds": wall, "setup_seconds": setup_s,
        # wall seconds each simulated hour cost (index = hour; over every session): the cost grows as the state forms
        "wall_seconds_by_hour": totals["wall_seconds_by_hour"],
        "particle_steps_per_second": run.steps_done * sim.n_p / max(wall, 1e-9),
        "frame_interval_s": scene.frame_every_steps * scene.dt,
        "trajectory_interval_s": scene.trajectory_every_steps * scene.dt,
        "neighbour_rebuilds": sim.rebuilds, "arch": arch, "cpu_threads": backend.threads(),
        "load_average": _load_average(), "precision": scene.precision,
        "integrator": scene.integrator, "strain_logged": scene.strain,
        "files": {k: Path(v).name for k, v in files.items()},
        # run.dt_ms as the run used it (0 in a scene file means the integrator's default)
        "scene_values": {**scene.to_dict(), "run": {**scene.raw["run"], "dt_ms": scene.dt * 1e3}},
    }
    if scene.step_control == "error":       # steps taken, scene steps they covered, mean and current multiple
        summary["step_control"] = sim.solver_stats()
    if status in ("interrupted", "failed", "no_space") and checkpoint is not None and Path(checkpoint).is_file():
        summary["files"]["checkpoint"] = Path(checkpoint).name
    if run.broken is not None:
        summary["invariant_broken"] = run.broken
    # each chunk redone at split steps after a broken invariant (run_loop.py), since the start of the run
    summary["rollbacks"] = [{"step": st, "simulated_seconds": t, "split": k} for st, t, k in sim.rollbacks]
    if run.gave_up:
        summary["gave_up"] = True
    return summary
