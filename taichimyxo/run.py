"""Running a scene: the simulation loop with writers attached (movie, trajectory, summary), a progress bar,
clean interruption (SIGINT/SIGTERM close every file and write a checkpoint) and --resume.

Outputs in the output folder, for scene NAME:
  NAME.mp4        the movie (one frame per output.frame_interval_min of simulated time)
  NAME.png        the last frame as a figure panel
  NAME.gsd        the trajectory (GSD / HOOMD schema, see trajectory.py)
  NAME.json       the run summary (scene, seed, sizes, steps, wall time, particle-steps/s, arch, precision)
  NAME.ckpt.npz   a checkpoint, written on interruption and every few minutes; removed when the run completes
"""
from __future__ import annotations

import json
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


def find_reusable_trajectory(scene: Scene, out: Path) -> Path | None:
    """A completed trajectory of the same physics, seed and at least the same length in `out` (e.g. S3's for S8):
    rendering it needs no simulation. Strain must have been logged if the scene colours by strain."""
    fp = scene.fingerprint()
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
        g = out / d.get("files", {}).get("gsd", "")
        if g.is_file():
            return g
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


def _progress(total, initial, desc, enabled):
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=total, initial=initial, desc=desc, unit="step", unit_scale=True, dynamic_ncols=True,
                mininterval=1.0 if sys.stderr.isatty() else 30.0, file=sys.stderr, smoothing=0.1)


def _hm(seconds: float) -> str:
    m = int(round(seconds / 60.0))
    return f"{m // 60}:{m % 60:02d}"


