"""Thread scaling: ms per step of S3's start and of the benchmark states (benchmarks/states.py: S3 after one hour at
paper scale, S13 dense) at each CPU thread count, each count in its own process, alternating the counts over
`--repeats` rounds so a machine that slows down weighs on every count alike.

    python benchmarks/threads.py [--threads 1,2] [--repeats 2] [--steps 1000] [--states "S3 6 h"] [--concurrent]
                                 [--out DIR]

Writes threads.csv into the output folder (the median over the rounds, and every round) and prints a table with the
speed-up over one thread and the load average. On a machine with more cores: --threads 1,2,4,8,16.
--concurrent adds, in each round, as many one-thread processes at once as the largest thread count: what each of a
sweep's one-thread runs gets when they share the machine, and whether the cores themselves scale (each process as
fast as one alone) where one process's threads do not; that row's speed-up is its processes' ms per step against
the first count's (1.0: the cores scale, below 1: the processes slow each other).
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from benchlib import HERE, parser, write_csv


def rows_at(threads: int, steps: int, states: str = "", processes: int = 1) -> list[dict]:
    """Each state's row from `processes` workers of `threads` threads started at once (each its own process)."""
    cmd = [sys.executable, str(HERE / "states.py"), "--measure", "--threads", str(threads), "--steps", str(steps),
           "--states", states]
    workers = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
               for _ in range(processes)]
    out = []
    for w in workers:
        stdout, stderr = w.communicate(timeout=3600)
        rows = [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]
        if not rows:
            tail = (stderr or stdout).strip().splitlines()[-1:] or ["no output"]
            raise SystemExit(f"threads: the worker at {threads} threads failed: {tail[0][:300]}")
        for r in rows:
            r["processes"] = processes
        out += rows
    return out


def main() -> None:
    p = parser(__doc__)
    p.add_argument("--threads", default="1,2", help="comma-separated thread counts (default 1,2)")
    p.add_argument("--repeats", type=int, default=2, help="rounds over the counts (default 2)")
    p.add_argument("--steps", type=int, default=1000, help="steps timed per state (default 1000)")
    p.add_argument("--states", default="", help="comma-separated benchmark states (default all)")
    p.add_argument("--concurrent", action="store_true",
                   help="also time one-thread processes run at once, as many as the largest thread count")
    a = p.parse_args()
    counts = [int(t) for t in a.threads.split(",") if t]
    if not counts or min(counts) < 1:
        raise SystemExit(f"threads: --threads {a.threads!r}: give thread counts of at least 1, like 1,2")
    shapes = [(t, 1) for t in counts] + ([(1, max(counts))] if a.concurrent and max(counts) > 1 else [])
    runs = []
    for rnd in range(a.repeats):
        for t, n in shapes:
            for r in rows_at(t, 200 if a.quick else a.steps, a.states, n):
                r["round"] = rnd
                runs.append(r)
                at_once = f" ({n} processes at once)" if n > 1 else ""
                print(f"round {rnd} {t:>2} threads{at_once} {r['state']:>10}: {r['ms_per_step']:.3f} ms/step",
                      flush=True)
    table = []
    for state in dict.fromkeys(r["state"] for r in runs):
        one = None
        for t, n in shapes:
            ms = statistics.median(r["ms_per_step"] for r in runs
                                   if r["state"] == state and r["threads"] == t and r["processes"] == n)
            one = ms if (t, n) == shapes[0] else one
            table.append({"state": state, "threads": t, "processes": n, "ms_per_step": round(ms, 3),
                          "speedup_vs_first": round(one / ms, 2), "rounds": a.repeats,
                          "particles": next(r["particles"] for r in runs if r["state"] == state)})
    load = [round(x, 2) for x in os.getloadavg()]
    for row in table:
        at_once = f" x {row['processes']} processes" if row["processes"] > 1 else ""
        print(f"{row['state']:>10} {row['threads']:>2} threads{at_once} {row['ms_per_step']:8.3f} ms/step "
              f"x{row['speedup_vs_first']:.2f}")
    print(f"load average (1, 5, 15 min) at the end: {load}")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "threads.csv", table)
    write_csv(out / "threads_rounds.csv", runs)
    print(f"wrote {out / 'threads.csv'}")


if __name__ == "__main__":
    main()
