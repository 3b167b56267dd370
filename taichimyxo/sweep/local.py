"""The local executor: the sweep's runs on this machine, `jobs` at a time, each in a process of its own
(`python -m taichimyxo.sweep RUN_DIR --threads 1`, taichimyxo.sweep.runner) with one Taichi thread, its output in
the run's run.log.

A run that fails is reported with its error (its result.json, or the last line it printed when the process died)
and the others go on. Ctrl-C (or SIGTERM) is passed on to every running run once: each closes its trajectory, writes
its checkpoint and exits, and the next sweep of the same file resumes it; a finished run's files were written
before (result.json last, atomically), so nothing finished is lost. Runs get their own process group, so the
terminal's Ctrl-C reaches them only through this forwarding, once (a second one stops them at once).

Options (the sweep file's [local] table, or run_sweep's options): threads, the CPU threads of each run (default 1)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from .rundir import LOG_FILE, POINT_FILE, RUNNING_ELSEWHERE, read_json, read_result
from .runner import EXIT
from .spec import SweepError

OPTIONS = {"threads": 1}
EXIT_INTERRUPTED = 130


def check_options(options: dict) -> dict:
    """The options with their defaults; an unknown or bad one is a SweepError."""
    out = dict(OPTIONS)
    for k, v in options.items():
        if k not in OPTIONS:
            raise SweepError(f"[local] {k}: unknown option; allowed: {', '.join(OPTIONS)}")
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise SweepError(f"[local] {k} = {v!r}: expected an integer >= 1")
        out[k] = v
    return out


def _last_line(log: Path) -> str:
    try:
        lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1] if lines else ""


def outcome(run_dir: str, rc: int, launched_at: float) -> dict:
    """What a finished worker left: the result.json it wrote when its run ended for good (whatever its exit status:
    a Ctrl-C can reach it after the result is written); otherwise interrupted (exit 130: the checkpoint is written)
    or failed with the last line it printed (a crash, a kill)."""
    name = (read_json(Path(run_dir) / POINT_FILE) or {}).get("name", Path(run_dir).name)
    r = read_result(run_dir)
    if r and r.get("started_at", 0.0) >= launched_at - 1.0:          # this worker's, not an earlier session's
        return r
    if rc in (EXIT_INTERRUPTED, -signal.SIGINT, -signal.SIGTERM):
        return {"name": name, "run_dir": run_dir, "status": "interrupted", "error": None}
    if rc == EXIT[RUNNING_ELSEWHERE]:
        return {"name": name, "run_dir": run_dir, "status": RUNNING_ELSEWHERE, "error": None}
    why = _last_line(Path(run_dir) / LOG_FILE) or "no output"
    how = f"killed by signal {-rc}" if rc < 0 else f"exit {rc}"
    return {"name": name, "run_dir": run_dir, "status": "failed", "error": f"{how}: {why}"}


def execute(run_dirs: list[str], jobs: int, options: dict, progress) -> dict[str, dict]:
    """Run each folder's point (taichimyxo.sweep.runner), `jobs` at a time. Returns run_dir -> result (status
    completed, failed, interrupted, or "not started" when the sweep was interrupted before its turn)."""
    opts = check_options(options)
    queue = list(run_dirs)
    running: dict[str, tuple] = {}
    launched: dict[str, float] = {}
    results: dict[str, dict] = {}
    try:                                    # SIGTERM (a batch system, `kill`) stops the sweep as Ctrl-C does
        old_term = signal.signal(signal.SIGTERM, _raise_interrupt)
    except ValueError:                      # not the main thread: leave signals alone
        old_term = None

    def reap(block: bool) -> None:
        for d, (proc, log) in list(running.items()):
            rc = proc.wait() if block else proc.poll()
            if rc is None:
                continue
            log.close()
            del running[d]
            results[d] = outcome(d, rc, launched[d])
            progress.finished(d, results[d])

    try:
        while queue or running:
            while queue and len(running) < max(1, jobs):
                d = queue.pop(0)
                log = open(Path(d) / LOG_FILE, "ab")
                cmd = [sys.executable, "-m", "taichimyxo.sweep", d, "--threads", str(opts["threads"])]
                env = dict(os.environ, TAICHIMYXO_THREADS=str(opts["threads"]))
                launched[d] = time.time()
                proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                        env=env, start_new_session=True)
                keep_priority(proc.pid)
                running[d] = (proc, log)
                progress.started(d)
            reap(block=False)
            progress.tick()
            time.sleep(0.2)
    except KeyboardInterrupt:
        _stop(running, progress, queue)
        try:
            reap(block=True)
        except KeyboardInterrupt:           # a second Ctrl-C: stop them now
            for proc, _ in running.values():
                _signal(proc, signal.SIGINT)
            reap(block=True)
        for d in queue:
            results[d] = {"name": Path(d).name, "run_dir": d, "status": "not started", "error": None}
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
    return results


def keep_priority(pid: int) -> None:
    """Give a run started in its own session this process's niceness: where Linux groups the scheduling of each
    session (autogroup), a new session is scheduled at nice 0 whatever the process's own nice, so a sweep started
    with `nice -n 19` would run its runs at the priority of every other session."""
    nice = os.nice(0)
    group = Path(f"/proc/{pid}/autogroup")
    if nice <= 0 or not group.exists():
        return
    try:
        group.write_text(str(nice))
    except OSError:                         # not permitted here: the runs keep their session's priority
        pass


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def _signal(proc, sig) -> None:
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def _stop(running: dict, progress, queue: list) -> None:
    progress.note(f"interrupted: {len(running)} running runs close their files and write checkpoints; "
                  f"{len(queue)} not started")
    for proc, _ in running.values():
        _signal(proc, signal.SIGINT)
