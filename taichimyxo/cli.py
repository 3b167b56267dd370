"""Command line: python -m taichimyxo {list, keys, scene, render, analyze, videos, bench}.

Bad input is one line on stderr naming the problem and a non-zero exit (2), before any simulation starts."""
from __future__ import annotations

import argparse
import os
import sys

from .scene import SCHEMA, Scene, SceneError, available_scenes, parse_set, resolve_path

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


def _fail(msg: str) -> int:
    print(f"taichimyxo: error: {msg}", file=sys.stderr)
    return EXIT_BAD_INPUT


class _Parser(argparse.ArgumentParser):
    def error(self, message):          # one line, exit 2
        print(f"taichimyxo: error: {message}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


ARCHES = ("cpu", "cuda", "vulkan", "metal", "gpu")       # as backend.init accepts them


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"{v} must be at least 1")
    return v


def _build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m taichimyxo", description="Myxobacteria guiding simulator (Taichi).")
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=_Parser)

    sub.add_parser("list", help="list the scenes, one line each")
    sub.add_parser("keys", help="list every scene key with its default and meaning")

    s = sub.add_parser("scene", help="run a scene (name like S3, or a path to a TOML file)")
    s.add_argument("scene")
    s.add_argument("--hours", type=float, help="simulated hours (overrides run.hours)")
    s.add_argument("--preview", action="store_true", help="small, short version (about a minute on 2 cores)")
    s.add_argument("--out", default="videos", help="output folder (default videos/)")
    s.add_argument("--seed", type=int, help="random seed (overrides run.seed)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override any scene key by its dotted name, e.g. --set guiding.kind=active")
    s.add_argument("--arch", default="cpu", choices=ARCHES,
                   help="cpu (default), cuda, vulkan, metal, gpu; unavailable GPUs fall back to cpu")
    s.add_argument("--threads", type=_positive_int, help="CPU threads (default: all cores)")
    s.add_argument("--resume", action="store_true", help="continue an interrupted run from its checkpoint")
    s.add_argument("--force", action="store_true", help="run even if the time step exceeds the stability limit")
    s.add_argument("--no-movie", action="store_true", help="trajectory and summary only")
    s.add_argument("--fps", type=float, help="movie frames per second")
    s.add_argument("--size", help="movie size WxH, e.g. 1280x720")
    s.add_argument("--frame-minutes", type=float, help="simulated minutes between frames")
    s.add_argument("--quiet", action="store_true", help="no progress bar")

    r = sub.add_parser("render", help="render a trajectory (.gsd) to a movie without simulating")
    r.add_argument("trajectory")
    r.add_argument("--color", choices=["speed", "strain"], default="speed")
    r.add_argument("--out", help="output .mp4 (default: next to the trajectory)")
    r.add_argument("--fps", type=float, default=10.0)
    r.add_argument("--size", default="1920x1080")
    r.add_argument("--every", type=int, default=1, help="render every K-th frame")

    a = sub.add_parser("analyze", help="aggregates, rotation and speed profiles from a trajectory")
    a.add_argument("trajectory")
    a.add_argument("--out", help="output folder (default: next to the trajectory)")
    a.add_argument("--every", type=int, default=1)

    v = sub.add_parser("videos", help="regenerate the supplementary videos S1-S17")
    v.add_argument("--preview", action="store_true")
    v.add_argument("--only", help="comma-separated scene names, e.g. S3,S8")
    v.add_argument("--out", default="videos")
    v.add_argument("--arch", default="cpu", choices=ARCHES)

    b = sub.add_parser("bench", help="benchmarks: throughput, accuracy, stability")
    b.add_argument("which", choices=["throughput", "accuracy", "stability"])
    b.add_argument("--quick", action="store_true", help="a reduced version (minutes)")
    b.add_argument("--out", default="benchmarks/results")
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
    from .stability import check_step
    check_step(sc, force=getattr(args, "force", False))
    return sc


def cmd_list() -> int:
    for name in available_scenes():
        try:
            sc = Scene.load(name)
            fig = f" [{sc.raw['scene']['paper_figure']}]" if sc.raw["scene"]["paper_figure"] else ""
            print(f"{name:<12} {sc.raw['scene']['title']}{fig}")
        except SceneError as e:
            print(f"{name:<12} (invalid: {e})")
    return 0


def cmd_keys() -> int:
    for sec, keys in SCHEMA.items():
        print(f"[{sec}]")
        for k, (typ, default, check, doc) in keys.items():
            print(f"  {sec}.{k} = {default!r:<12} {doc}")
    return 0


def cmd_scene(args) -> int:
    from .run import run_scene
    sc = load_scene_from_args(args)
    summary = run_scene(sc, out_dir=args.out, arch=args.arch, resume=args.resume, progress=not args.quiet,
                        threads=args.threads)
    if summary.get("status") == "interrupted":
        print(f"taichimyxo: {sc.name} interrupted at {summary['simulated_seconds'] / 3600:.3f} h; files closed, "
              f"checkpoint {summary['files'].get('checkpoint')}; continue with --resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    _print_summary(summary, args.out)
    return 0


def _print_summary(summary: dict, out: str) -> None:
    if "particle_steps_per_second" in summary:
        print(f"{summary['scene']}: {summary['cells']} cells, {summary['steps']} steps "
              f"({summary['simulated_seconds'] / 3600:.2f} h simulated) in {summary['wall_seconds']:.1f} s wall, "
              f"{summary['particle_steps_per_second'] / 1e6:.1f} M particle-steps/s")
    else:
        print(f"{summary['scene']}: {summary['status']} {summary.get('source_trajectory', '')}")
    for k, f in summary.get("files", {}).items():
        print(f"  {os.path.join(out, f)}")


def cmd_render(args) -> int:
    if not os.path.isfile(args.trajectory):
        return _fail(f"trajectory {args.trajectory} not found")
    from .render import render_trajectory
    out = args.out or os.path.splitext(args.trajectory)[0] + (".strain" if args.color == "strain" else "") + ".mp4"
    from .run import check_output_dir
    check_output_dir(os.path.dirname(os.path.abspath(out)))
    png = os.path.splitext(out)[0] + ".png"
    n = render_trajectory(args.trajectory, out, color=args.color, size=_size(args.size), fps=args.fps,
                          every=args.every, png_path=png)
    print(f"{out}: {n} frames; last frame {png}")
    return 0


def cmd_analyze(args) -> int:
    if not os.path.isfile(args.trajectory):
        return _fail(f"trajectory {args.trajectory} not found")
    from .analysis import analyze, format_summary
    summary = analyze(args.trajectory, out_dir=args.out, every=args.every)
    print(format_summary(summary))
    return 0


def cmd_videos(args) -> int:
    from .videos import regenerate
    return regenerate(preview=args.preview, only=args.only, out_dir=args.out, arch=args.arch)


def cmd_bench(args) -> int:
    from . import bench
    return bench.main(args.which, quick=args.quick, out_dir=args.out)


def main(argv: list[str] | None = None) -> int:
    args = _build_parser().parse_args(argv)
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
        if args.cmd == "videos":
            return cmd_videos(args)
        if args.cmd == "bench":
            return cmd_bench(args)
    except SceneError as e:
        return _fail(str(e))
    except KeyboardInterrupt:
        print("taichimyxo: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    return 0
