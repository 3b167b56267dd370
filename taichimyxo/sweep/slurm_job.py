"""What a Slurm job of a sweep runs (taichimyxo.sweep.slurm submits it through submitit): one run folder's point
(taichimyxo.sweep.runner.run_point), requeued when it reaches its time limit and resumed from its checkpoint.

How a time limit becomes a resumed run:

1. the job is submitted with ``--signal=USR2@signal_delay_s``: slurmctld sends SIGUSR2 to the job's step at most
   signal_delay_s + 30 s before the time limit (it checks time limits every 30 s) and SIGTERM at the limit;
2. :class:`TimeLimitStop` turns that SIGUSR2 into the stop the simulation knows (taichimyxo.runtime.run_loop.Interrupt):
   at once when the run's driver listens, otherwise one SIGTERM as soon as it does (the signal came before the
   simulation started); the driver finishes its chunk, closes the trajectory and writes the checkpoint (as Ctrl-C);
3. run_point returns "interrupted", and the handler submitit installed for SIGUSR2 runs: ``checkpoint()`` (submitit's
   Checkpointable: the same call again, which resumes from the checkpoint on disk), ``scontrol requeue``, exit. The
   job is pending again and starts over, up to the executor's max_requeues times.

A SIGTERM without the warning (scancel, a time limit reached without it) stops the run the same way, checkpoint
written, with no requeue: the next sweep of the same file resumes it.

What the run prints goes to the run folder's run.log (as with the local executor); the job's own log (submitit's,
srun's) to the sweep's slurm/ folder. Each attempt is a line in the run folder's slurm-attempts.jsonl: when it started,
the job id and Slurm's restart count (SLURM_RESTART_COUNT), host and process id, and when it ended: its status,
simulated seconds and sessions (a resumed run has more than one) and whether the time-limit signal stopped it."""
from __future__ import annotations

import json
import os
import signal
import socket
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

from submitit.helpers import Checkpointable

from ..runtime.backend import reset
from ..runtime.run_loop import Interrupt
from .rundir import LOG_FILE
from .runner import run_point

ATTEMPTS_FILE = "slurm-attempts.jsonl"


class TimeLimitStop:
    """While active: SIGUSR2 (Slurm's warning before the time limit, or a preemption) stops the simulation cleanly
    with a checkpoint (one SIGTERM, once the run's driver listens for it). ``signalled``: the warning came;
    ``requeue()``: hand it to the handler that was there before (submitit's: checkpoint, requeue, exit)."""

    def __init__(self, poll_s: float = 0.2):
        self.poll_s = poll_s
        self.signalled = threading.Event()
        self._done = threading.Event()
        self._previous = None
        self._thread = None

    def __enter__(self):
        self._previous = signal.signal(signal.SIGUSR2, self._on_warning)
        self._thread = threading.Thread(target=self._forward, name="time-limit-stop", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._done.set()
        self._thread.join()
        signal.signal(signal.SIGUSR2, self._previous)

    def _on_warning(self, signum, frame):
        print(f"taichimyxo: caught {signal.Signals(signum).name} (time limit or preemption): stopping with a "
              "checkpoint", flush=True)
        self.signalled.set()
        driver = _listening_driver()
        if driver is not None:      # the stop is asked for here, in the main thread: the chunk now running is the last
            driver.request(signal.SIGTERM)

    def _forward(self) -> None:
        """After a warning that came before the simulation's driver listened: wait until it handles SIGTERM, then
        send one (a second one would stop it at once, without a checkpoint, so never when it already has one)."""
        while not self._done.is_set():
            if self.signalled.is_set():
                driver = _listening_driver()
                if driver is not None:
                    if driver.signum is None:
                        os.kill(os.getpid(), signal.SIGTERM)
                    return
            self._done.wait(self.poll_s)

    def requeue(self) -> None:
        """Run the SIGUSR2 handler that was installed before (submitit's: checkpoint(), scontrol requeue, exit)."""
        if callable(self._previous):
            self._previous(signal.SIGUSR2, None)


def _listening_driver() -> Interrupt | None:
    """The simulation driver's signal catcher, when it handles SIGTERM now (taichimyxo.runtime.run_loop.drive)."""
    driver = getattr(signal.getsignal(signal.SIGTERM), "__self__", None)
    return driver if isinstance(driver, Interrupt) else None


@contextmanager
def output_to(path):
    """Everything the process writes to stdout and stderr (Taichi's C++ too) appended to `path` meanwhile: the run
    folder's run.log, as the local executor writes it."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        yield
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for f in (fd, *saved):
            os.close(f)


def record_attempt(run_dir, **fields) -> None:
    """Append one JSON line to the run folder's slurm-attempts.jsonl."""
    line = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "job_id": job_id(),
            "restart_count": int(os.environ.get("SLURM_RESTART_COUNT", 0)), "host": socket.gethostname(),
            "pid": os.getpid(), **fields}
    with open(Path(run_dir) / ATTEMPTS_FILE, "a") as f:
        f.write(json.dumps(line) + "\n")


def read_attempts(run_dir) -> list[dict]:
    """The run folder's attempt records (taichimyxo.sweep.slurm_job.record_attempt), oldest first."""
    try:
        lines = (Path(run_dir) / ATTEMPTS_FILE).read_text().splitlines()
    except OSError:
        return []
    out = []
    for ln in lines:
        try:
            out.append(json.loads(ln))
        except ValueError:
            pass
    return out


def job_id() -> str | None:
    """This job's id as squeue shows it (ARRAY_TASK for a task of an array)."""
    arr, task = os.environ.get("SLURM_ARRAY_JOB_ID"), os.environ.get("SLURM_ARRAY_TASK_ID")
    return f"{arr}_{task}" if arr and task else os.environ.get("SLURM_JOB_ID")


class SlurmRun(Checkpointable):
    """The callable each job runs: run_point(run_dir, threads) under TimeLimitStop. Checkpointable: on the warning
    signal submitit resubmits the same call (Checkpointable.checkpoint), which resumes from the checkpoint the run
    wrote."""

    def __call__(self, run_dir: str, threads: int = 1) -> dict:
        os.environ["TAICHIMYXO_THREADS"] = str(threads)
        record_attempt(run_dir, event="start")
        print(f"taichimyxo: running {run_dir}; its output: {Path(run_dir) / LOG_FILE}", flush=True)
        with TimeLimitStop() as stop, output_to(Path(run_dir) / LOG_FILE):
            res = run_point(run_dir, threads=threads)
        stopped = stop.signalled.is_set() and res.get("status") == "interrupted"
        record_attempt(run_dir, event="end", status=res.get("status"), simulated_seconds=res.get("simulated_seconds"),
                       sessions=res.get("sessions"), stopped_by_time_limit=stopped)
        if stopped:
            # Taichi writes the kernels it compiled to its offline cache when it is reset: now, before the requeue
            # has Slurm terminate this process, so that the next attempt loads them instead of compiling again
            reset()
            stop.requeue()          # exits the job when it requeues; returns (or raises) when it may not
        return res
