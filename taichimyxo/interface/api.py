"""The Python API for notebooks and scripts; every command of the command line is a thin layer over it.

    import taichimyxo as tm
    scene = tm.load_scene("S3", set={"domain.width_um": 30, "domain.height_um": 30}, seed=2)
    sim = tm.Simulation(scene)                                   # the scene's integrator, cells placed
    traj = tm.writers.Trajectory("out/S3.gsd", trigger=tm.Periodic(minutes=1))
    tm.run(sim, minutes=3, writers=[traj])                       # simulated time, writers attached
    frame = sim.frame()                                          # a Frame: numpy arrays
    image = tm.render_frame(frame, color="speed")                # an RGB image, (h, w, 3) uint8

- :func:`load_scene`: a scene by name (as ``list`` shows it) or path, with keys overridden by their dotted names.
- :class:`Simulation` (taichimyxo.runtime.simulation.Simulation): the simulation of the scene's integrator, cells placed
  by the scene's start, Taichi started for the scene's precision; ``Simulation.from_checkpoint`` and
  ``Simulation.from_positions`` start elsewhere. ``sim.advance(steps)`` advances with no writer.
- :func:`run`: ``sim.run(...)``: run for simulated time (or steps) with writers attached (taichimyxo.io.writers,
  triggers in taichimyxo.runtime.triggers); returns the :class:`taichimyxo.runtime.run_loop.Run` (status, steps, wall
time).
- :func:`render_frame`: one Frame to an image; :func:`render_movie`: a trajectory to a movie and a panel.
- :func:`analyze`: what ``python -m taichimyxo analyze`` does (taichimyxo.analysis).
- :func:`claims`: what ``python -m taichimyxo claims`` does: the paper's claims measured on runs, as one table.
- :func:`run_scene`: what ``python -m taichimyxo scene`` does (every output, --resume, the summary).
"""
from __future__ import annotations

import os

from ..io.scene import SCHEMA, Scene, SceneError


class RenderOptionError(ValueError):
    """A colouring option render cannot use (a range for a colouring without one, vmin above vmax, ...)."""


def expect(value, kind, call: str, example: str) -> None:
    """A wrong kind of argument: one sentence naming the call, the argument and a valid value (TypeError)."""
    if not isinstance(value, kind):
        got = type(value).__name__ + (f" {value!r}" if isinstance(value, (str, int, float)) else "")
        raise TypeError(f"{call}: expected {example}; got {got}")


