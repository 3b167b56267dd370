"""The Slurm executor (`sweep FILE --executor slurm`): each run folder is one task of a Slurm job array, submitted
through submitit (https://github.com/facebookincubator/submitit) from the machine where `sbatch` works (a login
node); the run folders and the logs must be on a filesystem the compute nodes share.

Each task runs taichimyxo.sweep.slurm_job.SlurmRun (run_point on the folder, `cpus_per_task` Taichi threads). A run
that reaches its time limit writes its checkpoint, is requeued and resumes from it (slurm_job says how), up to
`max_requeues` times. Results collect as for local runs: from the run folders (result.json), so a sweep run again
with any executor skips what is done. Progress polls squeue every `poll_s`: runs done, running, failed, requeued, and
the time left. What a run prints goes to its folder's run.log; the jobs' own logs (submitit's files: the job script,
JOBID_TASK_0_log.out with the signals and requeues) to OUT/slurm/JOBID_TASK/; each run folder's slurm.json names its
job and log, and slurm-attempts.jsonl lists its attempts.

Running the same sweep again while its jobs are still queued or running watches those jobs instead of submitting
them twice. Ctrl-C cancels the sweep's jobs: the running ones get SIGINT and stop as a Ctrl-C'd run does (files
closed, checkpoint written), the pending ones are removed; the next run of the sweep resumes them.

Options: the sweep file's [slurm] table, any of OPTIONS; the command line's --partition, --account, --time-min,
--cpus-per-task and --mem-gb override it."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import submitit

from .rundir import POINT_FILE, RESULT, read_json, read_result, write_json_atomic
from .slurm_job import SlurmRun, read_attempts
from .spec import SweepError

# option: (default, type, what it is)
OPTIONS = {
    "partition": (None, str, "partition (default: the cluster's default partition)"),
    "account": (None, str, "account to charge"),
    "qos": (None, str, "quality of service"),
    "constraint": (None, str, "node features (sbatch --constraint)"),
    "time_min": (60, int, "time limit of each job, minutes; a run that needs longer is requeued and resumes"),
    "cpus_per_task": (1, int, "CPUs per run (its Taichi threads)"),
    "mem_gb": (4.0, float, "memory per run, GB"),
    "signal_delay_s": (120, int, "SIGUSR2 (checkpoint and requeue) this many seconds before the time limit; "
                                 "slurmctld may send it up to 30 s earlier"),
    "max_requeues": (10, int, "times a run may be requeued after its time limit"),
    "setup": ([], list, "shell lines the job runs first (e.g. module load, source a venv)"),
    "python": (None, str, "the python the jobs run (default: this one)"),
    "poll_s": (10.0, float, "seconds between two looks at the queue"),
}
SLURM_RECORD = "slurm.json"
DEFAULT_JOBS = 256           # runs at once when --jobs is not given: as many as the cluster starts (submitit's default)
ACTIVE = {"PENDING", "RUNNING", "CONFIGURING", "COMPLETING", "REQUEUED", "REQUEUE_HOLD", "REQUEUE_FED", "RESIZING",
          "SUSPENDED", "STOPPED", "SIGNALING", "STAGE_OUT", "RESV_DEL_HOLD", "SPECIAL_EXIT", "PREEMPTED"}
LOST_AFTER_S = 120.0        # a job neither in the queue nor with a result after this long is reported failed


def check_options(options: dict) -> dict:
    """The options with their defaults; an unknown or bad one is a SweepError. Also refuses to go on without the
    Slurm commands (sbatch, squeue) on PATH."""
    out = {k: v[0] for k, v in OPTIONS.items()}
    for k, v in options.items():
        if k not in OPTIONS:
            raise SweepError(f"[slurm] {k}: unknown option; allowed: {', '.join(OPTIONS)}")
        if v is None:
            continue
        kind = OPTIONS[k][1]
        if kind is list:
            if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
                raise SweepError(f"[slurm] {k} = {v!r}: expected a list of strings")
        elif kind is str:
            if not isinstance(v, str) or not v:
                raise SweepError(f"[slurm] {k} = {v!r}: expected a non-empty string")
        else:
            what = "an integer" if kind is int else "a number"
            low = 0 if k in ("max_requeues", "signal_delay_s") or kind is float else 1
            if isinstance(v, bool) or not isinstance(v, (int, float)) or (kind is int and v != int(v)):
                raise SweepError(f"[slurm] {k} = {v!r}: expected {what}")
            if v < low or (kind is float and v <= 0):
                raise SweepError(f"[slurm] {k} = {v!r}: expected {what} {'>=' if kind is int else '>'} {low}")
            v = kind(v)
        out[k] = v
    if out["signal_delay_s"] >= out["time_min"] * 60:
        raise SweepError(f"[slurm] signal_delay_s = {out['signal_delay_s']}: must be shorter than the time limit "
                         f"(time_min = {out['time_min']} min)")
    for cmd in ("sbatch", "squeue", "scontrol"):
        if shutil.which(cmd) is None:
            raise SweepError(f"--executor slurm: no `{cmd}` on PATH: run the sweep where Slurm's commands work "
                             "(a cluster's login node)")
    return out


def log_root(run_dirs: list[str]) -> Path:
    """Where the jobs' logs go: OUT/slurm for run folders OUT/runs/* (a sweep), else beside the run folders."""
    base = Path(os.path.commonpath([str(Path(d).resolve()) for d in run_dirs]))
    if len(run_dirs) == 1:
        base = base.parent
    if base.name == "runs":
        base = base.parent
    return base / "slurm"


