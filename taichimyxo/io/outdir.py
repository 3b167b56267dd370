"""Output folders and the runs already in them.

Every command's --out is a folder, created if missing and refused in one line when it is a file or cannot be written
(`render --out` also takes a movie path ending in .mp4). A scene's folder is looked at before anything is written:
an unfinished run there (a checkpoint, or a trajectory without a finished summary) continues only with --resume and
is replaced only with --overwrite; a finished run of the same scene is complete (nothing to do), one of other
parameters is replaced only with --overwrite."""
from __future__ import annotations

import json
import os
from pathlib import Path

from ..runtime.status_line import duration
from .schema import SceneError


class OutputError(SceneError):
    """An output folder that is a file or cannot be written; one line for the user."""


RUN_FILES = (("mp4", "mp4"), ("png", "png"), ("gsd", "gsd"), ("json", "json"), ("ckpt", "ckpt.npz"))


def outputs(out: Path, name: str) -> dict:
    """The files a scene's run writes into `out`, by kind."""
    return {k: Path(out) / f"{name}.{ext}" for k, ext in RUN_FILES}


def probe_writable(folder: Path) -> None:
    """Write and remove a file: the only proof that works for every reason a folder can refuse (modes, ACLs, a
    read-only mount)."""
    probe = folder / f".taichimyxo-write-test-{os.getpid()}"
    probe.write_bytes(b"ok")
    probe.unlink()


def check_out_folder(path, flag: str = "--out") -> Path:
    """`path` as an output folder: created if missing; a file, or a folder that cannot be written, is an
    OutputError naming it, before any work starts."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"output folder {path} ({flag}) is a file; give a folder (it is created if missing)")
    try:
        p.mkdir(parents=True, exist_ok=True)
        probe_writable(p)
    except OSError as e:
        raise OutputError(f"output folder {path} ({flag}) cannot be written: {e.strerror or e}") from None
    return p


def refuse_file_as_folder(path, flag: str = "--out") -> None:
    """The part of check_out_folder that creates nothing: for a check made before a refusal could follow."""
    if path is not None and Path(path).exists() and not Path(path).is_dir():
        raise OutputError(f"output folder {path} ({flag}) is a file; give a folder (it is created if missing)")


def read_summary(path: Path) -> dict | None:
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) else None


def _trajectory_frames(path: Path) -> int | None:
    try:
        import gsd.hoomd
        with gsd.hoomd.open(str(path), "r") as t:
            return len(t)
    except Exception:  # noqa: BLE001 - a file cut short by kill -9 is still worth naming
        return None


def _checkpoint_time(path: Path, scene) -> str:
    try:
        import numpy as np
        with np.load(path, allow_pickle=False) as z:
            return f" at {duration(int(z['step']) * scene.dt)} simulated"
    except Exception:  # noqa: BLE001 - an unreadable checkpoint is refused by --resume itself
        return ""


def unfinished_work(files: dict, scene) -> str:
    """What an unfinished run left, in words: 'checkpoint S3.ckpt.npz at 1 min 30 s simulated, trajectory S3.gsd
    of 26 frames'."""
    parts = []
    if files["ckpt"].is_file():
        parts.append(f"checkpoint {files['ckpt'].name}{_checkpoint_time(files['ckpt'], scene)}")
    if files["gsd"].is_file():
        n = _trajectory_frames(files["gsd"])
        parts.append(f"trajectory {files['gsd'].name}" + (f" of {n} frame{'s' * (n != 1)}" if n is not None else ""))
    return ", ".join(parts) or f"summary {files['json'].name} of a run that did not finish"


def plan_run(scene, out_dir, resume: bool = False, overwrite: bool = False) -> str:
    """How a run of `scene` into out_dir starts, decided from what the folder holds, before anything is written:
    "new", "resume" (its checkpoint), "overwrite" (what is there is removed first) or "complete" (a finished run of
    the same scene: nothing to do). Anything else is a SceneError naming the way on (--resume, --overwrite)."""
    if resume and overwrite:
        raise SceneError("--resume and --overwrite: give one (continue the run in the folder, or start it again)")
    refuse_file_as_folder(out_dir)
    out = Path(out_dir)
    files = outputs(out, scene.name)
    summary = read_summary(files["json"])
    ckpt, gsd = files["ckpt"].is_file(), files["gsd"].is_file()
    if overwrite:
        return "overwrite"
    if summary and summary.get("completed") and not ckpt:
        done_s = summary.get("simulated_seconds", scene.hours * 3600)
        if summary.get("fingerprint") == scene.fingerprint() and done_s + scene.dt >= scene.hours * 3600:
            return "complete"
        raise SceneError(f"{out} holds a finished run of {scene.name} with other parameters ({files['json'].name}): "
                         f"--overwrite to replace it, or another --out")
    if summary and summary.get("status") == "failed":
        if resume and ckpt:
            return "resume"
        at = duration(float(summary.get("simulated_seconds", 0.0)))
        raise SceneError(f"{out} holds a run of {scene.name} stopped by a broken invariant at {at} "
                         f"({summary.get('invariant_broken', 'failed')}): --overwrite to start again")
    if ckpt or gsd or summary:
        what = unfinished_work(files, scene)
        if resume and ckpt:
            return "resume"
        if resume:
            raise SceneError(f"--resume: {out} holds {what} but no checkpoint (the run was stopped before its first "
                             f"one, e.g. by kill -9): --overwrite to start again")
        raise SceneError(f"{out} holds an unfinished run of {scene.name} ({what}): --resume to continue it, or "
                         f"--overwrite to start again")
    if resume:
        raise SceneError(f"--resume: no run of {scene.name} in {out} to resume (no checkpoint {files['ckpt'].name})")
    return "new"


def remove_run(files: dict) -> None:
    """Remove what an earlier run of the scene wrote (--overwrite), so nothing of it is mistaken for the new one's."""
    for p in files.values():
        Path(p).unlink(missing_ok=True)


def lock_run(out: Path, name: str):
    """Hold `out`/.NAME.lock for the run of scene NAME (an open file; closing it, or the process ending however it
    ends, releases it): a second run of the same scene into the same folder at the same time is refused (OutputError)
    before it reads or writes anything there. A file system without locks runs unguarded."""
    import fcntl
    f = open(Path(out) / f".{name}.lock", "a")        # noqa: SIM115 - held open for the run's lifetime
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.close()
        raise OutputError(f"{out} is being written by another run of {name} now; wait for it to end, or give "
                          f"another --out") from None
    except OSError:
        pass
    return f
