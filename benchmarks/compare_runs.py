"""Compare the last frames of two runs of the same scene and seed (e.g. before and after a physics change).

    python benchmarks/compare_runs.py BEFORE.gsd AFTER.gsd [--png out.png] [--labels before,after]

Prints, for each run's last frame: cells in clusters (cells within W + 0.1 µm of each other), clusters of 10 or more
cells and their mean size, rotating aggregates found by `analyze`'s detector (taichimyxo.analysis.find_aggregates),
packing (contacts per cell and mean overlap W - D of the contact law's samples, docs/model.md term 4) and speeds
(mean, 95th percentile, fraction of cells faster than 1.5 v_b). With --png, the two last frames side by side as
rendered by the movie renderer. Nothing here is a test; it is how the note of a physics change shows what changed.
"""
from __future__ import annotations

import argparse
import json

import numpy as np


def frame_stats(fr, v_b: float = 4.0) -> dict:
    from taichimyxo.analysis import cell_clusters, find_aggregates
    from taichimyxo.physics.geometry import sample_polyline_contacts

    pos = fr.positions
    n = len(pos)
    _, sizes, _, _ = cell_clusters(pos, fr.box, fr.width_um)
    big = sizes[sizes >= 10]
    aggs = find_aggregates(fr, v_b=v_b)
    d = sample_polyline_contacts(pos, fr.box, fr.width_um)[3]
    cell_speed = fr.particle_speed.mean(axis=1)
    return {
        "cells": n,
        "time_h": fr.time_s / 3600.0,
        "cells_in_clusters_ge2_pct": 100.0 * sizes[sizes >= 2].sum() / n,
        "clusters_ge10": int(len(big)),
        "mean_cluster_size_ge10": float(big.mean()) if len(big) else 0.0,
        "largest_cluster": int(sizes.max()),
        "rotating_aggregates": len(aggs),
        "cells_in_aggregates_pct": 100.0 * sum(a["n_cells"] for a in aggs) / n,
        "aggregate_radii_um": [round(float(a["radius_um"]), 1) for a in aggs],
        "contacts_per_cell": len(d) / n,
        "mean_overlap_um": float((fr.width_um - d).mean()) if len(d) else 0.0,
        "speed_mean_um_min": float(cell_speed.mean()),
        "speed_p95_um_min": float(np.percentile(fr.particle_speed, 95)),
        "cells_faster_1p5vb_pct": 100.0 * float((cell_speed > 1.5 * v_b).mean()),
    }


def last_frame(path: str):
    from taichimyxo.io.trajectory import read_frames
    fr = None
    for fr in read_frames(path):
        pass
    if fr is None:
        raise SystemExit(f"{path}: no frames")
    return fr


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs=2)
    ap.add_argument("--png")
    ap.add_argument("--labels", default="before,after")
    a = ap.parse_args(argv)
    labels = a.labels.split(",")
    frames = [last_frame(p) for p in a.runs]
    stats = {lab: frame_stats(fr) for lab, fr in zip(labels, frames)}
    keys = list(next(iter(stats.values())).keys())
    w = max(len(k) for k in keys)
    print(f"{'':{w}}  " + "  ".join(f"{lab:>22}" for lab in labels))
    for k in keys:
        vals = [stats[lab][k] for lab in labels]
        def fmt(v):
            return (f"{v:22.3g}" if isinstance(v, float) else f"{str(v):>22}")
        print(f"{k:{w}}  " + "  ".join(fmt(v) for v in vals))
    if a.png:
        import imageio.v3 as iio

        from taichimyxo.render import render_frame
        imgs = [render_frame(fr, size=(1000, 1000)) for fr in frames]
        iio.imwrite(a.png, np.concatenate(imgs, axis=1))
        print(f"wrote {a.png}")
        with open(a.png.rsplit(".", 1)[0] + ".json", "w") as f:
            json.dump(stats, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
