"""The benchmark suite: one entry point that lists the benchmarks of this folder and runs one.

    python benchmarks/suite.py                    # each benchmark, what it measures, where its results go
    python benchmarks/suite.py NAME [ARGS ...]    # run it (ARGS: its own, e.g. --quick, --out DIR; NAME --help)

Every benchmark is a script of the clone, not a command of the installed tool; each writes into benchmarks-results/
in the current folder unless --out names one (the project's own measurements are in benchmarks/results/, with the
command and the machine's load that made them). Speeds are ratios measured side by side in one run on a quiet
machine: stop other work first. The parts that are not benchmarks (benchlib.py, shared code; accuracy_measures.py,
the accuracy study's worker) are not listed."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

# name -> (group, what it measures, where its results are): the order the listing shows them in
BENCHMARKS = {
    "throughput": ("speed", "particle-steps/s of the benchmark states and the scenes' starts at 1x-16x the area",
                   "benchmarks/results/throughput.csv"),
    "vs_lammps": ("speed", "taichimyxo against LAMMPS rods (benchmarks/lammps/) in one invocation",
                  "benchmarks/results/vs_lammps.json"),
    "threads": ("speed", "ms per step against CPU threads, start and benchmark states",
                "benchmarks/results/threads.csv"),
    "states": ("speed", "(re)makes the benchmark states: the configurations runs spend their time in",
               "benchmarks/states/"),
    "before_after": ("speed", "an earlier commit against the working tree, alternating, in one run",
                     "benchmarks/results/before_after.csv"),
    "writers_cost": ("speed", "what the CLI's writers add to the bare steps", "benchmarks/results/writers_cost.csv"),
    "skin": ("speed", "cost per step and rebuilds against the neighbour-list skin", "benchmarks/results/skin.csv"),
    "dense_step": ("speed", "the dense step's parts by counted instructions, and its forces check",
                   "benchmarks/results/dense_step.md"),
    "pair_loop_c": ("speed", "the contact pair loop in plain C (OpenMP) against Taichi's, same state, alternating",
                    "benchmarks/results/pair_loop_c.csv"),
    "machine_speed": ("speed", "how steady the machine's cores are: a one-add loop in bursts, alone and together",
                      "benchmarks/results/machine_speed.csv"),
    "measures": ("speed", "wall time of the experimental measures on a paper-scale trajectory",
                 "docs/measures.md, Cost"),
    "accuracy": ("accuracy", "each method against a converged reference, and its cost per simulated hour",
                 "benchmarks/results/ACCURACY.md"),
    "accuracy_cost": ("accuracy", "wall time of a 6 h paper-scale S3 against step and integrator, with the outcome "
                      "check's verdict on each point", "benchmarks/results/accuracy_cost.md"),
    "accuracy_outcomes": ("accuracy", "whether a larger step changes what a user measures (sweep outcomes)",
                          "benchmarks/results/accuracy_outcomes.md"),
    "stability_sweep": ("accuracy", "the largest stable step per integrator over the stiffness grid",
                        "benchmarks/results/stability.md"),
    "long_run": ("stability", "30 simulated minutes of a dense S13-like patch keep every invariant",
                 "benchmarks/results/long_run.log"),
    "same_runs": ("changes", "every effect run under an earlier commit and the working tree, bit for bit",
                  "benchmarks/results/same_runs.csv"),
    "compare_runs": ("changes", "the last frames of two runs of one scene and seed, side by side", "a PNG where asked"),
    "rigid_body_check": ("physics", "pre-formed aggregates against the rigid-body model of the edge speed (S2 Text)",
                         "benchmarks/results/rigid_body_check.md"),
    "aggregate_balance": ("physics", "why a run's aggregates turn at their edge speed: the torque balance, factor "
                          "by factor from the rigid-body model's disk", "benchmarks/results/aggregate_balance.md"),
    "continue_state": ("physics", "a benchmark state continued as a run with velocities (the 6 h S3's aggregates' "
                       "torque balance)", "benchmarks/results/aggregate_balance_S3_paper_6h.md"),
    "tracks_validation": ("physics", "the mechanism report on degraded tracks of simulated runs",
                          "benchmarks/results/tracks_validation.md"),
    "lab_example": ("physics", "the mechanism report on a public data set of M. xanthus tracks (downloaded)",
                    "docs/lab-tracks.md"),
    "gpu_check": ("device", "the gpu tests and the CUDA throughput, on a machine with a CUDA GPU",
                  "gpu-check-results/"),
}
NOT_BENCHMARKS = {"benchlib", "accuracy_measures", "suite"}


def script(name: str) -> Path:
    return HERE / (f"{name}.sh" if name == "gpu_check" else f"{name}.py")


def present() -> list[str]:
    return [n for n in BENCHMARKS if script(n).is_file()]


def listing() -> str:
    rows, group = [], None
    for n in present():
        g, what, res = BENCHMARKS[n]
        if g != group:
            rows.append(f"\n{g}:")
            group = g
        rows.append(f"  {n:<18} {what}\n  {'':<18} results: {res}")
    return "\n".join(rows).lstrip("\n") + "\n"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("list", "-h", "--help"):
        print(__doc__.split("\n\n")[1] if argv else "", end="\n" if argv else "")
        print(listing(), end="")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in present():
        print(f"benchmarks/suite.py: unknown benchmark {name!r}; one of {', '.join(present())}", file=sys.stderr)
        return 2
    p = script(name)
    cmd = ["bash", str(p), *rest] if p.suffix == ".sh" else [sys.executable, str(p), *rest]
    return subprocess.call(cmd)


if __name__ == "__main__":
    sys.exit(main())
