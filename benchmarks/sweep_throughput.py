"""Parallel runs against parallel threads: the total throughput of N runs x 1 thread against 1 run x N threads, the
choice the local sweep executor makes, measured in one invocation on this machine.

    python benchmarks/sweep_throughput.py [--quick] [--out DIR] [--n 2] [--scene S3] [--scale 0.5] [--minutes 1]

Both go through the sweep's own machinery (run folders, the local executor's worker processes, one per run):
  N x 1   N seeds of the scene at once, each run on one thread (what `sweep --jobs N` does)
  1 x N   one of those runs alone on N threads
then N x 1 again, so a drift in the machine's load shows as a difference between the two. Throughput is simulated
steps per wall second summed over the runs that ran at once, two ways: the simulation loop's (each run's steps over
its loop's wall time; compiling, placing and analysing excluded) and end to end (all steps over the time from the
first worker's start to the last one's end: Python, compiling or loading kernels, placing, analysing included).
The default scene is S3 at half scale (100 x 100 µm, 500 cells: the scale of sweeps/stiffness.toml); below about
3000 segments a simulation runs its loops serially, so a smaller scene would gain nothing from threads by
construction. Kernels are compiled before measuring (a short run of the same configuration on 1 and on N threads);
a run loads them from Taichi's cache at its first step, inside the loop's time (a second or two).

Writes sweep_throughput.json and .csv into the output folder and prints the ratios (N x 1) / (1 x N); above 1, the
runs side by side do more. Rates on a busy machine are not results: note the load the script prints (N processes
also take a larger share of busy cores from other jobs than one process does, which favours N x 1 there).
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

from benchlib import parser, write_csv


def sweep_file(folder: Path, scene: str, scale: float, minutes: float, seeds: list[int]) -> Path:
    f = folder / f"bench-{len(seeds)}-{minutes:g}.toml"
    f.write_text(f'name = "bench"\nscene = "{scene}"\nseeds = {seeds}\nhours = {minutes / 60.0!r}\n'
                 f'scale = {scale!r}\n[set]\noutput.frame_interval_min = {max(minutes / 4, 0.01)!r}\n')
    return f


def measure(label: str, file: Path, root: Path, jobs: int, threads: int) -> dict:
    """Run every point of `file` with the local executor, `jobs` at a time on `threads` threads each."""
    from taichimyxo.sweep import plan
    from taichimyxo.sweep.local import execute
    from taichimyxo.sweep.progress import SweepProgress
    from taichimyxo.sweep.rundir import prepare
    sw, points, _ = plan(file, root)
    dirs = [str(prepare(p, root, sw)) for p in points]
    load = os.getloadavg()[0]
    progress = SweepProgress(label, total=len(dirs), skipped=0, jobs=jobs, stream=open(os.devnull, "w"))
    res = execute(dirs, jobs, {"threads": threads}, progress)
    bad = [r for r in res.values() if r["status"] != "completed"]
    if bad:
        sys.exit(f"{label}: {bad[0]['name']} {bad[0]['status']}: {bad[0].get('error')}")
    rs = list(res.values())
    steps = sum(r["steps"] for r in rs)
    span = max(r["ended_at"] for r in rs) - min(r["started_at"] for r in rs)
    return {"config": label, "runs": len(rs), "threads_per_run": threads, "steps": steps,
            "loop_steps_per_s": sum(r["steps"] / r["wall_seconds"] for r in rs),
            "end_to_end_steps_per_s": steps / span, "span_s": round(span, 2),
            "loadavg_1min_before": round(load, 2), "loadavg_1min_after": round(os.getloadavg()[0], 2)}


def main() -> None:
    p = parser(__doc__, quick_help="15 simulated seconds per run instead of a minute")
    p.add_argument("--n", type=int, default=2, help="runs side by side, and threads of the one run (default 2)")
    p.add_argument("--scene", default="S3")
    p.add_argument("--scale", type=float, default=0.5, help="box side scale (cells with the area; default 0.5)")
    p.add_argument("--minutes", type=float, default=1.0, help="simulated minutes per run (default 1)")
    a = p.parse_args()
    minutes = 0.25 if a.quick else a.minutes
    n = a.n
    with tempfile.TemporaryDirectory(prefix="sweep-throughput-") as tmp:
        tmp = Path(tmp)
        warm = sweep_file(tmp, a.scene, a.scale, 0.02, [1])
        print(f"compiling (a {0.02 * 60:g} s run of {a.scene} at scale {a.scale:g} on 1 and on {n} threads: Taichi "
              f"caches kernels per thread count) ...", flush=True)
        measure("warm-up", warm, tmp / "warm1", 1, 1)
        measure("warm-up", warm, tmp / "warmN", 1, n)
        many = sweep_file(tmp, a.scene, a.scale, minutes, list(range(1, n + 1)))
        one = sweep_file(tmp, a.scene, a.scale, minutes, [1])
        rows = []
        for label, file, jobs, threads in ((f"{n} runs x 1 thread", many, n, 1),
                                           (f"1 run x {n} threads", one, 1, n),
                                           (f"{n} runs x 1 thread (again)", many, n, 1)):
            t0 = time.perf_counter()
            rows.append(measure(label, file, tmp / f"r{len(rows)}", jobs, threads))
            r = rows[-1]
            print(f"{label}: {r['loop_steps_per_s']:.0f} steps/s in the loop, {r['end_to_end_steps_per_s']:.0f} "
                  f"end to end ({time.perf_counter() - t0:.0f} s; load {r['loadavg_1min_before']} -> "
                  f"{r['loadavg_1min_after']})", flush=True)
    par = [r for r in rows if r["runs"] > 1]
    ratio = {k: [r[k] / rows[1][k] for r in par] for k in ("loop_steps_per_s", "end_to_end_steps_per_s")}
    print(f"(N x 1) / (1 x N), N = {n}: loop {' and '.join(f'{x:.2f}' for x in ratio['loop_steps_per_s'])}, "
          f"end to end {' and '.join(f'{x:.2f}' for x in ratio['end_to_end_steps_per_s'])} (first and second "
          f"N x 1 pass); cores: {os.cpu_count()}")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = "sweep_throughput_quick" if a.quick else "sweep_throughput"
    write_csv(out / f"{stem}.csv", rows)
    (out / f"{stem}.json").write_text(json.dumps({"scene": a.scene, "scale": a.scale, "minutes": minutes, "n": n,
                                                  "cores": os.cpu_count(), "rows": rows, "ratios": ratio}, indent=1))
    print(f"written {out / stem}.csv/.json")


if __name__ == "__main__":
    main()
