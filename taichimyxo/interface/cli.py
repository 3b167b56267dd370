"""Command line: python -m taichimyxo {list, keys, scene, render, analyze, claims, decisions, videos, sweep, bench}.

Bad input is one line on stderr naming the problem and a non-zero exit (2), before any simulation starts.
Exit status: 0 done, 2 bad input, 3 a run stopped because its state broke a numerical invariant, 130 interrupted;
`sweep` and parallel `videos`: 1 when a run failed (each listed with its error; the others ran)."""
from __future__ import annotations

import argparse
import os
import sys

from ..io.scene import SCHEMA, Scene, SceneError, available_scenes, parse_set, to_toml, toml_value
from ..io.trajectory import TrajectoryError
from .cli_sweep import EXIT_INTERRUPTED, EXIT_RUN_FAILED, cmd_sweep, executor_arguments, executor_options, positive_int  # noqa: F401

EXIT_BAD_INPUT = 2
EXIT_INVARIANT = 3


def _fail(msg: str) -> int:
    print(f"taichimyxo: error: {msg}", file=sys.stderr)
    return EXIT_BAD_INPUT


class _Parser(argparse.ArgumentParser):
    def error(self, message):          # one line, exit 2
        print(f"taichimyxo: error: {message}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


ARCHES = ("cpu", "cuda", "vulkan", "metal", "gpu")       # as backend.init accepts them


def version() -> str:
    """The installed distribution's version (a wheel, or an editable clone), else the package's own."""
    try:
        from importlib.metadata import PackageNotFoundError
        from importlib.metadata import version as dist_version
        return dist_version("taichimyxo")
    except PackageNotFoundError:
        from .. import __version__
        return __version__


def _build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m taichimyxo", description="Myxobacteria guiding simulator (Taichi).")
    p.add_argument("--version", action="version", version=f"taichimyxo {version()}")
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=_Parser)

    sub.add_parser("list", help="list the scenes, one line each")
    sub.add_parser("keys", help="list every scene key with its default and meaning")

    s = sub.add_parser("scene", help="run a scene (name like S3, or a path to a TOML file)")
    s.add_argument("scene")
    s.add_argument("--hours", type=float, help="simulated hours (overrides run.hours)")
    s.add_argument("--preview", action="store_true",
                   help="small, short version (its time: docs/performance.md): the box side scaled by preview.scale "
                        "(cells with the area), at most preview.hours, frames every preview.frame_interval_min; "
                        "values given with --set or an option (--hours, --frame-minutes, --size) are used as given, "
                        "never scaled")
    s.add_argument("--out", default="videos", help="output folder (default videos/)")
    s.add_argument("--seed", type=int, help="random seed (overrides run.seed)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override any scene key by its dotted name, e.g. --set guiding.kind=active")
    s.add_argument("--arch", default="cpu", choices=ARCHES,
                   help="cpu (default), cuda, vulkan, metal, gpu; unavailable GPUs fall back to cpu")
    s.add_argument("--threads", type=positive_int, help="CPU threads (default: all cores)")
    s.add_argument("--resume", action="store_true", help="continue an unfinished run in --out from its checkpoint")
    s.add_argument("--overwrite", action="store_true", help="start again over a run already in --out (without it, a "
                   "folder holding an unfinished run, or a finished one of other parameters, is refused)")
    s.add_argument("--force", action="store_true",
                   help="run even if the time step exceeds the stability limit; the invariants are still checked at "
                        "every frame (a run that breaks them stops with exit status 3)")
    s.add_argument("--no-rollback", action="store_true",
                   help="stop at the first broken invariant (exit status 3) instead of redoing the stretch since "
                        "the last in-memory snapshot at half the step")
    s.add_argument("--show", action="store_true",
                   help="print the resolved scene as TOML (every key, after --set and --preview) and exit")
    s.add_argument("--no-movie", action="store_true", help="trajectory and summary only")
    s.add_argument("--fps", type=float, help="movie frames per second")
    s.add_argument("--size", help="movie size WxH, e.g. 1280x720")
    s.add_argument("--frame-minutes", type=float, help="simulated minutes between frames")
    s.add_argument("--quiet", action="store_true", help="no progress line")

    r = sub.add_parser("render", help="render a trajectory (.gsd) to a movie without simulating")
    r.add_argument("trajectory")
    r.add_argument("--color", choices=["speed", "strain", "identity", "polarity", "orientation"], default="speed",
                   help="segment speed (µm/min) or strain energy (J, log scale); cell identity, polarity (engine "
                        "direction) or axis angle (mod 180°, cyclic)")
    r.add_argument("--vmin", type=float, help="colour range low end (speed µm/min, default 0; strain J, 1e-21)")
    r.add_argument("--vmax", type=float, help="colour range high end (speed µm/min, default 16; strain J, 1e-17)")
    r.add_argument("--out", help="output folder (created if missing; the movie is named after the trajectory and "
                                 "the colouring), or a movie path ending in .mp4 (default: next to the trajectory)")
    r.add_argument("--fps", type=float, default=10.0)
    r.add_argument("--size", default="1920x1080")
    r.add_argument("--every", type=int, default=1, help="render every K-th frame")

    a = sub.add_parser("analyze", help="aggregates, rotation and speed profiles from a trajectory")
    a.add_argument("trajectory", help="GSD trajectory written by taichimyxo")
    a.add_argument("--out", help="output folder, created if missing (default: next to the trajectory)")
    a.add_argument("--every", type=int, default=1, help="analyse every K-th frame")
    a.add_argument("--v-b", type=float, default=None, help="free-cell speed, µm/min (default: from the scene, or 4)")
    a.add_argument("--no-plots", action="store_true", help="write the JSON summary only")
    a.add_argument("--measures", action="store_true", help="also defects, cluster-size fits, correlations, MSD and "
                   "reversal events (docs/measures.md)")
    a.add_argument("--smoothing", type=float, default=None, metavar="UM", help="--measures: smoothing length of "
                   "the orientation field, µm (default 5, one cell length; its grid is half of it, at most 2.5 µm)")

    c = sub.add_parser("claims", help="the paper's claims measured on runs, one table (markdown, CSV, JSON + plots)")
    c.add_argument("trajectories", nargs="+", metavar="RUN.gsd", help="GSD trajectories written by taichimyxo, or "
                   "runs kept as records by `figures` (RECORDS/NAME.SCALE/*.npz: their analysis as made); each run's "
                   "guiding (non-guided, passive, active, adhesion, slime) is read from the scene it stores")
    c.add_argument("--out", help="output folder for claims.md/.csv/.json and claims.*.png (default: current folder)")
    c.add_argument("--every", type=positive_int, default=1, help="analyse every K-th frame")
    c.add_argument("--v-b", type=float, default=None, help="free-cell speed, µm/min (default: each run's scene)")
    c.add_argument("--no-plots", action="store_true", help="the tables only")

    d = sub.add_parser("decisions", help="the decision study's table from decision sweeps' results (decision x "
                       "claim, mean ± SD over seeds; docs/decisions.md)")
    d.add_argument("folders", nargs="+", metavar="DIR", help="a decision sweep's --out folder (sweeps/decisions.toml, "
                   "sweeps/decisions_dense.toml), or a decisions.json an earlier table wrote (its runs join)")
    d.add_argument("--records", metavar="FOLDER", help="a figures' records folder (docs/figures/records): a sweep run "
                   "not finished in DIR whose physics a record holds is read from it")
    d.add_argument("--out", default=".", help="folder for decisions.md/.csv/.json (default: current folder)")

    v = sub.add_parser("videos", help="regenerate the supplementary videos S1-S17")
    v.add_argument("--preview", action="store_true")
    v.add_argument("--only", help="comma-separated scene names as `list` shows them, e.g. S3,S8,S2FigA")
    v.add_argument("--out", default="videos")
    v.add_argument("--arch", default="cpu", choices=ARCHES)
    v.add_argument("--scale", default="paper", choices=["paper", "half", "quarter"],
                   help="the box's sides x 1, 1/2 or 1/4, cells with the area (videos named NAME-half, ...)")
    v.add_argument("--from", dest="sources", action="append", default=[], metavar="DIR",
                   help="render a video from a finished run of its scene found in DIR's folders (e.g. the "
                        "figures' runs) instead of simulating it again; repeatable")
    executor_arguments(v, "videos at a time (default 1: one after another, as before)")

    w = sub.add_parser("sweep", help="a grid of scene keys x seeds from a sweep file, in parallel here or on a "
                                     "Slurm cluster; one table of outcomes")
    w.add_argument("file", help="sweep file (TOML), or the name of a shipped one, e.g. example; its format: "
                                "docs/sweeps.md")
    w.add_argument("--resume", action="store_true", help="continue the sweep's unfinished runs in --out")
    w.add_argument("--overwrite", action="store_true", help="start the sweep's runs in --out again")
    w.add_argument("--out", help="results folder (default sweeps-results/NAME, NAME the sweep's)")
    w.add_argument("--dry-run", action="store_true", help="validate, list the points and their folders; run nothing")
    w.add_argument("--runs", metavar="PATTERN", action="append",
                   help="run only the points whose name matches (shell pattern, e.g. 'scene=S1_*'; repeatable): part "
                        "of a sweep now, the rest later into the same folder")
    executor_arguments(w, "runs at a time (default: the number of cores), each on one thread")

    b = sub.add_parser("bench", help="measure the simulation's speed (taichimyxo/interface/bench.py)")
    bsub = b.add_subparsers(dest="bench", required=True, parser_class=_Parser)
    t = bsub.add_parser("throughput", help="particle-steps per second of scenes at multiples of the paper's area, "
                                           "and the projected wall time of a full 6 h S3")
    t.add_argument("--arch", default="cpu", choices=ARCHES, help="cpu (default) or cuda, ...: no fallback")
    t.add_argument("--sizes", default="1,4,16", help="multiples of each scene's area (default 1,4,16; cells scale "
                                                     "with the area)")
    t.add_argument("--scenes", default="S1,S3,S11", help="comma-separated scene names (default S1,S3,S11)")
    t.add_argument("--steps", type=positive_int, default=200, help="timed steps per measurement (default 200)")
    t.add_argument("--warm", type=int, default=50, help="untimed steps first: compiling, list settling (default 50)")
    t.add_argument("--threads", type=positive_int, help="CPU threads (default: all cores)")
    t.add_argument("--out", default="benchmarks-results",
                   help="folder for throughput.csv / .json, merged with rows already there (default "
                        "benchmarks-results/)")
    from ..figures.command import add_parser as add_figures_parser
    add_figures_parser(sub, executor_arguments)
    from .cli_tracks import add_parser as add_tracks_parser
    add_tracks_parser(sub)
    return p


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = text.lower().split("x")
        return int(w), int(h)
    except ValueError:
        raise SceneError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 1920x1080") from None


