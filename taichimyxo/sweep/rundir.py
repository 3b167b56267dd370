"""A point's run folder: the files that make it self-contained (taichimyxo/sweep/runner.py lists them all), written
before any run starts, and the state a folder is in. Every file another process reads is replaced atomically."""
from __future__ import annotations

import json
import os
from pathlib import Path

from ..io.scene import to_toml

RESULT = "result.json"
SCENE_FILE = "scene.toml"
POINT_FILE = "point.json"
LOG_FILE = "run.log"
LOCK_FILE = ".lock"
RUNNING_ELSEWHERE = "running elsewhere"     # run_point's status for a folder another process is running


def write_text_atomic(path, text: str) -> None:
    """Write to a temporary file and rename it over `path`: a reader (or an interruption) never sees half."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_json_atomic(path, data) -> None:
    write_text_atomic(path, json.dumps(data, indent=1))


def read_json(path) -> dict | None:
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) else None


def read_result(run_dir) -> dict | None:
    """The run's result.json (None before the run has ended for good)."""
    return read_json(Path(run_dir) / RESULT)


def hold(run_dir, wait_s: float = 5.0):
    """The run folder's lock, held by the process that runs it (an open file; closing it, or the process ending
    however it ends, releases it), or None when another process holds it: two commands never run one folder at once
    (a rerun while the first is still going, a requeued Slurm job). Waits up to wait_s for a moment's holder
    (`state` peeking)."""
    import fcntl
    import time
    f = open(Path(run_dir) / LOCK_FILE, "a")        # noqa: SIM115 - held open for the run's lifetime
    t_end = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return f
        except BlockingIOError:
            if time.monotonic() >= t_end:
                f.close()
                return None
            time.sleep(0.1)
        except OSError:                 # a file system without locks (some network mounts): run unguarded
            return f


def running(run_dir) -> bool:
    """Another process holds the folder's lock: the run is going on now."""
    if not (Path(run_dir) / LOCK_FILE).is_file():
        return False
    f = hold(run_dir, wait_s=0.0)
    if f is None:
        return True
    f.close()
    return False


def state(run_dir) -> str:
    """done (completed), failed (ended for good without completing), running (another process runs it now),
    interrupted (a checkpoint to resume from, or the trajectory of a run killed before its first) or new."""
    d = Path(run_dir)
    r = read_result(d)
    if r and r.get("status") == "completed":
        return "done"
    if r and r.get("status") == "failed":
        return "failed"
    if running(d):
        return "running"
    # a checkpoint, or a trajectory of a run killed before its first checkpoint
    if d.is_dir() and (any(d.glob("*.ckpt.npz")) or any(d.glob("*.gsd"))):
        return "interrupted"
    return "new"


def queue_order(dirs: list, states: dict, sizes: dict | None = None) -> list:
    """The order runs start in: interrupted runs first, so that a rerun finishes (and records) what an earlier
    session started before it begins new runs; within each group the largest `sizes` first (none: as given)."""
    return sorted(dirs, key=lambda d: (states[d] != "interrupted", -(sizes or {}).get(d, 0)))


def prepare_job(scene, run_dir, meta: dict, fresh: bool = False) -> Path:
    """A run folder for `scene`: scene.toml (the resolved scene) and point.json (`meta`: name; optionally out, the
    folder the run writes its files into, relative to run_dir (default: run_dir itself); arch; reuse, render from a
    finished trajectory of the same physics instead of simulating; analysis, {every, plots}, or None for none).
    Each is rewritten only when it differs, so a finished run keeps its files untouched; fresh: forget an earlier
    result (the caller found the run's outputs out of date). Returns the folder."""
    d = Path(run_dir)
    d.mkdir(parents=True, exist_ok=True)
    text = to_toml(scene)
    try:
        same = (d / SCENE_FILE).read_text() == text
    except OSError:
        same = False
    if not same:
        write_text_atomic(d / SCENE_FILE, text)
    if read_json(d / POINT_FILE) != meta:
        write_json_atomic(d / POINT_FILE, meta)
    if fresh:
        (d / RESULT).unlink(missing_ok=True)
    return d


def prepare(point, root, sweep) -> Path:
    """A sweep point's folder (Point.run_dir(root)), analysed as the sweep's [outputs] ask."""
    meta = {"sweep": sweep.name, "sweep_file": str(Path(sweep.path).resolve()), "name": point.name,
            "key": point.key, "overrides": point.overrides, "seed": point.seed,
            "analysis": {"every": sweep.outputs["analysis_every"], "plots": sweep.outputs["analysis_plots"]}}
    return prepare_job(point.scene, point.run_dir(root), meta)
