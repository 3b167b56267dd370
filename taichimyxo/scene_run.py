"""Running a scene: the simulation loop with writers attached (movie, trajectory, summary), a progress line,
clean interruption (SIGINT/SIGTERM close every file and write a checkpoint), --resume, and a check of the
numerical invariants at every frame (a run that breaks them stops, keeping what it wrote, and says why).

Outputs in the output folder, for scene NAME:
  NAME.mp4        the movie (one frame per output.frame_interval_min of simulated time)
  NAME.png        the last frame as a figure panel
  NAME.gsd        the trajectory (GSD / HOOMD schema, see trajectory.py; one frame per
                  output.trajectory_interval_min, by default the movie's interval)
  NAME.json       the run summary (scene, seed, sizes, steps, wall time, particle-steps/s, arch, precision; after a
                  resume: this session's steps and wall time, and the totals over all sessions)
  NAME.ckpt.npz   a checkpoint, written on interruption, on a broken invariant and every few minutes; removed when
                  the run completes
"""
from __future__ import annotations

import json
import math
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

from .scene import Scene, SceneError

SUMMARY_VERSION = 1


class OutputError(SceneError):
    pass


def check_output_dir(out_dir: str) -> Path:
    """Create the folder if needed and prove it is writable, before any long work starts."""
    p = Path(out_dir)
    try:
        p.mkdir(parents=True, exist_ok=True)
        probe = p / f".taichimyxo-write-test-{os.getpid()}"
        probe.write_bytes(b"ok")
        probe.unlink()
    except OSError as e:
        raise OutputError(f"output folder {out_dir} cannot be written: {e.strerror or e}") from None
    return p


def outputs(out: Path, name: str) -> dict:
    return {k: out / f"{name}.{ext}" for k, ext in
            (("mp4", "mp4"), ("png", "png"), ("gsd", "gsd"), ("json", "json"), ("ckpt", "ckpt.npz"))}


def find_reusable_trajectory(scene: Scene, out: Path) -> tuple[Path, int] | None:
    """A completed trajectory of the same physics, seed and at least the same length in `out` (e.g. S3's for S8):
    rendering it needs no simulation. Strain must have been logged if the scene colours by strain, and the
    scene's movie frames must fall on the trajectory's frames. Returns (path, every k-th frame to render)."""
    fp = scene.fingerprint()
    movie_s = scene.frame_every_steps * scene.dt
    for js in sorted(out.glob("*.json")):
        try:
            d = json.loads(js.read_text())
        except (OSError, ValueError):
            continue
        if not isinstance(d, dict) or d.get("fingerprint") != fp or not d.get("completed"):
            continue
        if d.get("simulated_seconds", 0) + 1e-9 < scene.hours * 3600 - scene.dt:
            continue
        if scene.raw["output"]["color"] == "strain" and not d.get("strain_logged"):
            continue
        # summaries older than output.trajectory_interval_min wrote a trajectory frame per movie frame
        traj_s = d.get("trajectory_interval_s") or \
            (d.get("scene_values") or {}).get("output", {}).get("frame_interval_min", 0) * 60.0
        ratio = movie_s / traj_s if traj_s else 0.0
        if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
            continue
        g = out / d.get("files", {}).get("gsd", "")
        if g.is_file():
            return g, int(round(ratio))
    return None


class _Interrupt:
    """SIGINT/SIGTERM set a flag; the loop finishes its chunk, closes the files and checkpoints."""

    def __init__(self):
        self.signum = None
        self._old = {}

    def __enter__(self):
        for s in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[s] = signal.signal(s, self._handle)
            except ValueError:      # not the main thread
                pass
        return self

    def _handle(self, signum, frame):
        if self.signum is not None:       # a second Ctrl-C: stop now
            raise KeyboardInterrupt
        self.signum = signum

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)


def duration(seconds: float) -> str:
    """A time with its units: '1 h 05 min' from an hour on, '6 min 05 s' from a minute on, else '3.6 s'."""
    if not math.isfinite(seconds):
        return "?"
    if seconds >= 3600 - 30:
        m = int(round(seconds / 60.0))
        return f"{m // 60} h {m % 60:02d} min"
    if seconds >= 60 - 0.5:
        s = int(round(seconds))
        return f"{s // 60} min {s % 60:02d} s"
    return f"{seconds:.1f} s"