def load_scene_from_args(args) -> Scene:
    over = parse_set(args.set)
    run = over.setdefault("run", {})
    outp = over.setdefault("output", {})
    if args.hours is not None:
        run["hours"] = args.hours
    if args.seed is not None:
        run["seed"] = args.seed
    if getattr(args, "fps", None) is not None:
        outp["fps"] = args.fps
    if getattr(args, "frame_minutes", None) is not None:
        outp["frame_interval_min"] = args.frame_minutes
    if getattr(args, "size", None):
        outp["video_width"], outp["video_height"] = _size(args.size)
    if getattr(args, "no_movie", False):
        outp["movie"] = False
    hours_override = run.get("hours") if args.hours is not None else None
    if hours_override is not None:
        run.pop("hours")
    sc = Scene.load(args.scene, over, preview=args.preview)
    if hours_override is not None:      # --hours wins over --preview's duration
        sc = sc.with_overrides({"run": {"hours": hours_override}})
    from ..physics.stability import check_step
    check_step(sc, force=getattr(args, "force", False))
    return sc


def cmd_list() -> int:
    from ..figures.specs import scene_panels
    panels = scene_panels()                 # which composite of `figures` each scene's run is a panel of
    for name in available_scenes():
        try:
            sc = Scene.load(name)
            fig = f" [{sc.paper_figure}]" if sc.paper_figure else ""
            print(f"{name:<12} {sc.title}{fig}{panels.get(name, '')}")
        except SceneError as e:
            print(f"{name:<12} (invalid: {e})")
    return 0


