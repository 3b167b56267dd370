"""The command line's sweep: `sweep FILE|NAME` and the executor options `sweep`, `videos` and `figures` share
(--executor, --jobs, the Slurm flags)."""
from __future__ import annotations

import argparse
import os
import sys

from ..io.scene import SceneError

EXIT_RUN_FAILED = 1
EXIT_INTERRUPTED = 130


def positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"{v} must be at least 1")
    return v


EXECUTOR_NAMES = ("local", "slurm")   # taichimyxo.sweep.orchestrator.EXECUTORS (not imported: keep the CLI light)


# --executor slurm's options on the command line: (flag, [slurm] key, type, metavar, help);
# taichimyxo.sweep.slurm.OPTIONS has them all (the sweep file's [slurm] table takes any of those)
SLURM_FLAGS = (("--partition", "partition", str, "NAME", "partition (default: the cluster's default)"),
               ("--account", "account", str, "NAME", "account to charge"),
               ("--time-min", "time_min", positive_int, "MIN", "time limit per run, minutes (default 60); a run "
                "that needs longer is requeued and resumes from its checkpoint"),
               ("--cpus-per-task", "cpus_per_task", positive_int, "N", "CPUs (Taichi threads) per run (default 1)"),
               ("--mem-gb", "mem_gb", float, "GB", "memory per run, GB (default 4)"))


def executor_arguments(p, jobs_help: str) -> None:
    p.add_argument("--executor", default="local", choices=EXECUTOR_NAMES,
                   help="local: processes on this machine (default); slurm: jobs on a Slurm cluster")
    p.add_argument("--jobs", type=positive_int, help=jobs_help + "; with slurm: jobs running at once (default: "
                                                              "as many as the cluster starts)")
    g = p.add_argument_group("--executor slurm", "(override the sweep file's [slurm] table)")
    for flag, key, kind, metavar, text in SLURM_FLAGS:
        g.add_argument(flag, dest=f"slurm_{key}", type=kind, metavar=metavar, help=text)


def executor_options(args) -> dict:
    """The executor's options given on the command line (they update the sweep file's [local] / [slurm] table)."""
    given = {key: getattr(args, f"slurm_{key}") for _, key, _, _, _ in SLURM_FLAGS
             if getattr(args, f"slurm_{key}", None) is not None}
    if given and args.executor != "slurm":
        flags = [f for f, key, _, _, _ in SLURM_FLAGS if key in given]
        raise SceneError(f"{', '.join(flags)}: only with --executor slurm")
    return given


def cmd_sweep(args) -> int:
    from ..runtime.status_line import duration
    from ..sweep import run_sweep
    res = run_sweep(args.file, executor=args.executor, jobs=args.jobs, out=args.out, dry_run=args.dry_run,
                    options=executor_options(args), resume=args.resume, overwrite=args.overwrite, runs=args.runs)
    sw, pts = res["sweep"], res["points"]
    combos = len(pts) // max(1, len(sw.seeds))
    over = f"{combos} grid points of {', '.join(sw.swept_keys)} x " if sw.swept_keys else ""
    seeds = f"{len(sw.seeds)} seed{'s' if len(sw.seeds) > 1 else ''}"
    hours = sorted({p.scene.hours for p, _, _ in pts})
    each = f"{duration(hours[0] * 3600)} simulated each" if len(hours) == 1 else \
        f"{duration(hours[0] * 3600)} to {duration(hours[-1] * 3600)} simulated"
    print(f"{sw.name}: {len(pts)} runs ({over}{seeds}), {each}, in {res['root']}")
    if args.dry_run:
        w = max(len(p.name) for p, _, _ in pts)
        for p, d, st in pts:
            print(f"  {st:<11} {p.name:<{w}}  {d}")
        return 0
    c = res["counts"]
    print(f"{sw.name}: {c['completed']} completed, {c['skipped']} done before, {c['failed']} failed"
          + (f", {c['interrupted'] + c['not started']} interrupted or not started" if c["interrupted"] +
             c["not started"] else "")
          + (f", {c['running elsewhere']} running in another process" if c["running elsewhere"] else ""))
    for d, r in res["results"].items():
        if r.get("status") == "failed":
            print(f"  failed {r.get('name')}: {r.get('error')} (log: {os.path.join(d, 'run.log')})")
    print(f"table {res['csv']}" + "".join(f"\nplot {p}" for p in res["plots"]))
    if c["interrupted"] or c["not started"]:
        print(f"taichimyxo: {sw.name} interrupted; continue with the same command and --resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    return EXIT_RUN_FAILED if c["failed"] else 0
