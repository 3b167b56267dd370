"""The Slurm executor on a real Slurm cluster: .ci/slurm.sh starts one on localhost (munged,
slurmctld, slurmd; CI runs it and sets TAICHIMYXO_SLURM_TESTS=1, which makes this test required). Elsewhere it is
skipped, with the reason, when no cluster answers or when the cluster's nodes are other machines (the test pauses a
job's process, so the jobs must run here). Two quick tests at the end need no cluster: the time-limit warning stops
a simulation with a checkpoint, and bad Slurm options are refused in one line.

A sweep of 2 points x 1 seed (36 simulated seconds in a 20 x 20 µm box, no movie) goes through
`--executor slurm` with a 1-minute time limit. One run is made to reach its time limit: once it simulates, the test
stops its process (SIGSTOP), so that it is still running when the limit comes however fast the machine is; Slurm
itself wakes it (SIGCONT, then the SIGUSR2 warning, taichimyxo.sweep.slurm_job). The run writes its checkpoint, is
requeued by Slurm, resumes and completes. Checked: both runs completed and collected, Slurm counts a restart, the
run's attempts (slurm-attempts.jsonl) show the stop at the time limit and the resumed attempt, its summary shows two
sessions (the second simulated only what was left), and its trajectory has every frame once, in order.

No timed asserts: the waits have generous limits only so that a broken cluster cannot hang the suite. It takes
about 1.5-2 minutes: Slurm checks time limits every 30 s and a requeued job waits 11 s before it starts again."""
from __future__ import annotations

import io
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import threading
import time

import pytest

REQUIRED = os.environ.get("TAICHIMYXO_SLURM_TESTS") == "1"
GIVE_UP_S = 900          # a cluster that does not run the jobs fails the test instead of hanging it
PAUSED_POINT = "guiding.kind=active_seed=1"
PAUSE_BEFORE_S = 22      # the time-limit warning comes 25-55 s after a job's start (SWEEP's [slurm])

SWEEP = """
name = "slurm-test"
scene = "S1"
seeds = 1
hours = 0.01                        # 36 s simulated: 18000 steps of 2 ms (run.dt_ms below)
box_um = [20, 20]

[grid]
guiding.kind = ["none", "active"]

[set]
output.frame_interval_min = 0.05    # a trajectory frame every 3 s: 13 frames
run.dt_ms = 2                       # pinned, not S1's own 4 ms: the paused run has work left when it wakes

[outputs]
movie = false

[slurm]
time_min = 1                        # Slurm's shortest time limit
signal_delay_s = 5                  # the warning 25-55 s after the start (slurmctld looks every 30 s)
poll_s = 1
mem_gb = 1
"""