def make_executor(folder: Path, opts: dict, jobs: int):
    ex = submitit.SlurmExecutor(folder=str(folder / "%j"), max_num_timeout=opts["max_requeues"],
                                python=opts["python"])
    params = {"job_name": "taichimyxo", "time": opts["time_min"], "cpus_per_task": opts["cpus_per_task"],
              "mem": f"{int(round(opts['mem_gb'] * 1024))}M", "signal_delay_s": opts["signal_delay_s"],
              "array_parallelism": max(1, jobs), "stderr_to_stdout": True,
              "setup": list(opts["setup"]) or None}
    params.update({k: opts[k] for k in ("partition", "account", "qos", "constraint") if opts[k]})
    ex.update_parameters(**params)
    return ex


def queue_states(job_ids) -> dict[str, tuple[str, str]] | None:
    """squeue's view of these jobs (array tasks one by one): job id -> (state, reason). Jobs it has forgotten (ended
    longer ago than MinJobAge) are absent. None when squeue fails (the controller busy or restarting: look again)."""
    arrays = sorted({j.split("_")[0] for j in job_ids})
    if not arrays:
        return {}
    try:
        p = subprocess.run(["squeue", "-h", "-r", "--states=all", "-o", "%i|%T|%r", "-j", ",".join(arrays)],
                           capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    if p.returncode != 0:
        # every job asked for is forgotten: squeue says so as an error; anything else is a failure to look
        return {} if "Invalid job id" in p.stderr else None
    states = {}
    for ln in p.stdout.splitlines():
        parts = ln.strip().split("|")
        if len(parts) == 3:
            states[parts[0]] = (parts[1], parts[2])
    return states


def restarts(job_id: str) -> int | None:
    """How often Slurm requeued the job (scontrol's Restarts=), None when it does not know the job."""
    try:
        out = subprocess.run(["scontrol", "-o", "show", "job", job_id], capture_output=True, text=True,
                             timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    for tok in out.split():
        if tok.startswith("Restarts="):
            return int(tok.split("=", 1)[1])
    return None


def still_queued(run_dirs: list[str]) -> dict[str, submitit.SlurmJob]:
    """The jobs an earlier sweep submitted for these folders (their slurm.json) that are still queued or running."""
    recs = {d: read_json(Path(d) / SLURM_RECORD) or {} for d in run_dirs}
    recs = {d: r for d, r in recs.items() if r.get("job_id") and r.get("folder")}
    states = queue_states([r["job_id"] for r in recs.values()])
    if states is None:
        raise SweepError("--executor slurm: squeue does not answer; is the Slurm controller up? (`squeue` says why)")
    return {d: submitit.SlurmJob(folder=r["folder"], job_id=r["job_id"]) for d, r in recs.items()
            if states.get(r["job_id"], ("",))[0] in ACTIVE}


def submit(run_dirs: list[str], opts: dict, jobs: int, progress) -> dict[str, submitit.SlurmJob]:
    """Submit the folders (one job array) except those an earlier sweep's jobs still run; run_dir -> its job."""
    watched = still_queued(run_dirs)
    for d, job in watched.items():
        progress.note(f"{Path(d).name}: already in Slurm job {job.job_id}; watching it")
    todo = [d for d in run_dirs if d not in watched]
    if not todo:
        return watched
    folder = log_root(run_dirs)
    folder.mkdir(parents=True, exist_ok=True)
    ex = make_executor(folder, opts, jobs)
    try:
        submitted = ex.map_array(SlurmRun(), todo, [opts["cpus_per_task"]] * len(todo))
    except Exception as e:          # noqa: BLE001 - sbatch refused the job: its last error line
        lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
        msg = next((ln for ln in reversed(lines) if "error:" in ln), lines[-1] if lines else repr(e))
        raise SweepError(f"--executor slurm: sbatch refused the jobs: {msg.split('error:', 1)[-1].strip()}") \
            from None
    for d, job in zip(todo, submitted):
        write_json_atomic(Path(d) / SLURM_RECORD, {"job_id": job.job_id, "folder": str(folder / "%j"),
                                                   "log": str(job.paths.stdout), "submitted": time.time()})
    first = submitted[0].job_id.split("_")[0]
    what = f"{len(todo)} runs as Slurm job array {first}" if len(todo) > 1 else f"1 run as Slurm job {first}"
    progress.note(f"submitted {what} "
                  f"({opts['time_min']} min, {opts['cpus_per_task']} CPU, {opts['mem_gb']:g} GB each); "
                  f"logs in {folder}")
    return {**watched, **dict(zip(todo, submitted))}


def job_result(run_dir: str, job) -> dict:
    """What the job left: run_point's dict, or failed with the job's error (its traceback's last line and the log)."""
    name = Path(run_dir).name
    try:
        res = job.result()
    except Exception as e:          # noqa: BLE001 - the job's own error, reported as the run's
        lines = [ln for ln in str(e).splitlines() if ln.strip() and not ln.startswith("-")]
        why = next((ln.strip() for ln in reversed(lines) if "Error" in ln or "error" in ln), lines[-1] if lines else "")
        if "timed-out too many times" in str(e):
            return {"name": name, "run_dir": run_dir, "status": "interrupted",
                    "error": f"requeued {starts(run_dir) - 1} times and not finished; run the sweep "
                             f"again to continue (log: {job.paths.stdout})"}
        return {"name": name, "run_dir": run_dir, "status": "failed",
                "error": f"{why} (log: {job.paths.stdout})"}
    return res if isinstance(res, dict) else {"name": name, "run_dir": run_dir, "status": "failed",
                                              "error": f"unexpected result {res!r}"}


def starts(run_dir: str) -> int:
    """How many times the run's job started (its attempts)."""
    return sum(1 for a in read_attempts(run_dir) if a.get("event") == "start")


def ended_without_result(run_dir: str, job, state: str) -> dict:
    """A job that left no result (killed, cancelled, lost): interrupted when its run can go on (a checkpoint to resume
    from, or a completed simulation whose analysis was cut short), else failed with the log's last line."""
    name = Path(run_dir).name
    r = read_result(run_dir)
    if r:
        return {**r, "status": "completed" if r.get("status") == "completed" else r.get("status", "failed")}
    last = ""
    try:
        lines = [ln.strip() for ln in job.paths.stdout.read_text(errors="replace").splitlines() if ln.strip()]
        last = lines[-1] if lines else ""
    except OSError:
        pass
    why = f"Slurm job {job.job_id} ended {state} without a result" + (f": {last}" if last else "")
    simulated = any((read_json(p) or {}).get("completed") for p in Path(run_dir).glob("*.json")
                    if p.name not in (POINT_FILE, RESULT, SLURM_RECORD))
    if simulated or any(Path(run_dir).glob("*.ckpt.npz")):
        return {"name": name, "run_dir": run_dir, "status": "interrupted", "error": why}
    return {"name": name, "run_dir": run_dir, "status": "failed", "error": f"{why} (log: {job.paths.stdout})"}


def note_requeues(run_dir: str, noted: dict, progress) -> None:
    """Report each time-limit stop of the run once, from its attempts record (slurm-attempts.jsonl) rather than from
    squeue's states: a requeued job passes through COMPLETING and PENDING for seconds, which a look every poll_s
    (10 s) can miss entirely."""
    stops = sum(1 for a in read_attempts(run_dir) if a.get("event") == "end" and a.get("stopped_by_time_limit"))
    if stops > noted.get(run_dir, 0):
        noted[run_dir] = stops
        progress.note(f"{Path(run_dir).name}: requeued (time limit); it resumes from its checkpoint")


def execute(run_dirs: list[str], jobs: int, options: dict, progress) -> dict[str, dict]:
    """Run each folder's point as a task of a Slurm job array, at most `jobs` at once; wait for all, reporting to
    `progress`. Returns run_dir -> result (run_point's dict; status completed, failed or interrupted)."""
    opts = check_options(options)
    if not run_dirs:
        return {}
    running = submit([str(d) for d in run_dirs], opts, jobs, progress)
    results: dict[str, dict] = {}
    seen: dict[str, str] = {}            # run_dir -> the last state squeue showed
    noted: dict[str, int] = {}           # run_dir -> time-limit stops already reported
    missing_since: dict[str, float] = {}
    try:
        while running:
            states = queue_states([j.job_id for j in running.values()])
            if states is None:           # squeue failed this time: look again later
                time.sleep(opts["poll_s"])
                continue
            for d, job in list(running.items()):
                st = states.get(job.job_id, ("", ""))[0]
                if job.paths.result_pickle.exists():
                    res = job_result(d, job)
                elif st in ACTIVE:
                    missing_since.pop(d, None)
                    if st == "RUNNING" and seen.get(d) != "RUNNING":
                        if d not in progress.running:
                            progress.started(d)
                        elif seen.get(d) in ("PENDING", "REQUEUED"):
                            progress.note(f"{Path(d).name}: running again (restart {restarts(job.job_id)}), "
                                          "resuming from its checkpoint")
                    seen[d] = st
                    note_requeues(d, noted, progress)
                    continue
                else:                    # ended without a result, or not (or no longer) known to squeue
                    first = missing_since.setdefault(d, time.monotonic())
                    if time.monotonic() - first < (LOST_AFTER_S if not st else 3 * opts["poll_s"]):
                        continue         # results on a shared filesystem may take a moment
                    res = ended_without_result(d, job, st or "(not in the queue)")
                results[d] = res
                del running[d]
                if d not in progress.running:
                    progress.started(d)
                if res.get("status") == "completed":
                    note_requeues(d, noted, progress)   # stopped, requeued and finished between two looks
                if res.get("status") == "interrupted" and res.get("error"):
                    progress.note(f"{Path(d).name}: {res['error']}")
                progress.finished(d, res)
            progress.tick()
            if running:
                time.sleep(opts["poll_s"])
    except KeyboardInterrupt:
        cancel(running, progress)
        for d, res in wait_cancelled(running).items():
            results[d] = res
            progress.finished(d, res)
    return results


def cancel(running: dict, progress) -> None:
    """Ctrl-C: running jobs get SIGINT (the run stops with its checkpoint, its job ends), pending ones are removed."""
    progress.note(f"interrupted: cancelling {len(running)} Slurm jobs; running runs write their checkpoints")
    ids = [j.job_id for j in running.values()]
    states = queue_states(ids) or {}
    run_ids = [i for i in ids if states.get(i, ("",))[0] == "RUNNING"]
    other = [i for i in ids if i not in run_ids]
    if run_ids:
        subprocess.run(["scancel", "--signal=INT", *run_ids], capture_output=True, timeout=60)
    if other:
        subprocess.run(["scancel", *other], capture_output=True, timeout=60)


def wait_cancelled(running: dict, timeout_s: float = 120.0) -> dict[str, dict]:
    """The cancelled jobs' results, waiting for their runs to write checkpoints (a second Ctrl-C stops waiting)."""
    out = {}
    t0 = time.monotonic()
    try:
        while running and time.monotonic() - t0 < timeout_s:
            states = queue_states([j.job_id for j in running.values()])
            if states is None:
                time.sleep(1.0)
                continue
            for d, job in list(running.items()):
                if job.paths.result_pickle.exists():
                    out[d] = job_result(d, job)
                elif states.get(job.job_id, ("",))[0] not in ACTIVE:
                    out[d] = {"name": Path(d).name, "run_dir": d, "status": "not started"
                              if not starts(d) else "interrupted", "error": None}
                else:
                    continue
                del running[d]
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    for d in running:
        subprocess.run(["scancel", running[d].job_id], capture_output=True, timeout=60)
        out[d] = {"name": Path(d).name, "run_dir": d, "status": "interrupted", "error": None}
    if out:
        print(f"taichimyxo: {len(out)} Slurm jobs cancelled; their logs: {log_root(list(out))}", file=sys.stderr)
    return out
