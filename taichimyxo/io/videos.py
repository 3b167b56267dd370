"""Regenerate the supplementary videos: `python -m taichimyxo videos [--preview] [--only S3,S8] [--jobs N]
[--executor local|slurm]`.

Runs S1-S17 in order (or the scenes --only names: any that `list` shows), each in its own process (one Simulation
per process: Taichi compiles per instance), skips those whose outputs are up to date (same scene fingerprint,
completed), resumes an interrupted one from its checkpoint, and shows overall progress. Ctrl-C stops after closing
the current run's files; run again to continue.

--scale half|quarter makes the videos on a box with sides scaled by 1/2 or 1/4 (cells with the area), named
NAME-half / NAME-quarter. --from DIR (repeatable) looks through DIR's folders for finished runs of a video's scene
(the same physics and seed, at least as long, frames on the movie's frames: e.g. `figures --scale half`'s runs for
`videos --scale half`) and renders the movie from that run's trajectory instead of simulating it again.

With --jobs N (N > 1) or --executor slurm the videos run in parallel through a sweep executor
(taichimyxo.sweep.orchestrator): each video gets a run folder OUT/.jobs/NAME/ (its resolved scene, its log, its result)
and writes its files into OUT as before; a video that can be rendered from another's trajectory (S8 from S3) waits
for that one. A failed video is reported and the others go on."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from .scene import Scene, SceneError, available_scenes

VIDEO_SCENES = [f"S{i}" for i in range(1, 18)]


def _up_to_date(sc: Scene, out: Path) -> bool:
    js = out / f"{sc.name}.json"
    mp4 = out / f"{sc.name}.mp4"
    if not (js.is_file() and mp4.is_file()):
        return False
    try:
        d = json.loads(js.read_text())
    except ValueError:
        return False
    if d.get("fingerprint") != sc.fingerprint() or not d.get("completed"):
        return False
    if d.get("status") == "rendered from trajectory":
        return True
    return d.get("simulated_seconds", 0.0) + sc.dt >= sc.hours * 3600


def video_scene(name: str, preview: bool = False, scale: str = "paper") -> Scene:
    """The scene of one video: its own, its --preview, or its box scaled (NAME-half, NAME-quarter: the same scene
    as a sweep's or `figures`' run at that scale, so a finished run of it can be rendered instead)."""
    sc = Scene.load(name, {}, preview=preview)
    if scale == "paper":
        return sc
    from ..figures.specs import SCALES  # one set of scales: `figures --scale` sizes its runs' boxes alike
    f = SCALES[scale]
    return Scene.load(name, {**sc.resized(sc.box[0] * f, sc.box[1] * f), "scene": {"name": f"{sc.name}-{scale}"}})


def render_finished(todo: list, out: Path, sources: list[Path]) -> list:
    """Render each video whose scene a finished run in `sources` (searched through, e.g. figures' or a sweep's
    run folders) already simulated; returns the videos still to make."""
    from ..runtime.scene_run import find_reusable_trajectory, render_only
    left = []
    for name, sc in todo:
        found = next((f for f in (find_reusable_trajectory(sc, d, recursive=True) for d in sources) if f), None)
        if found is None:
            left.append((name, sc))
            continue
        print(f"videos: {sc.name} rendered from the finished run {found[0]}", flush=True)
        render_only(sc, found[0], out, every=found[1])
    return left


def regenerate(preview: bool = False, only: str | None = None, out_dir: str = "videos", arch: str = "cpu",
               executor: str = "local", jobs: int = 1, options: dict | None = None, scale: str = "paper",
               sources: list | None = None) -> int:
    """Make the videos (module docstring); executor, jobs, options: in parallel through a sweep executor
    (taichimyxo.sweep.orchestrator) when jobs > 1 or executor is not local, with its options (e.g. Slurm's).
    scale: paper, half or quarter (video_scene); sources: folders whose finished runs are rendered rather than
    simulated again."""
    if preview and scale != "paper":
        raise SceneError(f"videos: --preview and --scale {scale} together; a preview has its own size, keep one")
    sources = [Path(d) for d in (sources or [])]
    for d in sources:
        if not d.is_dir():
            raise SceneError(f"videos --from {d}: no such folder")
    names = VIDEO_SCENES
    if only:
        # any scene `list` shows (the supplementary videos S1-S17 and the figure panels such as S2FigA)
        known = available_scenes()
        names = [n.strip() for n in only.split(",") if n.strip()]
        unknown = [n for n in names if n not in known]
        if unknown or not names:
            raise SceneError(f"--only: unknown scene {', '.join(unknown) or repr(only)}; available: "
                             f"{', '.join(known)}")
    ex = None
    if executor != "local" or jobs > 1:
        from ..sweep.orchestrator import executor_module
        # a missing executor or a bad option is bad input, refused before anything is written
        ex = executor_module(executor)
        opts = ex.check_options(options or {}) if hasattr(ex, "check_options") else dict(options or {})
        jobs = jobs or getattr(ex, "DEFAULT_JOBS", None) or os.cpu_count() or 1    # 0: the executor's default
    from ..runtime.scene_run import check_output_dir
    out = check_output_dir(out_dir)
    scenes = [(n, video_scene(n, preview, scale)) for n in names]      # validate all before running any
    todo = [(n, sc) for n, sc in scenes if not _up_to_date(sc, out)]
    print(f"videos: {len(scenes) - len(todo)} of {len(scenes)} up to date in {out}; {len(todo)} to make",
          flush=True)
    t0 = time.time()
    if sources:
        todo = render_finished(todo, out, sources)
    if ex is None and scale != "paper" and todo:
        # a scaled scene runs from its resolved scene file, as the executor writes one
        from ..sweep.orchestrator import executor_module
        ex, opts = executor_module("local"), {}
    if ex is not None:
        return in_parallel([sc for _, sc in todo], out, arch, ex, jobs, opts)
    for i, (name, sc) in enumerate(todo, 1):
        cmd = [sys.executable, "-m", "taichimyxo", "scene", name, "--out", str(out), "--arch", arch]
        if preview:
            cmd.append("--preview")
        # as `videos` always did: continue from a checkpoint, else make the video again
        cmd.append("--resume" if (out / f"{sc.name}.ckpt.npz").is_file() else "--overwrite")
        print(f"[{i}/{len(todo)}] {sc.name}: {sc.title} "
              f"(elapsed {time.time() - t0:.0f} s)", flush=True)
        try:
            rc = subprocess.call(cmd)
        except KeyboardInterrupt:
            rc = 130
        if rc != 0:
            print(f"videos: {sc.name} stopped (exit {rc}); run the same command again to continue", file=sys.stderr)
            return rc
    print(f"videos: done in {time.time() - t0:.0f} s", flush=True)
    return 0


def in_parallel(scenes: list, out: Path, arch: str, ex, jobs: int, opts: dict) -> int:
    """The videos through the executor module `ex` (taichimyxo.sweep.orchestrator), `jobs` at a time; those that can
    reuse an earlier one's trajectory (the same physics and seed: S8 and S3) in a second wave. Exit status: 0, 1 when a
    video failed, 130 when interrupted."""
    from ..sweep.progress import SweepProgress
    from ..sweep.rundir import prepare_job
    first, second, seen = [], [], set()
    for sc in scenes:
        (second if sc.fingerprint() in seen else first).append(sc)
        seen.add(sc.fingerprint())
    progress = SweepProgress("videos", total=len(scenes), skipped=0, jobs=jobs)
    results: dict = {}
    try:
        for wave in (first, second):
            dirs = [str(prepare_job(sc, out / ".jobs" / sc.name, {"name": sc.name, "out": "../..", "arch": arch,
                                                                  "reuse": True, "analysis": None}, fresh=True))
                    for sc in wave]
            if dirs:
                results.update(ex.execute(dirs, jobs, opts, progress))
            if any(r.get("status") in ("interrupted", "not started") for r in results.values()):
                break
    finally:
        progress.close()
    failed = [r for r in results.values() if r.get("status") == "failed"]
    for r in failed:
        print(f"videos: {r['name']} failed: {r.get('error')} (log: {Path(r['run_dir']) / 'run.log'})",
              file=sys.stderr)
    if any(r.get("status") in ("interrupted", "not started") for r in results.values()) or \
            len(results) < len(scenes):
        print("videos: interrupted; run the same command again to continue", file=sys.stderr)
        return 130
    return 1 if failed else 0