def cmd_keys() -> int:
    """Four aligned columns: the dotted key, its default, the values allowed, its meaning (units are in the key
    names)."""
    from ..io.schema import allowed
    rows = [(f"{sec}.{k}", toml_value(default), allowed(check) or "-", doc) for sec, keys in SCHEMA.items()
            for k, (typ, default, check, doc) in keys.items()]
    wk, wd, wa = (max(len(r[i]) for r in rows) for i in range(3))
    print(f"{'key':<{wk}}  {'default':<{wd}}  {'allowed':<{wa}}  meaning")
    for key, default, allow, doc in rows:
        print(f"{key:<{wk}}  {default:<{wd}}  {allow:<{wa}}  {doc}")
    return 0


def cmd_scene(args) -> int:
    sc = load_scene_from_args(args)
    if args.show:
        print(to_toml(sc), end="")
        return 0
    from ..runtime.status_line import duration
    from .api import run_scene
    summary = run_scene(sc, out_dir=args.out, arch=args.arch, resume=args.resume, progress=not args.quiet,
                        threads=args.threads, rollback=not args.no_rollback, overwrite=args.overwrite)
    if summary.get("already_complete"):
        print(f"{sc.name}: already complete in {args.out} ({sc.name}.json); nothing changed (--overwrite runs it "
              f"again)")
        return 0
    if summary.get("status") == "interrupted":
        print(f"taichimyxo: {sc.name} interrupted at {duration(summary['simulated_seconds'])} simulated; files closed, "
              f"checkpoint {summary['files'].get('checkpoint')}; continue with --resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    if summary.get("status") == "no_space":
        ck = summary["files"].get("checkpoint")
        print(f"taichimyxo: error: {sc.name} stopped at t = {duration(summary['simulated_seconds'])}: "
              f"{summary['invariant_broken']}; the files in {args.out} keep what was written; free space there and "
              + (f"continue with --resume (from {ck})" if ck and os.path.isfile(os.path.join(args.out, ck)) else
                 "start it again with --overwrite (no checkpoint was written yet)"), file=sys.stderr)
        return EXIT_RUN_FAILED
    if summary.get("status") == "failed":
        print(f"taichimyxo: error: {sc.name} stopped at step {summary['steps']} "
              f"(t = {duration(summary['simulated_seconds'])}): {summary['invariant_broken']}; the trajectory "
              f"{summary['files']['gsd']} is closed with the frames before it and the checkpoint "
              f"{summary['files']['checkpoint']} is written; use a smaller run.dt_ms", file=sys.stderr)
        return EXIT_INVARIANT
    _print_summary(summary, args.out)
    return 0


def _print_summary(summary: dict, out: str) -> None:
    if "particle_steps_per_second" in summary:
        from ..runtime.status_line import duration
        # this session's steps with this session's wall time (after --resume, the totals follow, labelled)
        steps = summary.get("steps_this_session", summary["steps"])
        line = (f"{summary['scene']}: {summary['cells']} cells, {steps} steps "
                f"({duration(summary.get('simulated_seconds_this_session', summary['simulated_seconds']))} "
                f"simulated) in {summary['wall_seconds']:.1f} s wall, "
                f"{summary['particle_steps_per_second'] / 1e6:.1f} M particle-steps/s")
        if summary.get("sessions", 1) > 1:
            line += (f"; run total over {summary['sessions']} sessions: {summary['steps']} steps, "
                     f"{duration(summary['simulated_seconds'])} simulated, {summary['wall_seconds_total']:.1f} s wall")
        print(line)
    else:
        print(f"{summary['scene']}: {summary['status']} {summary.get('source_trajectory', '')}")
    for k, f in summary.get("files", {}).items():
        print(f"  {os.path.join(out, f)}")


def cmd_render(args) -> int:
    # a file render cannot use, --color strain without logged strain or a bad colour range: one line before any
    # frame is written
    from .api import RenderOptionError, render_movie
    try:
        out, png, n = render_movie(args.trajectory, args.out, color=args.color, size=_size(args.size), fps=args.fps,
                                   every=args.every, vmin=args.vmin, vmax=args.vmax)
    except RenderOptionError as e:
        return _fail(f"render: {e}")
    print(f"{out}: {n} frames; last frame {png}")
    return 0


def cmd_analyze(args) -> int:
    from ..analysis import format_summary
    from .api import analyze
    if args.smoothing is not None and not args.smoothing > 0:
        return _fail(f"analyze: --smoothing {args.smoothing:g}: give a length in µm above 0")
    summary = analyze(args.trajectory, out_dir=args.out, every=args.every, v_b=args.v_b, plots=not args.no_plots,
                      measures=args.measures or args.smoothing is not None,
                      measure_params=None if args.smoothing is None else
                      dict(smoothing_um=args.smoothing, spacing_um=min(2.5, args.smoothing / 2)))
    print(format_summary(summary))
    print(f"wrote {summary['json']}" + "".join(f"\nwrote {p}" for p in summary["plots"]))
    return 0


def cmd_claims(args) -> int:
    from ..analysis.claims import format_claims
    from .api import claims
    res = claims(args.trajectories, out_dir=args.out, every=args.every, v_b=args.v_b, plots=not args.no_plots,
                 progress=lambda msg: print(msg, file=sys.stderr))
    print(format_claims(res["rows"]))
    print("".join(f"wrote {p}\n" for p in res["files"]), end="")
    return 0


def cmd_decisions(args) -> int:
    from ..analysis.decisions import write_decisions
    try:
        res = write_decisions(args.folders, args.out, args.records)
    except FileNotFoundError as e:
        raise SceneError(str(e)) from None
    print(open(os.path.join(res["out"], "decisions.md")).read(), end="")
    print(f"{res['runs']} finished runs; table in {res['out']}/decisions.md, .csv, .json")
    return 0


def cmd_videos(args) -> int:
    from ..io.videos import regenerate
    jobs = args.jobs or (1 if args.executor == "local" else 0)     # 0: the executor's default
    return regenerate(preview=args.preview, only=args.only, out_dir=args.out, arch=args.arch,
                      executor=args.executor, jobs=jobs, options=executor_options(args), scale=args.scale,
                      sources=args.sources)


def cmd_bench(args) -> int:
    from ..runtime.backend import BackendError
    from .bench import parse_sizes, throughput
    try:
        sizes = parse_sizes(args.sizes)
    except ValueError as e:
        return _fail(str(e))
    scenes = [n.strip() for n in args.scenes.split(",") if n.strip()]
    for name in scenes:
        Scene.load(name)                   # an unknown scene: one line, exit 2, before anything is measured
    from ..io.outdir import check_out_folder
    check_out_folder(args.out)
    try:
        throughput(args.arch, sizes, scenes, args.steps, max(0, args.warm), args.out, threads=args.threads)
    except BackendError as e:
        return _fail(f"bench: {e} (the benchmark measures the arch it is given; no fallback)")
    return 0


def _catch_ctrl_c() -> None:
    """Ctrl-C (SIGINT) stops a run or a sweep cleanly, even when the process inherited SIGINT ignored: a POSIX
    shell starts a background command (`taichimyxo sweep ... &` in a script) that way, and Python then never raises
    KeyboardInterrupt, so `kill -INT` would be lost (a sweep's own loop relies on KeyboardInterrupt)."""
    import signal
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def main(argv: list[str] | None = None) -> int:
    parser = _build_parser()
    if not (sys.argv[1:] if argv is None else argv):
        parser.print_help(sys.stderr)       # no command: the commands, each with what it does
        return EXIT_BAD_INPUT
    args = parser.parse_args(argv)
    _catch_ctrl_c()
    try:
        if args.cmd == "list":
            return cmd_list()
        if args.cmd == "keys":
            return cmd_keys()
        if args.cmd == "scene":
            return cmd_scene(args)
        if args.cmd == "render":
            return cmd_render(args)
        if args.cmd == "analyze":
            return cmd_analyze(args)
        if args.cmd == "claims":
            return cmd_claims(args)
        if args.cmd == "videos":
            return cmd_videos(args)
        if args.cmd == "decisions":
            return cmd_decisions(args)
        if args.cmd == "sweep":
            return cmd_sweep(args)
        if args.cmd == "bench":
            return cmd_bench(args)
        if args.cmd == "figures":
            return args.figures_main(args, executor_options(args))
        if args.cmd == "tracks":
            from .cli_tracks import main as tracks_main
            return tracks_main(args)
    except (SceneError, TrajectoryError) as e:
        return _fail(str(e))
    except KeyboardInterrupt:
        print("taichimyxo: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader went away (`list | head`): not an error of ours; keep Python from complaining at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return 0
