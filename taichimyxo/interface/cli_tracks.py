"""`python -m taichimyxo tracks FILE [--pixel-um X] [--frame-s S] [--time-unit s|min|frame] [--v-b V]
[--against DIR ...] [--out DIR]`: a lab's cell tracks measured the way the simulations are, and compared with
simulated runs of each guiding mechanism (taichimyxo.interface.tracks_api)."""
from __future__ import annotations

import sys


def add_parser(sub) -> None:
    t = sub.add_parser("tracks", help="a lab's cell tracks (TrackMate CSV/XML, or a CSV of track, time, x, y): the "
                                      "measures, and which guiding mechanism they match (docs/measures.md)")
    t.add_argument("file", help="TrackMate's spots table (.csv) or XML (.xml), a CSV with columns track, time, x, "
                                "y, or a simulated run (.gsd)")
    t.add_argument("--pixel-um", type=float, default=None, help="µm per pixel, when positions are in pixels")
    t.add_argument("--frame-s", type=float, default=None, help="frame interval, s (default: the median time step)")
    t.add_argument("--time-unit", default="s", choices=["s", "min", "frame"], help="unit of the time column")
    t.add_argument("--v-b", type=float, default=None, help="the cells' free speed, µm/min (default: speeds in "
                                                           "units of the median speed outside rotating groups)")
    t.add_argument("--against", action="append", default=[], metavar="DIR",
                   help="simulated runs to compare with: a folder of runs (e.g. from `sweep sweeps/mechanisms.toml`) "
                        "or a .gsd; repeatable; each run's mechanism is read from its scene")
    t.add_argument("--max-gap-frames", type=int, default=2, help="frames a track may miss before it is split")
    t.add_argument("--max-speed", type=float, default=30.0, help="µm/min; a faster step is an identity swap and "
                                                                 "splits the track")
    t.add_argument("--boot", type=int, default=500, help="bootstrap replicates (default 500)")
    t.add_argument("--out", default=".", help="folder for tracks.json and report.md/.json/.png (default: here)")
    t.add_argument("--no-plots", action="store_true")


def main(args) -> int:
    from .tracks_api import tracks_report
    res = tracks_report(args.file, pixel_um=args.pixel_um, frame_s=args.frame_s, time_unit=args.time_unit,
                        v_b=args.v_b, against=args.against, out_dir=args.out, n_boot=args.boot,
                        plots=not args.no_plots, max_gap_frames=args.max_gap_frames,
                        max_speed_um_per_min=args.max_speed, progress=lambda m: print(m, file=sys.stderr))
    g = res["measures"]["groups"]
    c = res["measures"]["counts"]
    print(f"{c['tracks_kept']} tracks kept of {c['tracks_read']} read ({c['split_at_gaps']} split at gaps, "
          f"{c['split_at_jumps']} at jumps, {c['pieces_too_short']} pieces too short, "
          f"{c.get('spots_without_track', 0)} spots without a track)")
    print(f"rotating groups: {g['groups_per_frame']:.2f} per frame, {g['fraction_in_groups']:.0%} of points; speed "
          f"in groups {g['speed_in_median_vref']:.2f}, edge {g['edge_speed_median_vref']:.2f}, outside "
          f"{g['speed_out_median_vref']:.2f} x v_ref ({g['v_ref_um_per_min']:.2f} µm/min)")
    if "report" in res:
        from ..analysis.mechanism_report import sentence
        print(sentence(res["report"]))
    print("".join(f"wrote {p}\n" for p in res["files"]), end="")
    return 0