def run_scene(scene: Scene, out_dir: str = "videos", arch: str = "cpu", resume: bool = False,
              progress: bool = True, threads: int | None = None, reuse: bool = True,
              checkpoint_every_s: float = 300.0, stop_after_steps: int | None = None) -> dict:
    """Run `scene`, writing NAME.mp4/.png/.gsd/.json into out_dir. Returns the summary dict.
    stop_after_steps (tests): behave as if interrupted after that many steps."""
    out = check_output_dir(out_dir)
    name = scene.name
    files = outputs(out, name)
    write_movie = scene.raw["output"]["movie"]
    color = scene.raw["output"]["color"]

    if reuse and not resume:
        src = find_reusable_trajectory(scene, out)
        if src is not None and src != files["gsd"]:
            return render_only(scene, src, out, progress=progress)

    ckpt = None
    if resume:
        if not files["ckpt"].is_file():
            raise SceneError(f"--resume: no checkpoint {files['ckpt']} to resume from")
        ckpt = dict(np.load(files["ckpt"], allow_pickle=False))
        if str(ckpt.get("fingerprint")) != scene.fingerprint():
            raise SceneError(f"--resume: {files['ckpt']} was written for different scene parameters")

    # place the cells before Taichi starts: a density the start cannot place is bad input (one line, exit 2), and a
    # resumed run takes its state from the checkpoint instead of placing cells it would throw away
    if ckpt is not None:
        positions, engine_direction = ckpt["x"], ckpt["ke"]
    else:
        from .init import PlacementError, initial_configuration
        try:
            positions, engine_direction = initial_configuration(scene)
        except PlacementError as e:
            raise SceneError(f"population: the {scene.start!r} start cannot place the cells ({e}); lower "
                             f"population.density_cells_per_cm2 or population.cells, or enlarge the domain") from None

    from . import backend
    used_arch = backend.init(arch, threads, default_fp="f64" if scene.precision == "f64" else None)
    from .sim import make_simulation
    from .trajectory import TrajectoryWriter

    t_setup = time.perf_counter()
    sim = make_simulation(scene, positions=positions, engine_direction=engine_direction)
    if ckpt is not None:
        sim.load_checkpoint(ckpt)
    setup_s = time.perf_counter() - t_setup

    total = scene.steps
    every = scene.frame_every_steps
    window = max(1, min(every, int(round(scene.raw["run"]["speed_window_s"] / scene.dt))))
    scene_dict = scene.to_dict()
    scene_dict["_fingerprint"] = scene.fingerprint()
    traj = TrajectoryWriter(str(files["gsd"]), scene_dict, mode="a" if ckpt is not None else "w")
    video = None
    size = (scene.raw["output"]["video_width"], scene.raw["output"]["video_height"])
    if write_movie:
        from .render import VideoWriter
        video = VideoWriter(str(files["mp4"]), size=size, fps=scene.raw["output"]["fps"], color=color,
                            title=name)
        if ckpt is not None and files["gsd"].is_file():
            from .trajectory import read_frames
            for fr in read_frames(str(files["gsd"])):     # the movie so far, re-rendered from the trajectory
                video.append(fr)

    def emit():
        fr = sim.frame()
        fr.meta["scene"] = name
        traj.append(fr)
        if video is not None:
            video.append(fr)
        return fr

    wall0 = time.perf_counter()
    steps_done_here = 0
    last_frame = None
    last_ckpt = time.perf_counter()
    status = "completed"
    bar = None
    try:
        with _Interrupt() as intr:
            # the bar appears once signals are caught: from then on Ctrl-C always ends in a checkpoint
            bar = _progress(total, sim.step_count, name, progress)
            if sim.step_count == 0:
                last_frame = emit()
            while sim.step_count < total:
                # advance to the next event: window start, frame, or end
                nxt_frame = min(total, (sim.step_count // every + 1) * every)
                win_start = nxt_frame - window
                target = win_start if sim.step_count < win_start else nxt_frame
                chunk = min(target - sim.step_count, 2000)
                if stop_after_steps is not None:
                    chunk = min(chunk, max(0, stop_after_steps - steps_done_here))
                sim.run(chunk)
                steps_done_here += chunk
                if sim.step_count == win_start and win_start != nxt_frame:
                    sim.snapshot_speed()
                if sim.step_count == nxt_frame:
                    last_frame = emit()
                if bar is not None:
                    bar.update(chunk)
                    el = time.perf_counter() - wall0
                    bar.set_postfix_str(f"t={_hm(sim.time)} h:mm, {steps_done_here / max(el, 1e-9):.0f} steps/s")
                interrupted = intr.signum is not None or (stop_after_steps is not None and
                                                          steps_done_here >= stop_after_steps)
                if interrupted:
                    status = "interrupted"
                    break
                if time.perf_counter() - last_ckpt > checkpoint_every_s:
                    _write_checkpoint(sim, scene, files["ckpt"])
                    last_ckpt = time.perf_counter()
    finally:
        if bar is not None:
            bar.close()
        traj.close()
        if video is not None:
            video.close()
    wall = time.perf_counter() - wall0
    if status == "interrupted":
        _write_checkpoint(sim, scene, files["ckpt"])
    else:
        if files["ckpt"].is_file():
            files["ckpt"].unlink()
        if last_frame is None:
            last_frame = sim.frame()
        if write_movie:
            from .render import write_png
            write_png(last_frame, str(files["png"]), color=color, size=size)
    summary = {
        "summary_version": SUMMARY_VERSION,
        "scene": name, "title": scene.raw["scene"]["title"], "paper_figure": scene.raw["scene"]["paper_figure"],
        "seed": scene.seed, "fingerprint": scene.fingerprint(), "completed": status == "completed",
        "status": status, "cells": scene.n_cells, "particles": sim.n_p, "segments": sim.n_s,
        "box_um": list(scene.box), "steps": sim.step_count, "dt_s": scene.dt,
        "simulated_seconds": sim.time, "wall_seconds": wall, "setup_seconds": setup_s,
        "particle_steps_per_second": steps_done_here * sim.n_p / max(wall, 1e-9),
        "neighbour_rebuilds": sim.rebuilds, "arch": used_arch, "precision": scene.precision,
        "integrator": scene.integrator, "strain_logged": scene.strain,
        "files": {k: v.name for k, v in files.items() if k != "ckpt" and (k in ("gsd", "json") or write_movie)},
        "scene_values": scene.to_dict(),
    }
    if status == "interrupted":
        summary["files"]["checkpoint"] = files["ckpt"].name
    files["json"].write_text(json.dumps(summary, indent=1))
    sim.close()
    return summary


def _write_checkpoint(sim, scene, path: Path) -> None:
    st = sim.get_checkpoint()
    st["fingerprint"] = np.array(scene.fingerprint())
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **st)
    os.replace(tmp, path)


def render_only(scene: Scene, gsd: Path, out: Path, progress: bool = True) -> dict:
    """Make NAME.mp4/.png from an existing trajectory (same physics and seed) without simulating."""
    from .render import render_trajectory
    files = outputs(out, scene.name)
    t0 = time.perf_counter()
    size = (scene.raw["output"]["video_width"], scene.raw["output"]["video_height"])
    n = render_trajectory(str(gsd), str(files["mp4"]), color=scene.raw["output"]["color"], size=size,
                          fps=scene.raw["output"]["fps"], png_path=str(files["png"]), progress=progress,
                          title=scene.name)
    summary = {"summary_version": SUMMARY_VERSION, "scene": scene.name, "seed": scene.seed,
               "fingerprint": scene.fingerprint(), "completed": True, "status": "rendered from trajectory",
               "source_trajectory": gsd.name, "frames": n, "wall_seconds": time.perf_counter() - t0,
               "files": {"mp4": files["mp4"].name, "png": files["png"].name}}
    files["json"].write_text(json.dumps(summary, indent=1))
    return summary