def positive_int(value, call: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{call} = {value!r}: expected a whole number >= 1, e.g. 1")


def load_scene(name_or_path, set: dict | None = None, *, seed: int | None = None, hours: float | None = None,
               preview: bool = False, force: bool = False) -> Scene:
    """The scene `name_or_path` (a name like "S3", or a TOML file), validated.

    set: values by dotted key, {"domain.width_um": 30, "guiding.kind": "active"} (or nested, {"domain": {...}});
    seed, hours: run.seed, run.hours. preview: the small, short version (values given here are never scaled).
    A time step above the integrator's stability limit is refused (SceneError) unless force=True."""
    if set is not None:
        expect(set, dict, "load_scene(set=...)", "a dict of values by dotted key, e.g. {'cell.k_a_N_m': 1e-16}")
    over: dict = {}
    for key, val in (set or {}).items():
        if isinstance(val, dict):
            over.setdefault(key, {}).update(val)
            continue
        sec, _, k = str(key).partition(".")
        if sec not in SCHEMA or k not in SCHEMA[sec]:
            raise SceneError(f"set {key!r}: unknown key; see `python -m taichimyxo keys`")
        over.setdefault(sec, {})[k] = val
    if seed is not None:
        over.setdefault("run", {})["seed"] = seed
    scene = Scene.load(os.fspath(name_or_path), over, preview=preview)
    if hours is not None:           # after --preview, which would cap it
        scene = scene.with_overrides({"run": {"hours": hours}})
    from ..physics.stability import check_step
    check_step(scene, force=force)
    return scene


def run(sim, *, seconds=None, minutes=None, hours=None, steps=None, writers=(), progress: bool = False, **options):
    """sim.run(...): run `sim` for simulated time (seconds, minutes or hours, on the scene's step grid) or `steps`,
    with `writers` attached (taichimyxo.io.writers), closed at the end. progress: show the progress line. options:
    taichimyxo.runtime.run_loop.drive's (catch_signals, chunk_steps, speed_window_s, rollback). Returns the Run (status
    "completed", or "interrupted" after Ctrl-C, or "failed" with Run.broken naming a broken invariant)."""
    from ..runtime.simulation import Simulation
    expect(sim, Simulation, "run(sim, ...)", "a Simulation, e.g. tm.Simulation(tm.load_scene('S3'))")
    return sim.run(seconds=seconds, minutes=minutes, hours=hours, steps=steps, writers=writers, progress=progress,
                   **options)


def render_frame(frame, color: str = "speed", size=(1920, 1080), **options):
    """One Frame as an RGB image, (h, w, 3) uint8 (taichimyxo.render.render_frame: legend, time, scale bar;
    options: fit, vmin, vmax, background, decorations, title, ...)."""
    from ..io.frame import Frame
    expect(frame, Frame, "render_frame(frame)", "a Frame, e.g. sim.frame()")
    colors = SCHEMA["output"]["color"][2]
    if color not in colors:
        raise ValueError(f"render_frame(color={color!r}): expected one of {', '.join(colors)}")
    from ..render import render_frame as render
    return render(frame, size=size, color=color, **options)


def render_movie(trajectory, out=None, *, color: str = "speed", size=(1920, 1080), fps: float = 10.0,
                 every: int = 1, vmin=None, vmax=None, progress: bool = True) -> tuple[str, str, int]:
    """A GSD trajectory to an MP4 movie with a PNG panel of its last frame beside it, without simulating.
    out: a folder (created if missing) or a movie path ending in .mp4; by default the trajectory's folder. In a
    folder the movie is named after the trajectory and the colouring (S3.mp4 for speed, S3.strain.mp4, ...).
    Returns (movie, panel, frames). A file that is not a trajectory of cells, or color="strain" without logged
    strain, is a TrajectoryError; a bad colour range a RenderOptionError; both before anything is written."""
    from ..io.trajectory import check_trajectory
    trajectory = os.fspath(trajectory)
    need = {}
    if color == "strain":
        need["log/bonds/strain_energy_J"] = ("--color strain needs the strain energy logged: use another --color, "
                                             "or rerun the scene with --set output.strain=true")
    check_trajectory(trajectory, need)
    from ..render import make_scale, render_trajectory
    try:
        make_scale(color, vmin=vmin, vmax=vmax)
    except ValueError as e:
        raise RenderOptionError(str(e)) from None
    suffix = "" if color == "speed" else f".{color}"     # each colouring its own file
    from ..io.outdir import check_out_folder
    out = os.fspath(out) if out else None
    if out and out.lower().endswith(".mp4") and not os.path.isdir(out):
        check_out_folder(os.path.dirname(os.path.abspath(out)))
    else:
        folder = check_out_folder(out or os.path.dirname(os.path.abspath(trajectory)))
        out = os.path.join(folder, os.path.splitext(os.path.basename(trajectory))[0] + suffix + ".mp4")
    png = os.path.splitext(out)[0] + ".png"
    n = render_trajectory(trajectory, out, color=color, size=size, fps=fps, every=every, png_path=png, vmin=vmin,
                          vmax=vmax, progress=progress)
    return out, png, n


def analyze(trajectory, out_dir=None, *, every: int = 1, v_b: float | None = None, plots: bool = True,
            measures: bool = False, measure_params: dict | None = None) -> dict:
    """Aggregates, rotation and speed profiles of a GSD trajectory (what ``python -m taichimyxo analyze`` does):
    the summary dict, also written as JSON (and PNG plots) next to the trajectory or into out_dir. A file that is
    not a trajectory of cells is a TrajectoryError before anything is written. measures: also defects, cluster
    sizes, correlations, MSD and reversal events (taichimyxo.analysis.measures; ``analyze --measures``), with
    measure_params overriding its defaults (e.g. dict(smoothing_um=2.0, spacing_um=1.0))."""
    positive_int(every, "analyze(every)")
    from ..io.trajectory import check_trajectory
    check_trajectory(os.fspath(trajectory))
    from ..io.outdir import check_out_folder
    check_out_folder(os.fspath(out_dir) if out_dir else os.path.dirname(os.path.abspath(os.fspath(trajectory))))
    from ..analysis import analyze as analyze_trajectory
    return analyze_trajectory(os.fspath(trajectory), out_dir=out_dir, every=every, v_b=v_b, plots=plots,
                              measures=measures, measure_params=measure_params)


def claims(trajectories, out_dir=None, *, every: int = 1, v_b: float | None = None, plots: bool = True,
           progress=None) -> dict:
    """The paper's claims measured on one or more GSD trajectories (what ``python -m taichimyxo claims`` does), or
    on runs kept as records by ``figures`` (their analysis as made when the run finished): claims.md, claims.csv,
    claims.json and a plot per claim in out_dir (default: the current folder). Returns dict(rows, runs, files);
    each row: claim, measured, paper, status, runs. Every file is checked (a missing file, or one that is neither
    a trajectory of cells nor a record with its analysis, is a TrajectoryError) and the output folder proved
    writable before any analysis; the tables are replaced only by complete ones."""
    positive_int(every, "claims(every)")
    from ..analysis.claim_runs import check_run_file
    from ..io.trajectory import TrajectoryError
    from ..runtime.scene_run import check_output_dir
    if isinstance(trajectories, (str, os.PathLike)):
        trajectories = [trajectories]
    paths = [os.fspath(p) for p in trajectories]
    if not paths:
        raise TrajectoryError("claims needs at least one trajectory")
    seen = {}
    for p in paths:          # one run counted twice would weigh twice in every claim it enters
        if os.path.realpath(p) in seen:
            raise TrajectoryError(f"claims: {p} is given twice (also as {seen[os.path.realpath(p)]}); "
                                  "give each run once")
        seen[os.path.realpath(p)] = p
    for p in paths:
        check_run_file(p, every, v_b)
    check_output_dir(os.fspath(out_dir) if out_dir else ".")
    from ..analysis.claims import claims as measure_claims
    return measure_claims(paths, out_dir=os.fspath(out_dir) if out_dir else None, every=every, v_b=v_b, plots=plots,
                          progress=progress)


def run_scene(scene: Scene, out_dir: str = "videos", **options) -> dict:
    """Everything ``python -m taichimyxo scene`` writes (taichimyxo.runtime.scene_run.run_scene); returns the
    summary."""
    expect(scene, Scene, "run_scene(scene)", "a Scene, e.g. tm.load_scene('S3')")
    from ..runtime.scene_run import run_scene as run_all
    return run_all(scene, out_dir=out_dir, **options)
