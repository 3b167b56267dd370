"""`python -m taichimyxo figures [FIG ...] [--scale paper|half|quarter] [--seeds N] [--executor local|slurm]
[--jobs N] [--threads N] [--out DIR] [--dry-run] [--no-run]`: each of the paper's figures as one composite image.

Every figure's runs are checked first (an unknown figure, a scale that leaves too few cells, missing runs under
--no-run: one line, exit 2, nothing written); then the runs of every figure asked for go to one executor together
(so the cores stay busy across figures), finished runs skipped and interrupted ones resumed; then each figure whose
runs completed is composed (taichimyxo.figures.compose) and, for S2 Fig and S3 Fig, its stiffness series measured
(on the finished runs so far where some are missing)."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from ..sweep.rundir import RUNNING_ELSEWHERE
from ..sweep.spec import choose_runs
from .plan import FINISHED
from .specs import FIGURES, SCALES, figure

EXIT_RUN_FAILED = 1
EXIT_INTERRUPTED = 130


def add_parser(sub, executor_arguments) -> None:
    """The `figures` subcommand on the CLI's subparsers; executor_arguments adds --executor, --jobs and the Slurm
    options as `sweep` has them."""
    f = sub.add_parser("figures", help="the paper's figures (Fig2, Fig3, Fig4, S2Fig, S3Fig, S6Fig) as composite "
                                       "images, from their runs (sweeps/figures/*.toml)")
    f.add_argument("names", nargs="*", metavar="FIG", help=f"figures (default: all): {', '.join(FIGURES)}")
    f.add_argument("--scale", default="paper", choices=list(SCALES),
                   help="the box's sides: paper (the scenes' own), half or quarter (cells with the area)")
    f.add_argument("--seeds", type=int, help="seeds per run (default: the figure's sweep file: 3 for S2Fig and "
                                             "S3Fig, 1 for the others); the panels show the first")
    f.add_argument("--threads", type=int, default=None, help="CPU threads per run, local executor (default 1)")
    f.add_argument("--out", default="figures", help="output folder: the figures and their runs (default figures/)")
    f.add_argument("--records", metavar="DIR", help="where each finished run is kept as a small record the figure "
                                                    "can be composed from when its run folder is gone (default: "
                                                    "OUT/records; docs/figures.md)")
    f.add_argument("--dry-run", action="store_true", help="the runs, simulated hours and estimated wall time; "
                                                          "nothing runs or is written")
    f.add_argument("--no-run", action="store_true", help="compose from finished runs only; missing runs are refused")
    f.add_argument("--runs", metavar="PATTERN", action="append",
                   help="run only the runs whose name matches (shell pattern, e.g. 'scene=S3FigA_*'; repeatable): "
                        "part of a figure now, the rest later or elsewhere, the records joining them")
    executor_arguments(f, "runs at a time (default: the number of cores), each on one thread")
    f.set_defaults(figures_main=cmd_figures)        # the CLI dispatches here without importing this module twice


def resolve_names(names: list[str]) -> list:
    from .plan import FigureError
    if not names:
        return list(FIGURES.values())
    out = []
    for n in names:
        fig = figure(n)
        if fig is None:
            raise FigureError(f"figures: unknown figure {n!r}; known: {', '.join(FIGURES)}")
        if fig not in out:
            out.append(fig)
    return out


def cmd_figures(args, options: dict) -> int:
    from .plan import FigureError, plan_figure
    if args.seeds is not None and args.seeds < 1:
        raise FigureError(f"figures --seeds {args.seeds}: give at least 1")
    if args.threads is not None and (args.threads < 1 or args.executor != "local"):
        raise FigureError(f"figures --threads {args.threads}: a count >= 1, with the local executor (Slurm: "
                          f"--cpus-per-task)")
    if args.dry_run and args.no_run:
        raise FigureError("figures: --dry-run and --no-run together; keep one")
    if args.runs and args.no_run:
        raise FigureError("figures: --runs and --no-run together; --runs chooses what runs")
    figs = resolve_names(args.names)
    plans = [plan_figure(f, args.scale, Path(args.out), args.seeds) for f in figs]
    chosen = choose_runs([pt.name for p in plans for pt in p.points], args.runs, "figures")
    records = Path(args.records) if args.records else Path(args.out) / "records"
    for p in plans:
        p.records = records
    jobs = args.jobs or os.cpu_count() or 1
    if args.dry_run:
        print_dry_run(plans, jobs, records, chosen, args.threads or 1)
        return 0
    if args.no_run:
        for p in plans:
            missing = [pt.name for pt, st in zip(p.points, p.states()) if st not in FINISHED]
            if missing:
                raise FigureError(f"figures {p.figure.name} --no-run: {len(missing)} of {len(p.points)} runs not "
                                  f"finished in {p.root} ({missing[0]}{', ...' if len(missing) > 1 else ''}); run "
                                  f"without --no-run")
    rc = 0
    if not args.no_run:
        options = {**options, **({"threads": args.threads} if args.threads else {})}
        rc = run_all(plans, args.executor, args.jobs, options, chosen)
        if rc == EXIT_INTERRUPTED:
            return rc
    from .compose import compose_figure
    from .records import save_records
    for p in plans:                         # every record first: a figure may share another's run
        for path in save_records(p, records):
            print(f"kept {path}")
    for p in plans:
        states = p.states()
        if any(st not in FINISHED for st in states):        # a failed run: the other figures are still made
            done = sum(st in FINISHED for st in states)
            why = f"{p.figure.name} not composed: {done} of {len(states)} runs finished"
            if p.figure.stiffness and done:                 # the series so far: its rows say what is missing
                from .stiffness import write_stiffness
                for path in write_stiffness(p, Path(args.out)):
                    print(f"wrote {path}")
                why += "; its stiffness series measured on those"
            print(f"taichimyxo: {why}", file=sys.stderr)
            continue
        for path in compose_figure(p, Path(args.out)):
            print(f"wrote {path}")
    return rc


def run_identity(point) -> tuple:
    """What makes two figures' points one run: the scene's fingerprint (physics, seed, box; not names or outputs)
    and the duration."""
    return point.scene.fingerprint(), float(point.scene.hours)


def run_owners(plans: list, chosen: set | None = None) -> dict:
    """For each run two figures share (run_identity), the figure and point that runs it: the one whose run has
    begun, else the first figure asked for; the other's record then stands for both. Points --runs left out do not
    run."""
    owners, rank = {}, {"new": 0}
    for p in plans:
        for pt in p.points:
            if chosen is not None and pt.name not in chosen:
                continue
            k, r = run_identity(pt), rank.get(p.run_state(pt), 1)
            if k not in owners or r > owners[k][2]:
                owners[k] = (p.figure.name, pt.name, r)
    return {k: v[:2] for k, v in owners.items()}


def print_dry_run(plans: list, jobs: int, records: Path | None = None, chosen: set | None = None,
                  threads: int = 1) -> None:
    from ..runtime.status_line import duration
    from .plan import bench_rates, makespan, measured_rates, run_seconds, thread_speedup
    rates, measured = bench_rates(), measured_rates(records)
    speedup, measured_threads = thread_speedup(threads)
    total, all_secs, owners = 0.0, [], run_owners(plans, chosen)
    for p in plans:
        states = p.states()
        secs = [run_seconds(pt.scene, rates, measured) for pt in p.points]
        secs = [s / speedup if s else s for s in secs]                        # one-thread costs, on `threads`
        done = [p.fraction_done(pt) if st in ("interrupted", "running") else 0.0 for pt, st in zip(p.points, states)]
        secs = [s * (1.0 - f) if s else s for s, f in zip(secs, done)]       # what is left of a run under way
        hours = sum(pt.scene.hours for pt in p.points)
        total += hours
        cells = sorted({pt.scene.n_cells for pt in p.points})
        w, h = p.points[0].scene.box
        todo = [s for pt, s, st in zip(p.points, secs, states)
                if st not in FINISHED and (chosen is None or pt.name in chosen)]
        est = (", every run finished" if all(st in FINISHED for st in states)
               else f", about {duration(sum(s for s in todo if s))} of run time left" if None not in secs else "")
        print(f"{p.figure.name} ({p.scale_name}, {w:g} x {h:g} µm, {'/'.join(map(str, cells))} cells): "
              f"{len(p.points)} runs x {len(p.sweep.seeds)} seed{'s' if len(p.sweep.seeds) > 1 else ''}, "
              f"{hours:g} simulated hours{est}; {p.figure.scenes}; in {p.root}")
        for pt, st, s, f in zip(p.points, states, secs, done):
            if chosen is not None and pt.name not in chosen:
                st = "not chosen" if st not in FINISHED else st
            owner = owners.get(run_identity(pt), (p.figure.name, pt.name))
            if st not in FINISHED and st != "not chosen" and owner != (p.figure.name, pt.name):
                st, s = "shared", None
            note = ""
            if st in FINISHED:              # nothing left to run: say where the run is, not what it would cost
                rec = p.record_file(pt) if st == "shared" else None
                s = None
                if st == "shared":
                    note = (f"the record {rec.parent.name}/{rec.name}" if rec is not None
                            else f"the same run as {' '.join(owner)}")
            left = f" left ({f:.0%} done)" if f else ""
            print(f"  {st:<11} {pt.name:<34} {pt.scene.hours:g} h  {'~' + duration(s) + left if s else note}".rstrip())
            if st not in FINISHED and st != "not chosen" and s:
                all_secs.append(s)
    runs = sum(len(p.points) for p in plans)
    runs = f"{len(chosen)} of {runs} runs chosen" if chosen is not None else f"{runs} runs"
    if not rates and not measured:
        print(f"total: {runs}, {total:g} simulated hours; no benchmark table to estimate the wall time from")
        return
    done = sum(len(v) for v in measured.values())
    bench = ("the benchmark's particle-steps/s for the kind of scene (benchmarks/results/throughput.csv) x the cost "
             "of a formed state")
    source = (f"the particle-steps/s of the {done} finished run{'s' if done != 1 else ''} kept in {records}, for "
              f"the same kind of scene, else {bench}") if done else bench
    each = "one thread each" if threads == 1 else (
        f"{threads} threads each: one thread's time / {speedup:.2f}, the speed-up measured at {measured_threads} "
        f"threads (benchmarks/results/threads.csv)" if measured_threads > 1 else
        f"{threads} threads each, priced as one: no speed-up measured at {threads} threads")
    at_once = max(1, min(jobs, len(all_secs)))         # no more at a time than there are runs to make
    print(f"total: {runs}, {total:g} simulated hours; estimated wall time on this machine with {at_once} at a time "
          f"({each}): {duration(makespan(all_secs, jobs))} ({source}; taichimyxo/figures/plan.py)")


def run_all(plans: list, executor: str, jobs: int | None, options: dict, chosen: set | None = None) -> int:
    """Every figure's unfinished runs (those chosen; None: all) through one executor; then each sweep's table. 0, or
    the exit status."""
    from ..runtime.scene_run import check_output_dir
    from ..sweep.collect import collect
    from ..sweep.orchestrator import executor_module
    from ..sweep.progress import SweepProgress
    from ..sweep.rundir import prepare
    from ..sweep.spec import load_sweep
    from .plan import write_sweep_file
    ex = executor_module(executor)
    opts = {**plans[0].sweep.executor_options.get(executor, {}), **options}
    if hasattr(ex, "check_options"):
        opts = ex.check_options(opts)
    jobs = jobs or getattr(ex, "DEFAULT_JOBS", None) or os.cpu_count() or 1
    for p in plans:
        check_output_dir(str(p.root))
    dirs, sizes, recorded, point_of = [], {}, set(), {}
    owners = run_owners(plans, chosen)
    for p in plans:
        p.sweep = load_sweep(write_sweep_file(p))       # the run folders name the sweep file beside them
        for pt, st in zip(p.points, p.states()):
            if chosen is not None and pt.name not in chosen:
                continue
            if st in ("recorded", "shared") or owners[run_identity(pt)] != (p.figure.name, pt.name):
                recorded.add(pt.dir_name)               # finished elsewhere, or another figure runs it: its record
                continue
            d = str(prepare(pt, p.root, p.sweep))
            dirs.append(d)
            point_of[d] = (p, pt)
            sizes[d] = pt.scene.steps * pt.scene.n_cells
    states = {d: _state(d) for d in dirs}
    from ..sweep.rundir import queue_order
    todo = queue_order([d for d in dirs if states[d] not in ("done", "running")], states, sizes)  # longest 1st
    going = [d for d in dirs if states[d] == "running"]
    for d in going:
        print(f"taichimyxo: {Path(d).name} is running in another process; left to it", file=sys.stderr)
    names = "+".join(p.figure.name for p in plans)
    total = len(dirs) + len(recorded) - len(going)
    progress = SweepProgress(names, total=total, skipped=total - len(todo), jobs=jobs,
                             on_completed=lambda d: _keep(*point_of[d]))
    progress.tick()
    try:
        results = ex.execute(todo, jobs, opts, progress) if todo else {}
    finally:
        progress.close()
    for p in plans:
        collect(p.sweep, p.root, p.points)
    bad = {d: r for d, r in results.items() if r.get("status") not in ("completed", "skipped", RUNNING_ELSEWHERE)}
    for d, r in bad.items():
        print(f"  {r.get('status', 'failed')} {r.get('name')}: {r.get('error') or ''} (log: {d}/run.log)",
              file=sys.stderr)
    if any(r.get("status") in ("interrupted", "not started") for r in bad.values()):
        print("taichimyxo: figures interrupted; run the same command again to continue", file=sys.stderr)
        return EXIT_INTERRUPTED
    return EXIT_RUN_FAILED if bad else 0


def _keep(runs, point) -> None:
    """A run's record as soon as it completes: a session that ends, or a machine that is wiped, before the figure's
    other runs do keeps it."""
    from .records import save_record
    if runs.records is not None:
        path = save_record(runs, point, runs.records)
        if path is not None:
            print(f"kept {path}", flush=True)


def _state(d: str) -> str:
    from ..sweep.rundir import state
    return state(d)
