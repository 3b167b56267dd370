"""Thread scaling: ms per step of S3's start and of the benchmark states (benchmarks/states.py: S3 after one hour at
paper scale, S13 dense) at each CPU thread count, each count in its own process, alternating the counts over
`--repeats` rounds so a machine that slows down weighs on every count alike.

    python benchmarks/threads.py [--threads 1,2] [--repeats 2] [--steps 1000] [--out DIR]

Writes threads.csv into the output folder (the median over the rounds, and every round) and prints a table with the
speed-up over one thread and the load average. On a machine with more cores: --threads 1,2,4,8,16.
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from benchlib import HERE, parser, write_csv


def rows_at(threads: int, steps: int) -> list[dict]:
    cmd = [sys.executable, str(HERE / "states.py"), "--measure", "--threads", str(threads), "--steps", str(steps)]
    out = []
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
    for line in p.stdout.splitlines():
        if line.startswith("{"):
            out.append(json.loads(line))
    if not out:
        tail = (p.stderr or p.stdout).strip().splitlines()[-1:] or ["no output"]
        raise SystemExit(f"threads: the worker at {threads} threads failed: {tail[0][:300]}")
    return out


def main() -> None:
    p = parser(__doc__)
    p.add_argument("--threads", default="1,2", help="comma-separated thread counts (default 1,2)")
    p.add_argument("--repeats", type=int, default=2, help="rounds over the counts (default 2)")
    p.add_argument("--steps", type=int, default=1000, help="steps timed per state (default 1000)")
    a = p.parse_args()
    counts = [int(t) for t in a.threads.split(",") if t]
    runs = []
    for rnd in range(a.repeats):
        for t in counts:
            for r in rows_at(t, 200 if a.quick else a.steps):
                r["round"] = rnd
                runs.append(r)
                print(f"round {rnd} {t:>2} threads {r['state']:>10}: {r['ms_per_step']:.3f} ms/step", flush=True)
    table = []
    for state in dict.fromkeys(r["state"] for r in runs):
        one = None
        for t in counts:
            ms = statistics.median(r["ms_per_step"] for r in runs if r["state"] == state and r["threads"] == t)
            one = ms if t == counts[0] else one
            table.append({"state": state, "threads": t, "ms_per_step": round(ms, 3),
                          "speedup_vs_first": round(one / ms, 2), "rounds": a.repeats,
                          "particles": next(r["particles"] for r in runs if r["state"] == state)})
    load = [round(x, 2) for x in os.getloadavg()]
    for row in table:
        print(f"{row['state']:>10} {row['threads']:>2} threads {row['ms_per_step']:8.3f} ms/step "
              f"x{row['speedup_vs_first']:.2f}")
    print(f"load average (1, 5, 15 min) at the end: {load}")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "threads.csv", table)
    write_csv(out / "threads_rounds.csv", runs)
    print(f"wrote {out / 'threads.csv'}")


if __name__ == "__main__":
    main()
