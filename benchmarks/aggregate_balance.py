"""Why the aggregates of a run turn at the edge speed they do: the torque balance of every rotating aggregate over
the last part of each trajectory (taichimyxo/analysis/aggregate_balance.py), as the chain of factors from the
ideal disk of the rigid-body model (S2 Text) to the measured edge speed.

    python benchmarks/aggregate_balance.py RUN.gsd [RUN.gsd ...] --out benchmarks/results/aggregate_balance.md

Each trajectory must carry particle velocities and use the default guiding reading.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from taichimyxo.analysis import aggregate_balance as ab
from taichimyxo.analysis.aggregates import find_aggregates
from taichimyxo.io.scene import Scene
from taichimyxo.io.schema import SCHEMA
from taichimyxo.io.trajectory import count_frames, read_frames, read_scene

FACTORS = ab.FACTORS


def run_rows(path: Path, start_fraction: float, every: int):
    d = read_scene(str(path))
    if not d:
        raise SystemExit(f"aggregate_balance: {path} holds no taichimyxo scene")
    scene = Scene.from_dict({k: v for k, v in d.items() if k in SCHEMA})      # leaves the fingerprint out
    P = ab.balance_params(scene)
    n = count_frames(str(path))
    rows = []
    for fr in read_frames(str(path), every=every, start=int(start_fraction * n)):
        rows += ab.frame_balances(fr, find_aggregates(fr, v_b=P["v_b"]), P)
    return scene, P, n, rows


def fmt(q):
    return f"{q[0]:.2f} ({q[1]:.2f}–{q[2]:.2f})"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trajectories", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, required=True, help="markdown table to write")
    ap.add_argument("--start-fraction", type=float, default=0.75, help="frames from this fraction of the run on")
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--min-radius", type=float, default=3.0, help="also summarise aggregates of at least this R, µm")
    ap.add_argument("--radius-bins", default="0,3,4,5,7", help="edges of the radius bins of the second table, µm")
    a = ap.parse_args(argv)
    for p in a.trajectories:
        if not p.is_file():
            print(f"aggregate_balance: no trajectory {p}", file=sys.stderr)
            return 2
    try:
        edges = [float(x) for x in a.radius_bins.split(",")] + [float("inf")]
    except ValueError:
        print(f"aggregate_balance: --radius-bins {a.radius_bins!r} is not a comma-separated list of µm",
              file=sys.stderr)
        return 2
    lines = ["# The torque balance of rotating aggregates", "",
             f"`python benchmarks/aggregate_balance.py {' '.join(p.name for p in a.trajectories)} --out "
             f"{a.out.name}` (frames from {a.start_fraction:g} of each run on, every {a.every}). Each factor: median "
             "(quartiles) over aggregate-frames; measured edge / disk = arrangement × outside × rotation × "
             "edge profile, arrangement = profile × alignment (torque) × alignment (drag) × pulls "
             "(taichimyxo/analysis/aggregate_balance.py). Torques outside: summed over aggregate-frames, as a "
             "fraction of the drive, negative where they brake the rotation.", "",
             "| run | aggregates | R | n | edge µm/min | model edge | " + " | ".join(FACTORS[2:])
             + " | adhesion outside / drive | contacts outside / drive |",
             "|" + "---|" * (len(FACTORS) + 6)]
    by_radius = ["", "By radius (medians over the aggregate-frames of each bin; ρ: Spearman rank correlation of "
                 "the edge speed with the alignment across them):", "",
                 "| run | R µm | n | edge µm/min | model edge | " + " | ".join(FACTORS[2:]) + " | ρ |",
                 "|" + "---|" * (len(FACTORS) + 4)]
    for p in a.trajectories:
        scene, P, n, rows = run_rows(p, a.start_fraction, a.every)
        label = (f"{scene.raw['scene']['name']} seed {scene.raw['run']['seed']} ({P['kind']}, ζ_n/ζ_t "
                 f"{P['drag_ratio_normal']:g}{'' if P['self_follow'] else ', no self-following'}, {n} frames)")
        for title, rmin in (("all", 0.0), (f"R ≥ {a.min_radius:g} µm", a.min_radius)):
            s = ab.summarise(rows, rmin)
            if not s["n"]:
                lines.append(f"| {label} | {title} | – | 0 |" + " – |" * (len(FACTORS) + 2))
                continue
            Rs = sorted(r["radius_um"] for r in rows if r["radius_um"] >= rmin)
            lines.append(f"| {label} | {title} | {Rs[0]:.1f}–{Rs[-1]:.1f} | {s['n']} | "
                         + " | ".join(fmt(s[k]) for k in FACTORS)
                         + f" | {s['adhesion_outside_over_drive']:+.3f} | {s['contacts_outside_over_drive']:+.3f} |")
        for lo, hi in zip(edges[:-1], edges[1:]):
            s = ab.summarise(rows, lo, hi)
            if s["n"]:
                by_radius.append(f"| {label} | {lo:g}–{hi:g} | {s['n']} | "
                                 + " | ".join(f"{s[k][0]:.0f}" if k == "bend_deg" else f"{s[k][0]:.2f}"
                                              for k in FACTORS)
                                 + f" | {s['rho_edge_alignment']:+.2f} |")
    lines += by_radius
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