def cluster_problem() -> str | None:
    """Why no Slurm cluster takes jobs here, or None."""
    if shutil.which("sbatch") is None or shutil.which("sinfo") is None:
        return "no Slurm client commands (sbatch, sinfo) on PATH"
    try:
        p = subprocess.run(["sinfo", "-h", "-o", "%t"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError) as e:
        return f"sinfo failed: {e}"
    if p.returncode != 0:
        return f"sinfo failed: {(p.stderr or p.stdout).strip()}"
    states = [s.rstrip("*~#!%$@^-") for s in p.stdout.split()]
    if not any(s in ("idle", "mix", "alloc", "comp") for s in states):
        return f"no Slurm node takes jobs (sinfo: {' '.join(p.stdout.split()) or 'no nodes'})"
    nodes = set(subprocess.run(["sinfo", "-h", "-N", "-o", "%N"], capture_output=True, text=True,
                               timeout=60).stdout.split())
    if nodes != {socket.gethostname().split(".")[0]}:
        return (f"the Slurm cluster's nodes ({' '.join(sorted(nodes))}) are not just this machine, and the test "
                "pauses a job's process")
    return None


@pytest.fixture
def slurm_cluster():
    why = cluster_problem()
    try:
        import submitit  # noqa: F401
    except ImportError:
        why = why or "no submitit (pip install -e '.[test]')"
    if why:
        if REQUIRED:
            pytest.fail(f"TAICHIMYXO_SLURM_TESTS=1 but {why}; .ci/slurm.sh starts a single-node cluster")
        pytest.skip(f"{why}; .ci/slurm.sh starts a single-node cluster (CI sets TAICHIMYXO_SLURM_TESTS=1)")


def frames_in(run_dir) -> int:
    from taichimyxo.io.trajectory import count_frames
    try:
        return count_frames(str(next(run_dir.glob("*.gsd"))))
    except Exception:           # noqa: BLE001 - not there yet, or being written: look again
        return 0


def read_log(run_dir) -> str:
    try:
        return (run_dir / "run.log").read_text(errors="replace")
    except OSError:
        return ""


def slurm_start(job_id: str) -> float | None:
    """The job's start time as Slurm has it (seconds since the epoch), None before it started."""
    out = subprocess.run(["squeue", "-h", "-j", job_id, "-o", "%S"], capture_output=True, text=True).stdout.strip()
    try:
        return time.mktime(time.strptime(out, "%Y-%m-%dT%H:%M:%S"))
    except ValueError:
        return None


class Pauser(threading.Thread):
    """SIGSTOP the first attempt of the run named `point` once it simulates (its trajectory has a frame after the
    first), so that it is still running when its time limit comes whatever the machine's speed: before the
    time-limit warning can come (PAUSE_BEFORE_S after the job's start), or later (a slow start) when the run has
    not reported the warning yet."""

    def __init__(self, root, point):
        super().__init__(daemon=True)
        self.root, self.point = root, point
        self.paused = self.not_paused = None
        self.done = threading.Event()

    def run(self):
        from taichimyxo.sweep.slurm import SLURM_RECORD
        from taichimyxo.sweep.slurm_job import read_attempts
        while not self.done.is_set():
            for d in self.root.glob(f"runs/{self.point}-*"):
                att = read_attempts(d)
                if any(a["event"] == "end" for a in att):
                    self.not_paused = f"{self.point} ended its first attempt before it was seen simulating"
                    return
                start = next((a for a in att if a["event"] == "start"), None)
                if start is None or not (d / SLURM_RECORD).is_file() or frames_in(d) < 2:
                    continue
                if start["host"] != socket.gethostname():
                    self.not_paused = f"{self.point} runs on {start['host']}, not here"
                    return
                t0 = slurm_start(json.loads((d / SLURM_RECORD).read_text())["job_id"])
                if t0 is None:
                    continue
                early = time.time() - t0 < PAUSE_BEFORE_S
                if early or "caught SIGUSR2" not in read_log(d):
                    os.kill(start["pid"], signal.SIGSTOP)
                    self.paused = {"pid": start["pid"], "frames": frames_in(d), "after_s": time.time() - t0}
                else:
                    self.not_paused = f"{self.point} had the time-limit warning before it simulated"
                return
            self.done.wait(0.1)


@pytest.mark.slow
def test_sweep_on_slurm_requeues_a_run_at_its_time_limit_and_resumes_it(slurm_cluster, tmp_path):
    from taichimyxo.io.trajectory import read_frames
    from taichimyxo.sweep import run_sweep
    from taichimyxo.sweep.slurm import SLURM_RECORD, restarts
    from taichimyxo.sweep.slurm_job import read_attempts

    path = tmp_path / "slurm-test.toml"
    path.write_text(SWEEP)
    root = tmp_path / "out"
    pauser = Pauser(root, PAUSED_POINT)
    pauser.start()
    log = io.StringIO()
    gave_up = []

    def give_up(signum, frame):      # the executor cancels its jobs on KeyboardInterrupt and returns
        gave_up.append(time.monotonic())
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGALRM, give_up)
    signal.alarm(GIVE_UP_S)
    try:
        res = run_sweep(str(path), executor="slurm", out=str(root), stream=log)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        pauser.done.set()
        for rec in root.glob(f"runs/*/{SLURM_RECORD}"):      # nothing left behind on the cluster
            subprocess.run(["scancel", json.loads(rec.read_text())["job_id"]], capture_output=True)
    progress = log.getvalue()
    assert not gave_up, f"the sweep did not end within {GIVE_UP_S} s:\n{progress}"
    paused = pauser.paused or pauser.not_paused       # for the messages: whether the run was paused, or why not

    # both runs completed and were collected the way local runs are
    assert res["counts"]["completed"] == 2 and res["counts"]["failed"] == 0, (res["counts"], progress)
    with open(res["csv"]) as f:
        rows = f.read().splitlines()
    assert len(rows) == 3, rows                        # header + one row per run
    assert "requeued (time limit)" in progress, (progress, paused)

    run_dir = next(root.glob(f"runs/{PAUSED_POINT}-*"))
    job_id = json.loads((run_dir / SLURM_RECORD).read_text())["job_id"]
    # Slurm requeued the job (its own count)
    assert (restarts(job_id) or 0) >= 1, f"scontrol shows no restart of job {job_id}"

    # the attempts: the first stopped by the time-limit warning after simulating, with a checkpoint, then resumed
    att = read_attempts(run_dir)
    starts = [a for a in att if a["event"] == "start"]
    ends = [a for a in att if a["event"] == "end"]
    assert len(starts) >= 2 and len(ends) == len(starts), (att, paused)
    assert starts[0]["restart_count"] == 0 and starts[1]["restart_count"] >= 1, att
    first = ends[0]
    assert first["status"] == "interrupted" and first["stopped_by_time_limit"], (att, paused)
    assert first["simulated_seconds"] > 0, att
    assert ends[-1]["status"] == "completed" and ends[-1]["sessions"] == len(starts), att

    # resumed, not restarted: the last session simulated only what was left; every frame once, in order
    summary = json.loads(next(p for p in run_dir.glob("*.json") if p.stem == PAUSED_POINT).read_text())
    assert summary["completed"] and summary["sessions"] == len(starts), summary
    assert abs(summary["simulated_seconds"] - 36.0) < 1e-6, summary
    assert 0 < summary["simulated_seconds_this_session"] <= 36.0 - first["simulated_seconds"] + 1e-6, summary
    times = [fr.time_s for fr in read_frames(str(run_dir / f"{PAUSED_POINT}.gsd"))]
    assert len(times) == 13 and all(b > a for a, b in zip(times, times[1:])), times

    # the other run: completed (requeued or not: that depends on the machine's speed)
    other = next(d for d in root.glob("runs/*") if d != run_dir)
    assert json.loads((other / "result.json").read_text())["status"] == "completed"


