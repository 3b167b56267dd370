"""A sweep from its file to its table: `run_sweep(path, executor="local", jobs=None, out=None)` validates every
point, writes the run folders, hands the unfinished ones to an executor and collects the results.

Executors are modules named in EXECUTORS, imported when asked for (a cluster's dependencies only where it is
used). Each provides

    execute(run_dirs: list[str], jobs: int, options: dict, progress: SweepProgress) -> dict[str, dict]

which runs every folder's point (taichimyxo.sweep.runner.run_point(run_dir, threads), in a process of its own; the
folder holds everything the run needs), at most `jobs` at a time, reports to `progress` (started, finished, note,
tick; taichimyxo.sweep.progress) and returns run_dir -> the dict run_point returns (status completed, failed,
interrupted or "not started"). A failing run must not stop the others. On Ctrl-C it stops the running runs cleanly
(their checkpoints written) and returns. `options`: the sweep file's table of the executor's name ([local],
[slurm]) updated by the caller's options; an optional `check_options(options) -> dict` raises SweepError for a bad
one before any run starts and returns them with defaults."""
from __future__ import annotations

import importlib
import os
from pathlib import Path

from .collect import collect
from .progress import SweepProgress
from .rundir import RUNNING_ELSEWHERE, prepare, queue_order, state, write_text_atomic
from .spec import SweepError, choose_runs, load_sweep

EXECUTORS = {"local": "taichimyxo.sweep.local", "slurm": "taichimyxo.sweep.slurm"}
DEFAULT_ROOT = "sweeps-results"


def executor_module(name: str):
    """The executor's module, imported now; a missing one (or its missing dependency) is a SweepError."""
    if name not in EXECUTORS:
        raise SweepError(f"--executor {name!r}: allowed: {', '.join(EXECUTORS)}")
    mod = EXECUTORS[name]
    try:
        return importlib.import_module(mod)
    except ModuleNotFoundError as e:
        if e.name == mod:
            raise SweepError(f"--executor {name}: {mod} is not part of this installation") from None
        raise SweepError(f"--executor {name} needs the Python package {e.name} (pip install {e.name})") from None


def default_root(sweep) -> Path:
    return Path(DEFAULT_ROOT) / sweep.name


def plan(path, out=None) -> tuple:
    """(sweep, points, root): the file read and every point resolved and validated, nothing written."""
    sweep = load_sweep(path)
    points = sweep.points()
    return sweep, points, Path(out) if out else default_root(sweep)


def run_sweep(path, executor: str = "local", jobs: int | None = None, out=None, dry_run: bool = False,
              options: dict | None = None, stream=None, resume: bool = False, overwrite: bool = False,
              runs: list[str] | None = None) -> dict:
    """Run the sweep file at `path` (taichimyxo/sweep/__init__.py: its format) with `executor`, `jobs` runs at a time
    (default: the executor's DEFAULT_JOBS, else the number of cores), into `out` (default sweeps-results/NAME).
    Finished runs are skipped. Runs in `out` that did not finish (interrupted, killed, failed) are refused unless
    resume (continue them from their checkpoints) or overwrite (start every run of the sweep again). dry_run:
    validate and list, run and write nothing. runs: shell patterns on the point names; only the matching runs run
    (the rest later or elsewhere, into the same folder), the table collects every finished one.

    Returns dict(sweep, root, points: [(point, run_dir, state)], results: run_dir -> result, counts: completed /
    skipped / failed / interrupted / not started, csv, plots). Bad input (the file, a point, the executor or its
    options) raises SweepError before any run starts."""
    sweep, points, root = plan(path, out)
    ex = executor_module(executor)
    opts = {**sweep.executor_options.get(executor, {}), **(options or {})}
    if hasattr(ex, "check_options"):
        opts = ex.check_options(opts)
    jobs = jobs or getattr(ex, "DEFAULT_JOBS", None) or os.cpu_count() or 1     # slurm: the cluster decides
    chosen = choose_runs([p.name for p in points], runs, "sweep")
    listing = [(p, p.run_dir(root), state(p.run_dir(root))) for p in points]
    if chosen is not None:
        listing = [(p, d, st if p.name in chosen or st == "done" else "not chosen") for p, d, st in listing]
    counts = {"completed": 0, "skipped": 0, "failed": 0, "interrupted": 0, "not started": 0, RUNNING_ELSEWHERE: 0}
    if dry_run:
        return {"sweep": sweep, "root": root, "points": listing, "results": {}, "counts": counts, "jobs": jobs}
    listing = check_earlier_runs(listing, root, resume, overwrite)
    from ..runtime.scene_run import check_output_dir
    check_output_dir(str(root))
    write_text_atomic(root / "sweep.toml", Path(sweep.path).read_text())     # what was asked, beside the results
    dirs = [str(prepare(p, root, sweep)) for p in points]
    states = {d: st for d, (_, _, st) in zip(dirs, listing)}
    todo = queue_order([d for d in dirs if states[d] not in ("done", "not chosen", "running")], states)
    counts["skipped"] = sum(st == "done" for _, _, st in listing)
    counts[RUNNING_ELSEWHERE] = sum(st == "running" for _, _, st in listing)   # another command's: left to it
    progress = SweepProgress(sweep.name, total=counts["skipped"] + len(todo), skipped=counts["skipped"], jobs=jobs,
                             stream=stream)
    progress.tick()
    results: dict = {}
    try:
        results = ex.execute(todo, jobs, opts, progress) if todo else {}
    finally:
        progress.close()
    for r in results.values():
        st = r.get("status", "failed")
        counts[st if st in counts else "failed"] += 1
    col = collect(sweep, root, points)
    return {"sweep": sweep, "root": root, "points": listing, "results": results, "counts": counts, "jobs": jobs,
            "csv": col["csv"], "plots": col["plots"]}


def check_earlier_runs(listing: list, root, resume: bool, overwrite: bool) -> list:
    """Nothing of an earlier sweep is lost without being asked: runs that did not finish are continued only with
    resume, and every run folder is removed and started again only with overwrite. Returns the listing to run."""
    if resume and overwrite:
        raise SweepError("--resume and --overwrite: give one (continue the sweep's runs, or start them again)")
    from ..io.outdir import refuse_file_as_folder
    refuse_file_as_folder(root)
    unfinished = [(p, d, st) for p, d, st in listing if st in ("interrupted", "failed")]
    going = [p.name for p, _, st in listing if st == "running"]
    if overwrite and going:
        raise SweepError(f"{root}: {len(going)} run{'s' * (len(going) > 1)} of this sweep running now in another "
                         f"process ({going[0]}); --overwrite only once they have stopped")
    if overwrite:
        import shutil
        for _, d, st in listing:
            if st not in ("new", "not chosen"):
                shutil.rmtree(d)
        return [(p, d, "not chosen" if st == "not chosen" else "new") for p, d, st in listing]
    if unfinished and not resume:
        p, d, st = unfinished[0]
        raise SweepError(f"{root} holds {len(unfinished)} unfinished run{'s' * (len(unfinished) > 1)} of this sweep "
                         f"({p.name}: {st}): --resume to continue them, or --overwrite to start the sweep again")
    return listing
