"""How steady this machine's cores are: a loop of one dependent add per iteration, timed in short bursts on each core
alone and on all cores at once, so a timing elsewhere can be read against the machine's own spread.

    python benchmarks/machine_speed.py [--bursts 30] [--iterations 300000000] [--out DIR]

Compiles a ten-line C loop with the system's C compiler (cc), runs it pinned to each core in turn and then on all
cores at the same moment, and writes machine_speed.csv (one row per burst: round, core, alone or together, G
iterations per second) and prints each core's range and median. Each iteration waits for the one before, so the
rate follows the core's clock and whatever share of the physical core the host gives the guest, not the memory or
the other core; it needs no hardware counters (which virtual machines often lack). Stop other work first: this
measures the machine, not them.
"""
from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from benchlib import parser, write_csv

LOOP_C = r"""
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
int main(int argc, char **argv) {
  long n = atol(argv[1]); unsigned long a = 1;
  struct timespec t0, t1; clock_gettime(CLOCK_MONOTONIC, &t0);
  for (long k = 0; k < n; k++) { __asm__ volatile("add %1, %0" : "+r"(a) : "r"(k)); }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  printf("%.4f %lu\n", n / ((t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec)) / 1e9, a);
  return 0;
}
"""


def build(folder: Path) -> Path:
    """The loop, compiled (SystemExit with one line where no C compiler is found or the machine is not x86-64)."""
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        raise SystemExit("machine_speed: no C compiler (cc, gcc or clang) on PATH; install one (Debian: gcc)")
    src, exe = folder / "loop.c", folder / "loop"
    src.write_text(LOOP_C)
    p = subprocess.run([cc, "-O2", "-o", str(exe), str(src)], capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"machine_speed: the loop does not compile here (x86-64 only): {p.stderr.strip()[:200]}")
    return exe


def burst(exe: Path, cores: list[int], iterations: int) -> list[float]:
    """One burst on each of `cores` started at the same moment: G iterations per second on each."""
    def pinned(c):
        return lambda: os.sched_setaffinity(0, {c})
    procs = [subprocess.Popen([str(exe), str(iterations)], stdout=subprocess.PIPE, text=True, preexec_fn=pinned(c))
             for c in cores]
    return [float(p.communicate()[0].split()[0]) for p in procs]


def main(argv=None) -> int:
    p = parser(__doc__)
    p.add_argument("--bursts", type=int, default=30, help="bursts per core and per way of running (default 30)")
    p.add_argument("--iterations", type=int, default=300_000_000, help="loop iterations per burst (default 3e8)")
    a = p.parse_args(argv)
    if a.bursts < 1 or a.iterations < 1:
        print("machine_speed: --bursts and --iterations must be at least 1", file=sys.stderr)
        return 2
    if not hasattr(os, "sched_setaffinity"):
        print("machine_speed: needs os.sched_setaffinity (Linux) to pin a burst to a core", file=sys.stderr)
        return 2
    cores = sorted(os.sched_getaffinity(0))
    bursts = 10 if a.quick else a.bursts
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        exe = build(Path(tmp))
        for rnd in range(bursts):
            for c in cores:
                rows.append({"round": rnd, "core": c, "way": "alone",
                             "g_iterations_per_s": burst(exe, [c], a.iterations)[0]})
            if len(cores) > 1:
                for c, rate in zip(cores, burst(exe, cores, a.iterations)):
                    rows.append({"round": rnd, "core": c, "way": "together", "g_iterations_per_s": rate})
    for way in ("alone", "together"):
        for c in cores:
            r = [x["g_iterations_per_s"] for x in rows if x["way"] == way and x["core"] == c]
            if r:
                print(f"core {c} {way:>8}: {min(r):.2f}-{max(r):.2f} G iterations/s, median {statistics.median(r):.2f}"
                      f" ({len(r)} bursts; max/min {max(r) / min(r):.2f})")
    print(f"load average (1, 5, 15 min) at the end: {[round(x, 2) for x in os.getloadavg()]}")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "machine_speed.csv", rows)
    print(f"wrote {out / 'machine_speed.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