# ------------------------------------------------------------------------------------------------ without a cluster
def test_time_limit_warning_stops_the_simulation_with_a_checkpoint(ti_cpu, tmp_path, small_scene):
    """SIGUSR2 (Slurm's warning before the time limit) under TimeLimitStop: the run stops as on Ctrl-C, checkpoint
    written, also when the warning comes before the simulation started (here: before run_scene is called)."""
    pytest.importorskip("submitit")
    from taichimyxo.runtime.scene_run import run_scene
    from taichimyxo.sweep.slurm_job import TimeLimitStop
    sc = small_scene(20, run={"hours": 0.01, "dt_ms": 2.0}, output={"frame_interval_min": 0.02})   # 18000 steps
    before = signal.getsignal(signal.SIGUSR2)
    with TimeLimitStop() as stop:
        os.kill(os.getpid(), signal.SIGUSR2)
        summary = run_scene(sc, out_dir=str(tmp_path), progress=False)
    assert stop.signalled.is_set()
    assert summary["status"] == "interrupted" and 0 < summary["steps"] < sc.steps, summary
    assert (tmp_path / f"{sc.name}.ckpt.npz").is_file()
    assert signal.getsignal(signal.SIGUSR2) == before                 # the handler that was there is back


def test_bad_slurm_options_are_one_line(capsys, tmp_path):
    pytest.importorskip("submitit")
    from taichimyxo.interface.cli import main
    from taichimyxo.sweep.slurm import check_options
    from taichimyxo.sweep.spec import SweepError
    for bad, says in (({"mem_gb": -1}, "[slurm] mem_gb = -1: expected a number > 0"),
                      ({"time_min": 1.5}, "[slurm] time_min = 1.5: expected an integer"),
                      ({"partitions": "x"}, "[slurm] partitions: unknown option"),
                      ({"time_min": 1, "signal_delay_s": 60}, "must be shorter than the time limit")):
        with pytest.raises(SweepError, match=re.escape(says)):
            check_options(bad)
    f = tmp_path / "s.toml"
    f.write_text('scene = "S1"\nhours = 0.001\n')
    assert main(["sweep", str(f), "--mem-gb", "2", "--dry-run"]) == 2
    assert capsys.readouterr().err.strip() == "taichimyxo: error: --mem-gb: only with --executor slurm"