class Progress:
    """One status line on stderr: simulated time of the total, one rate (steps per second of wall time in this
    session) and the time left at that rate. On a terminal it is redrawn in place every second; otherwise (a log
    file, a pipe) it is a plain line when the run starts, every 30 s, and at the end, so a log grows by a short line
    per half minute instead of by one endless carriage-return line."""

    def __init__(self, name: str, total_steps: int, dt: float, start_step: int, stream=None,
                 interval_s: float | None = None):
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = interval_s if interval_s is not None else (1.0 if self.tty else 30.0)
        self.name, self.total, self.dt, self.start = name, total_steps, dt, start_step
        self.t0 = time.perf_counter()
        self.last = -math.inf
        self.width = 0

    def line(self, step: int) -> str:
        el = time.perf_counter() - self.t0
        done = step - self.start
        rate = done / el if el > 0 and done > 0 else 0.0
        left = duration((self.total - step) / rate) if rate > 0 else "?"
        pct = 100.0 * step / max(self.total, 1)
        return (f"{self.name}: {duration(step * self.dt)} of {duration(self.total * self.dt)} simulated "
                f"({pct:.0f} %), {rate:.0f} steps/s, {left} left")

    def update(self, step: int, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now - self.last < self.interval:
            return
        self.last = now
        text = self.line(step)
        if self.tty:
            self.stream.write("\r" + text.ljust(self.width))
            self.width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self, step: int) -> None:
        self.update(step, force=True)
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _placement_progress(scene):
    """What the start shows while it places cells: nothing for a start that takes a moment; for a dense or very
    large random start, a line when it begins and a line every 5 s (placed of total, tries), so a long placement
    never looks like a hang."""
    if scene.start != "random" or (scene.area_fraction < 0.3 and scene.n_cells < 100_000):
        return None
    print(f"taichimyxo: placing {scene.n_cells} cells at random (area fraction {scene.area_fraction:.2f}) ...",
          file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    last = [t0]

    def report(placed, n, tries):
        now = time.perf_counter()
        if now - last[0] >= 5.0 or placed == n:
            last[0] = now
            print(f"taichimyxo: placed {placed} of {n} cells ({100.0 * placed / max(n, 1):.0f} %, {tries} tries, "
                  f"{duration(now - t0)})", file=sys.stderr, flush=True)
    return report


class InvariantBroken(RuntimeError):
    """The state broke a numerical invariant: the step is too large for the configuration (or the model blew up)."""


# Checked at every frame (positions and windowed speeds already copied for the frame, so the check is nearly free).
# Looser than the tests' bounds (invariants.Bounds: lengths within 20 %) so a healthy long run is never stopped,
# yet any explicit-Euler blow-up crosses them within a frame or two.
SEGMENT_LENGTH_TOL = 0.5


def check_positions(pos, scene) -> str | None:
    """The first invariant the positions (n_cells, N, 2) break, as a phrase, or None: all finite, every segment
    within 1 +- SEGMENT_LENGTH_TOL of l0."""
    if not np.all(np.isfinite(pos)):
        return "non-finite positions"
    from .invariants import segment_lengths
    ln = segment_lengths(pos) / scene.rest_length
    lo, hi = float(ln.min(initial=1.0)), float(ln.max(initial=1.0))
    if lo < 1 - SEGMENT_LENGTH_TOL or hi > 1 + SEGMENT_LENGTH_TOL:
        return f"segment lengths {lo:.2f}..{hi:.2f} l0 outside 1 +- {SEGMENT_LENGTH_TOL} l0"
    return None


def check_frame(fr, scene, speed_bound_vb: float, check_speed: bool) -> str | None:
    """check_positions, and every windowed particle speed within the physical bound (speed_bound_vb v_b, from
    invariants.Bounds.for_scene). check_speed: the frame's speeds were averaged over the full speed window."""
    broken = check_positions(fr.positions, scene)
    if broken is not None:
        return broken
    if check_speed:
        v_b = scene.raw["cell"]["speed_um_per_min"]
        sp = np.asarray(fr.particle_speed, np.float64)
        top = float(sp.max(initial=0.0)) / v_b if np.all(np.isfinite(sp)) else math.inf
        if top > speed_bound_vb:
            return f"particle speed {top:.3g} v_b above the physical bound {speed_bound_vb:.3g} v_b"
    return None


def _previous_sessions(path: Path, scene: Scene) -> dict:
    """Totals of the earlier sessions of this run (from the summary an interrupted session wrote)."""
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(d, dict) or d.get("fingerprint") != scene.fingerprint() or d.get("completed"):
        return {}
    return {"wall_seconds_total": float(d.get("wall_seconds_total", d.get("wall_seconds", 0.0))),
            "sessions": int(d.get("sessions", 1))}


def run_scene(scene: Scene, out_dir: str = "videos", arch: str = "cpu", resume: bool = False,
              progress: bool = True, threads: int | None = None, reuse: bool = True,
              checkpoint_every_s: float = 300.0, stop_after_steps: int | None = None) -> dict:
    """Run `scene`, writing NAME.mp4/.png/.gsd/.json into out_dir. Returns the summary dict.
    stop_after_steps (tests): behave as if interrupted after that many steps.
    A run that breaks an invariant returns with status "failed" (files closed, checkpoint written)."""
    # what the run needs, before anything is placed, allocated or written
    from .resources import check_resources
    check_resources(scene)
    out = check_output_dir(out_dir)
    name = scene.name
    files = outputs(out, name)
    write_movie = scene.raw["output"]["movie"]
    color = scene.raw["output"]["color"]

    if reuse and not resume:
        found = find_reusable_trajectory(scene, out)
        if found is not None and found[0] != files["gsd"]:
            return render_only(scene, found[0], out, progress=progress, every=found[1])

    ckpt = None
    if resume:
        if not files["ckpt"].is_file():
            raise SceneError(f"--resume: no checkpoint {files['ckpt']} to resume from")
        ckpt = dict(np.load(files["ckpt"], allow_pickle=False))
        if str(ckpt.get("fingerprint")) != scene.fingerprint():
            raise SceneError(f"--resume: {files['ckpt']} was written for different scene parameters")
        done = int(ckpt["step"])
        if done > scene.steps:
            # continuing would mark the run complete at a length it has passed and delete the checkpoint
            raise SceneError(f"--resume: {files['ckpt']} has already simulated {duration(done * scene.dt)} "
                             f"({done} steps), more than run.hours = {scene.hours:g} h asks; give --hours "
                             f"{done * scene.dt / 3600:.6g} or more (the checkpoint is kept)")

    # place the cells before Taichi starts: a density the start cannot place is bad input (one line, exit 2), and a
    # resumed run takes its state from the checkpoint instead of placing cells it would throw away
    if ckpt is not None:
        positions, engine_direction = ckpt["x"], ckpt["ke"]
    else:
        from .init import PlacementError, initial_configuration
        try:
            positions, engine_direction = initial_configuration(
                scene, progress=_placement_progress(scene) if progress else None)
        except PlacementError as e:
            raise SceneError(f"population: the {scene.start!r} start cannot place the cells ({e}); lower "
                             f"population.density_cells_per_cm2 or population.cells, or enlarge the domain"
                             f"{scene.preview_note()}") from None

    from . import backend
    used_arch = backend.init(arch, threads, default_fp="f64" if scene.precision == "f64" else None)
    from .sim import NeighbourOverflow, make_simulation
    from .trajectory import TrajectoryWriter

    t_setup = time.perf_counter()
    sim = make_simulation(scene, positions=positions, engine_direction=engine_direction)
    if ckpt is not None:
        sim.load_checkpoint(ckpt)
    setup_s = time.perf_counter() - t_setup

    total = scene.steps
    # events: a movie frame every movie_every steps, a trajectory frame every traj_every; the loop stops at every
    # multiple of their greatest common divisor and writes what falls due there (both, always, at the end)
    movie_every = scene.frame_every_steps
    traj_every = scene.trajectory_every_steps
    every = math.gcd(movie_every, traj_every) if write_movie else traj_every
    window = max(1, min(every, int(round(scene.raw["run"]["speed_window_s"] / scene.dt))))
    scene_dict = scene.to_dict()
    scene_dict["_fingerprint"] = scene.fingerprint()
    traj = TrajectoryWriter(str(files["gsd"]), scene_dict, mode="a" if ckpt is not None else "w")
    video = None
    size = (scene.raw["output"]["video_width"], scene.raw["output"]["video_height"])
    if write_movie:
        from .render import VideoWriter
        video = VideoWriter(str(files["mp4"]), size=size, fps=scene.raw["output"]["fps"], color=color,
                            title=name, free_speed=scene.raw["cell"]["speed_um_per_min"], **scene.color_range)
        if ckpt is not None and files["gsd"].is_file():
            from .trajectory import read_frames
            if movie_every % traj_every:
                # a trajectory coarser than the movie lacks some of the frames the movie had before the interruption
                print(f"taichimyxo: the movie up to {duration(sim.time)} is rebuilt from the trajectory's frames "
                      f"(every {duration(traj_every * scene.dt)}): the movie frames between them are gone",
                      file=sys.stderr)
            for fr in read_frames(str(files["gsd"])):     # the movie so far, re-rendered from the trajectory
                if fr.step % movie_every == 0:
                    video.append(fr)

    from .invariants import Bounds
    speed_bound = Bounds.for_scene(scene).speed_factor
    # speeds are compared with the bound only when averaged over the full speed window (shorter windows, when
    # frames are closer together than it, carry step-scale jitter the bound does not describe)
    full_window = window * scene.dt >= scene.raw["run"]["speed_window_s"] - 0.5 * scene.dt

    def emit():
        fr = sim.frame()
        fr.meta["scene"] = name
        broken = check_frame(fr, scene, speed_bound, full_window and fr.step > 0)
        if broken is not None:
            raise InvariantBroken(broken)
        final = fr.step == total
        if fr.step % traj_every == 0 or final:
            traj.append(fr)
        if video is not None and (fr.step % movie_every == 0 or final):
            video.append(fr)
        return fr

    wall0 = time.perf_counter()
    start_step = sim.step_count
    steps_done_here = 0
    last_frame = None
    last_ckpt = time.perf_counter()
    status = "completed"
    broken = None
    bar = None
    try:
        with _Interrupt() as intr:
            # the progress line appears once signals are caught: from then on Ctrl-C always ends in a checkpoint
            if progress:
                bar = Progress(name, total, scene.dt, sim.step_count)
                bar.update(sim.step_count, force=True)
            if sim.step_count == 0:
                last_frame = emit()
            while sim.step_count < total:
                # advance to the next event: window start, frame, or end. The window opens `window` steps before
                # each frame; when frames are closer together than the window, it opens at the previous frame, so
                # the displayed speed is always a displacement over a window that ended at the frame (docs/model.md)
                nxt_frame = min(total, (sim.step_count // every + 1) * every)
                win_start = max(nxt_frame - window, (nxt_frame - 1) // every * every)
                if sim.step_count == win_start:
                    sim.snapshot_speed()
                target = win_start if sim.step_count < win_start else nxt_frame
                chunk = min(target - sim.step_count, 2000)
                if stop_after_steps is not None:
                    chunk = min(chunk, max(0, stop_after_steps - steps_done_here))
                sim.run(chunk)
                steps_done_here += chunk
                if sim.step_count == nxt_frame:
                    last_frame = emit()
                else:
                    # between frames too (at most 2000 steps apart): a blow-up is stopped before NaNs reach the
                    # neighbour list, however far apart the frames are
                    broken = check_positions(sim.positions(), scene)
                    if broken is not None:
                        raise InvariantBroken(broken)
                if bar is not None:
                    bar.update(sim.step_count)
                interrupted = intr.signum is not None or (stop_after_steps is not None and
                                                          steps_done_here >= stop_after_steps)
                if interrupted:
                    status = "interrupted"
                    break
                if time.perf_counter() - last_ckpt > checkpoint_every_s:
                    _write_checkpoint(sim, scene, files["ckpt"])
                    last_ckpt = time.perf_counter()
    except (InvariantBroken, NeighbourOverflow) as e:
        # NeighbourOverflow: more neighbours than the list holds, which a blown-up state produces
        status = "failed"
        broken = str(e)
    finally:
        if bar is not None:
            bar.close(sim.step_count)
        traj.close()
        if video is not None:
            video.close()
    wall = time.perf_counter() - wall0
    if status in ("interrupted", "failed"):
        _write_checkpoint(sim, scene, files["ckpt"])
    else:
        if files["ckpt"].is_file():
            files["ckpt"].unlink()
        if last_frame is None:
            last_frame = sim.frame()
        if write_movie:
            from .render import write_png
            write_png(last_frame, str(files["png"]), color=color, title=name,   # the panel `render` writes too
                      free_speed=scene.raw["cell"]["speed_um_per_min"], **scene.color_range)
    before = _previous_sessions(files["json"], scene) if ckpt is not None else {}
    summary = {
        "summary_version": SUMMARY_VERSION,
        "scene": name, "title": scene.raw["scene"]["title"], "paper_figure": scene.raw["scene"]["paper_figure"],
        "seed": scene.seed, "fingerprint": scene.fingerprint(), "completed": status == "completed",
        "status": status, "cells": scene.n_cells, "particles": sim.n_p, "segments": sim.n_s,
        "box_um": list(scene.box), "dt_s": scene.dt,
        # totals since the start of the run (over every session, when it was interrupted and resumed)
        "steps": sim.step_count, "simulated_seconds": sim.time,
        "wall_seconds_total": before.get("wall_seconds_total", 0.0) + wall,
        "sessions": before.get("sessions", 0) + 1,
        # this session (this process) alone: the rate pairs its steps with its wall time
        "steps_this_session": sim.step_count - start_step,
        "simulated_seconds_this_session": (sim.step_count - start_step) * scene.dt,
        "wall_seconds": wall, "setup_seconds": setup_s,
        "particle_steps_per_second": steps_done_here * sim.n_p / max(wall, 1e-9),
        "frame_interval_s": movie_every * scene.dt, "trajectory_interval_s": traj_every * scene.dt,
        "neighbour_rebuilds": sim.rebuilds, "arch": used_arch, "precision": scene.precision,
        "integrator": scene.integrator, "strain_logged": scene.strain,
        "files": {k: v.name for k, v in files.items() if k != "ckpt" and (k in ("gsd", "json") or write_movie)},
        "scene_values": scene.to_dict(),
    }
    if status in ("interrupted", "failed"):
        summary["files"]["checkpoint"] = files["ckpt"].name
    if broken is not None:
        summary["invariant_broken"] = broken
    files["json"].write_text(json.dumps(summary, indent=1))
    sim.close()
    return summary


def _write_checkpoint(sim, scene, path: Path) -> None:
    st = sim.get_checkpoint()
    st["fingerprint"] = np.array(scene.fingerprint())
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **st)
    os.replace(tmp, path)


def render_only(scene: Scene, gsd: Path, out: Path, progress: bool = True, every: int = 1) -> dict:
    """Make NAME.mp4/.png from an existing trajectory (same physics and seed) without simulating."""
    from .render import render_trajectory
    files = outputs(out, scene.name)
    t0 = time.perf_counter()
    size = (scene.raw["output"]["video_width"], scene.raw["output"]["video_height"])
    n = render_trajectory(str(gsd), str(files["mp4"]), color=scene.raw["output"]["color"], size=size,
                          fps=scene.raw["output"]["fps"], png_path=str(files["png"]), progress=progress, every=every,
                          title=scene.name)
    summary = {"summary_version": SUMMARY_VERSION, "scene": scene.name, "seed": scene.seed,
               "fingerprint": scene.fingerprint(), "completed": True, "status": "rendered from trajectory",
               "source_trajectory": gsd.name, "frames": n, "wall_seconds": time.perf_counter() - t0,
               "files": {"mp4": files["mp4"].name, "png": files["png"].name}}
    files["json"].write_text(json.dumps(summary, indent=1))
    return summary
