"""One point of a sweep, run from its folder alone: what every executor runs, in a process of its own (Taichi
compiles per Simulation, and one Simulation per process keeps runs apart).

A run folder is self-contained, so a process on another machine or a Slurm node given only its path can run it:

  scene.toml          the resolved scene (every key; `python -m taichimyxo scene scene.toml` runs it too)
  point.json          the sweep, the point's name, key, swept values and seed, and what to analyse (`analysis`:
                      {every, plots}, or null for none; `videos` also sets `out`, the folder the files go to,
                      relative to the run folder, `arch` and `reuse`, rendering from a finished trajectory of the
                      same physics; taichimyxo.sweep.rundir.prepare_job)
  NAME.gsd            the trajectory (always), NAME.json the run summary, NAME.mp4/.png when the sweep asks
  NAME.analysis.json  the analysis of the trajectory (taichimyxo.analysis), with its plots when the sweep asks
  NAME.ckpt.npz       the checkpoint while the run is unfinished (every few minutes, on SIGINT/SIGTERM)
  result.json         written last, atomically, when the run ended for good (completed or failed): status,
                      simulated and wall time, the outcomes (taichimyxo.sweep.collect.outcomes), the error
  run.log             what the run printed (the local executor's workers)
  .lock               locked by the process running the point, so no two run one folder at once

`run_point(run_dir)` skips a completed run, resumes from the checkpoint when there is one, analyses a run whose
simulation completed but whose analysis did not, and returns a small dict. `python -m taichimyxo.sweep RUN_DIR
[--threads N]` does the same from the command line (exit 0 completed or skipped, 1 failed, 130 interrupted, 75 the
folder is being run by another process)."""
from __future__ import annotations

import json
import sys
import time
import traceback
from pathlib import Path

from .collect import outcomes
from .rundir import POINT_FILE, RESULT, RUNNING_ELSEWHERE, SCENE_FILE, hold, read_json, read_result, write_json_atomic


def run_point(run_dir: str, threads: int = 1) -> dict:
    """Run the point stored in run_dir (scene.toml, point.json), on `threads` CPU threads. Returns a small dict:
    status (completed, skipped: completed before, interrupted: a checkpoint is written, failed), name, run_dir,
    simulated_seconds, wall_seconds (the simulation's, over every session), outcomes, error (a failed run). Never
    raises for a failing run: a failure is recorded in result.json and returned."""
    run_dir = Path(run_dir)
    t0 = time.perf_counter()
    point = read_json(run_dir / POINT_FILE) or {}
    # started_at / ended_at (Unix time, this process): when the run held its worker, for how runs overlapped
    base = {"name": point.get("name", run_dir.name), "key": point.get("key"), "run_dir": str(run_dir.resolve()),
            "started_at": time.time()}
    done = read_result(run_dir)
    if done and done.get("status") == "completed":
        return {**done, "status": "skipped"}
    lock = hold(run_dir)
    if lock is None:
        return {**base, "status": RUNNING_ELSEWHERE, "error": None}
    try:
        return _run(run_dir, point, base, threads, t0)
    except KeyboardInterrupt:
        return {**base, "status": "interrupted", "error": None}
    except Exception as e:                      # a failing run is reported, never takes the sweep down
        msg = str(e).splitlines()[0] if str(e) else ""
        err = f"{type(e).__name__}: {msg}" if not isinstance(e, ValueError) or not msg else msg
        res = {**base, "status": "failed", "error": err, "traceback": traceback.format_exc(limit=8),
               "process_seconds": time.perf_counter() - t0, "ended_at": time.time()}
        write_json_atomic(run_dir / RESULT, res)
        return res
    finally:
        lock.close()


def _run(run_dir: Path, point: dict, base: dict, threads: int, t0: float) -> dict:
    from ..io.scene import Scene
    from ..runtime.scene_run import run_scene
    scene = Scene.load(str(run_dir / SCENE_FILE))
    # where the run writes its files: its own folder, or (`videos`) the shared folder point.json names, relative
    out = (run_dir / point.get("out", ".")).resolve()
    gsd = out / f"{scene.name}.gsd"
    summary = read_json(out / f"{scene.name}.json")
    simulated = bool(summary) and summary.get("completed") and summary.get("fingerprint") == scene.fingerprint() \
        and summary.get("simulated_seconds", 0.0) + scene.dt >= scene.hours * 3600 and gsd.is_file()
    if not simulated:
        resume = (out / f"{scene.name}.ckpt.npz").is_file()
        # the sweep (or `videos`) decided before handing the point over: continue from a checkpoint, else start again
        summary = run_scene(scene, out_dir=str(out), arch=point.get("arch", "cpu"), resume=resume, progress=True,
                            threads=threads, reuse=bool(point.get("reuse", False)), overwrite=not resume)
    status = "completed" if summary.get("completed") else summary["status"]
    res = {**base, "seed": scene.seed, "overrides": point.get("overrides", {}), "status": status,
           "steps": summary.get("steps"), "cells": summary.get("cells"),
           "simulated_seconds": summary.get("simulated_seconds"),
           "wall_seconds": summary.get("wall_seconds_total", summary.get("wall_seconds")),
           "sessions": summary.get("sessions", 1), "error": None}
    if status == "interrupted":
        return res                              # the checkpoint is on disk; the next run resumes it
    if status == "failed":
        res["error"] = f"stopped at step {summary['steps']}: {summary.get('invariant_broken', 'failed')}"
    elif point.get("analysis") is not None:
        from ..interface.api import analyze
        t_an = time.perf_counter()
        analysis = analyze(str(gsd), out_dir=str(out), every=int(point["analysis"].get("every", 1)),
                           plots=bool(point["analysis"].get("plots", False)))
        res.update(analysis_seconds=time.perf_counter() - t_an, analysis=Path(analysis["json"]).name,
                   outcomes=outcomes(analysis))
    res.update(process_seconds=time.perf_counter() - t0, ended_at=time.time())
    write_json_atomic(run_dir / RESULT, res)
    return res


EXIT = {"completed": 0, "skipped": 0, "failed": 1, "interrupted": 130, RUNNING_ELSEWHERE: 75}


def main(argv=None) -> int:
    """`python -m taichimyxo.sweep RUN_DIR [--threads N]`: run one point's folder; the result as JSON on stdout."""
    import argparse
    p = argparse.ArgumentParser(prog="python -m taichimyxo.sweep",
                                description="run one point of a sweep from its folder (what each worker does)")
    p.add_argument("run_dir")
    p.add_argument("--threads", type=int, default=1, help="CPU threads of this run (default 1)")
    a = p.parse_args(argv)
    if not (Path(a.run_dir) / SCENE_FILE).is_file():
        print(f"taichimyxo: error: {a.run_dir}: no {SCENE_FILE}; not a sweep's run folder", file=sys.stderr)
        return 2
    res = run_point(a.run_dir, threads=a.threads)
    if res.get("status") == "failed":
        print(f"taichimyxo: error: {res['name']}: {res['error']}", file=sys.stderr)
    print(json.dumps({k: v for k, v in res.items() if k != "traceback"}), flush=True)
    return EXIT.get(res.get("status"), 1)
