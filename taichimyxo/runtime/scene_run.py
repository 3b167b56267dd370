"""Running a scene: the writers a scene asks for (taichimyxo.io.writers: movie, trajectory, summary, checkpoint, the
invariant check, a progress line), built from the scene and the command line's options and driven by
taichimyxo.runtime.run_loop.drive; clean interruption (SIGINT/SIGTERM close every file and write a checkpoint),
--resume, and a check of the
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
import sys
import time
from pathlib import Path

from ..io.event_log import EventLog
from ..io.outdir import OutputError, check_out_folder, lock_run, outputs, plan_run, read_summary, remove_run  # noqa: F401
from ..io.scene import Scene, SceneError
from ..io.writers import (
    SUMMARY_VERSION,
    Checkpoint,
    FigurePanel,
    InvariantCheck,
    Movie,
    ProgressLine,
    Summary,
    Trajectory,
    previous_sessions,
    read_checkpoint,
    scene_render_options,
)
from .run_loop import drive
from .status_line import duration
from .triggers import Periodic, WallClock


def check_output_dir(out_dir: str) -> Path:
    """Create the folder if needed and prove it is writable, before any long work starts (taichimyxo.io.outdir)."""
    return check_out_folder(out_dir)


def find_reusable_trajectory(scene: Scene, out: Path, recursive: bool = False) -> tuple[Path, int] | None:
    """A completed trajectory of the same physics, seed and at least the same length in `out` (e.g. S3's for S8;
    recursive: in any folder below it, e.g. a sweep's or the figures' runs): rendering it needs no simulation.
    A scene coloured by strain takes the logged strain, else the strain computed from the positions (render_only);
    the scene's movie frames must fall on the trajectory's frames. Returns (path, every k-th frame to render)."""
    fp = scene.fingerprint()
    movie_s = scene.frame_every_steps * scene.dt
    for js in sorted(out.rglob("*.json") if recursive else out.glob("*.json")):
        try:
            d = json.loads(js.read_text())
        except (OSError, ValueError):
            continue
        if not isinstance(d, dict) or d.get("fingerprint") != fp or not d.get("completed"):
            continue
        if d.get("simulated_seconds", 0) + 1e-9 < scene.hours * 3600 - scene.dt:
            continue
        # summaries older than output.trajectory_interval_min wrote a trajectory frame per movie frame
        traj_s = d.get("trajectory_interval_s") or \
            (d.get("scene_values") or {}).get("output", {}).get("frame_interval_min", 0) * 60.0
        ratio = movie_s / traj_s if traj_s else 0.0
        if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
            continue
        g = js.parent / d.get("files", {}).get("gsd", "")
        if g.is_file() and g.suffix == ".gsd":
            return g, int(round(ratio))
    return None


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


def run_scene(scene: Scene, out_dir: str = "videos", arch: str = "cpu", resume: bool = False,
              progress: bool = True, threads: int | None = None, reuse: bool = True,
              checkpoint_every_s: float = 300.0, stop_after_steps: int | None = None, rollback: bool = True,
              overwrite: bool = False, start_state=None) -> dict:
    """Run `scene`, writing NAME.mp4/.png/.gsd/.json into out_dir. Returns the summary dict.
    start_state: (positions (n_cells, N, 2) µm, engine_direction (n_cells,)) to start from instead of the scene's
    own start (e.g. a benchmark state continued as a run); a resumed run takes its checkpoint's state either way.
    An earlier run in out_dir (taichimyxo.io.outdir.plan_run): an unfinished one continues only with resume and is
    replaced only with overwrite; a finished one of the same scene is returned as it is, with "already_complete".
    stop_after_steps (tests): behave as if interrupted after that many steps.
    rollback: a chunk that breaks an invariant is redone at split steps (taichimyxo/runtime/run_loop.py); a run that
    breaks one at every split, or at once without rollback, returns with status "failed" (files closed, checkpoint
    written). Two runs of one scene into one folder at once: the second is refused (outdir.lock_run)."""
    if (Path(out_dir) / f".{scene.name}.lock").is_file():
        lock_run(Path(out_dir), scene.name).close()      # another run writing there now: refused before all else
    # what the run needs, before anything is placed, allocated or written
    from .resources import check_resources
    start = plan_run(scene, out_dir, resume=resume, overwrite=overwrite)
    if start == "complete":
        return {**read_summary(outputs(Path(out_dir), scene.name)["json"]), "already_complete": True}
    check_resources(scene)
    out = check_output_dir(out_dir)
    lock = lock_run(out, scene.name)
    try:
        return _run_locked(scene, out, start, resume=resume, progress=progress, arch=arch, threads=threads,
                           reuse=reuse, checkpoint_every_s=checkpoint_every_s, stop_after_steps=stop_after_steps,
                           rollback=rollback, start_state=start_state)
    finally:
        Path(lock.name).unlink(missing_ok=True)        # the folder as the run left it, no lock behind
        lock.close()


def _run_locked(scene: Scene, out: Path, start: str, *, resume, progress, arch, threads, reuse, checkpoint_every_s,
                stop_after_steps, rollback, start_state=None) -> dict:
    files = outputs(out, scene.name)
    if start == "overwrite":
        remove_run(files)

    if reuse and not resume and start_state is None:
        found = find_reusable_trajectory(scene, out)
        if found is not None and found[0] != files["gsd"]:
            return render_only(scene, found[0], out, progress=progress, every=found[1])

    ckpt = None
    if resume:
        try:
            ckpt = read_checkpoint(files["ckpt"], scene)
        except ValueError as e:
            raise SceneError(f"--resume: {e}") from None
        done = int(ckpt["step"])
        if done > scene.steps:
            # continuing would mark the run complete at a length it has passed and delete the checkpoint
            raise SceneError(f"--resume: {files['ckpt']} has already simulated {duration(done * scene.dt)} "
                             f"({done} steps), more than run.hours = {scene.hours:g} h asks; give --hours "
                             f"{done * scene.dt / 3600:.6g} or more (the checkpoint is kept)")
        if files["gsd"].is_file():
            from ..io.trajectory import trim_after
            trim_after(str(files["gsd"]), done)     # frames written past the checkpoint are made again

    # place the cells before Taichi starts: a density the start cannot place is bad input (one line, exit 2), and a
    # resumed run takes its state from the checkpoint instead of placing cells it would throw away
    from .simulation import Simulation, init_backend, initial_state
    if ckpt is None:
        start = start_state if start_state is not None else \
            initial_state(scene, progress=_placement_progress(scene) if progress else None)
    used_arch = init_backend(scene, arch, threads)
    t_setup = time.perf_counter()
    if ckpt is None:
        sim = Simulation.from_positions(scene, *start, arch=arch, threads=threads)
    else:
        sim = Simulation.from_checkpoint(scene, ckpt, arch=arch, threads=threads)
    setup_s = time.perf_counter() - t_setup

    attached = scene_writers(scene, files, resumed=ckpt is not None, progress=progress,
                             checkpoint_every_s=checkpoint_every_s, setup_seconds=setup_s, arch=used_arch,
                             before=previous_sessions(files["json"], scene, ckpt) if ckpt is not None else None,
                             started_from="placement" if start_state is None else "given state")
    movie = next((w for w in attached if isinstance(w, Movie)), None)
    if movie is not None and ckpt is not None and files["gsd"].is_file():
        from ..io.trajectory import read_frames
        movie_every, traj_every = scene.frame_every_steps, scene.trajectory_every_steps
        if movie_every % traj_every:
            # a trajectory coarser than the movie lacks some of the frames the movie had before the interruption
            print(f"taichimyxo: the movie up to {duration(sim.time)} is rebuilt from the trajectory's frames "
                  f"(every {duration(traj_every * scene.dt)}): the movie frames between them are gone",
                  file=sys.stderr)
        # the movie so far, re-rendered from the trajectory
        movie.append_frames(fr for fr in read_frames(str(files["gsd"])) if fr.step % movie_every == 0)

    drive(sim, scene.steps - sim.step_count, attached, stop_after_steps=stop_after_steps, rollback=rollback)
    summary = next(w for w in attached if isinstance(w, Summary)).summary
    sim.close()
    return summary


def scene_writers(scene: Scene, files: dict, *, resumed: bool = False, progress: bool = True,
                  checkpoint_every_s: float = 300.0, setup_seconds: float = 0.0, arch: str = "cpu",
                  before: dict | None = None, started_from: str = "placement") -> list:
    """The writers a scene's run attaches (what a user would build): the invariant check at every frame, the
    progress line, the trajectory (every output.trajectory_interval_min) and the movie (every
    output.frame_interval_min), both also at the last step, the checkpoint (every checkpoint_every_s of wall
    clock, on interruption and on a broken invariant), the last-frame panel and the summary. before: a resumed run's
    totals over its earlier sessions (writers.previous_sessions); started_from: what the summary says the run
    started from ("placement" or "given state")."""
    write_movie = scene.movie
    look = scene_render_options(scene)
    attached = [InvariantCheck()]
    if progress:
        attached.append(ProgressLine(scene.name, scene.steps))
    attached.append(Trajectory(files["gsd"], Periodic(steps=scene.trajectory_every_steps), final=True,
                               append=resumed))
    attached.append(EventLog(files["gsd"], append=resumed))    # <run>.events.csv when cells reverse or guide
    if write_movie:
        size = scene.video_size
        attached.append(Movie(files["mp4"], Periodic(steps=scene.frame_every_steps), final=True, size=size,
                              fps=scene.fps, **look))
    attached.append(Checkpoint(files["ckpt"], WallClock(seconds=checkpoint_every_s), before=before))
    if write_movie:
        attached.append(FigurePanel(files["png"], **look))        # the panel `render` writes too
    listed = {k: v for k, v in files.items() if k != "ckpt" and (k in ("gsd", "json") or write_movie)}
    attached.append(Summary(files["json"], files=listed, checkpoint=files["ckpt"], resumed=resumed,
                            setup_seconds=setup_seconds, arch=arch, before=before, started_from=started_from))
    return attached


def render_only(scene: Scene, gsd: Path, out: Path, progress: bool = True, every: int = 1) -> dict:
    """Make NAME.mp4/.png from an existing trajectory (same physics and seed) without simulating."""
    from ..render import render_trajectory
    files = outputs(out, scene.name)
    t0 = time.perf_counter()
    size = scene.video_size
    n = render_trajectory(str(gsd), str(files["mp4"]), color=scene.color, size=size,
                          fps=scene.fps, png_path=str(files["png"]), progress=progress, every=every,
                          title=scene.name, strain_from=(scene.width, scene.k_c))
    summary = {"summary_version": SUMMARY_VERSION, "scene": scene.name, "seed": scene.seed,
               "fingerprint": scene.fingerprint(), "completed": True, "status": "rendered from trajectory",
               "source_trajectory": gsd.name if gsd.parent == out else str(gsd),
               "frames": n, "wall_seconds": time.perf_counter() - t0,
               "files": {"mp4": files["mp4"].name, "png": files["png"].name}}
    files["json"].write_text(json.dumps(summary, indent=1))
    return summary
