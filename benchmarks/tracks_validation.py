"""Tracks validation: the mechanism report (taichimyxo/analysis/mechanism_report.py) on tracks made from simulated
runs whose mechanism is known, degraded the way a microscope and a tracker degrade them (centroids only, a longer
frame interval, position noise, missed detections, identity swaps: analysis.lab_tracks.degrade). Each run in turn is
the "measured" one, against the other runs of every mechanism (leave one out); the table gives, per degradation and
level, how often the report names the right mechanism, names a wrong one, or cannot tell; with the free speed v_b
given (a lab that measured isolated cells) and read from the tracks' straight gliders.

    python -m taichimyxo sweep sweeps/mechanisms.toml --out REFS          # 12 runs, ~40 min of 2 cores
    python benchmarks/tracks_validation.py REFS --out benchmarks/results  # a few minutes

Writes tracks_validation.md and .json into --out.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from benchlib import parser

# each row changes one degradation of the base to one of its levels
BASE = dict(frame_s=60.0, noise_um=0.2, missed=0.05, swaps_per_track_hour=0.5)
LEVELS = {"frame_s": [30.0, 120.0, 240.0], "noise_um": [0.0, 0.5, 1.0], "missed": [0.0, 0.2, 0.4],
          "swaps_per_track_hour": [0.0, 2.0, 8.0]}


def main(argv=None) -> int:
    p = parser(__doc__, "the base degradation only, 100 bootstrap replicates")
    p.add_argument("refs", nargs="+", help="folders of simulated runs (sweeps/mechanisms.toml's --out) or .gsd files")
    p.add_argument("--boot", type=int, default=200)
    a = p.parse_args(argv)
    from taichimyxo.analysis.lab_tracks import degrade
    from taichimyxo.analysis.mechanism_report import compare, in_group_speeds
    from taichimyxo.interface.tracks_api import find_runs, tracks_from_run
    from taichimyxo.io.trajectory import read_scene
    runs = find_runs(a.refs)
    mechs = sorted({m for m, _ in runs})
    if len(mechs) < 2:
        print(f"tracks_validation: runs of at least two mechanisms needed; found {mechs}", file=sys.stderr)
        return 2
    t0 = time.time()
    tracks = [tracks_from_run(f) for _, f in runs]
    vbs = [float(read_scene(f).get("cell", {}).get("speed_um_per_min", 4.0)) for _, f in runs]
    levels = {"base": [None]} if a.quick else {"base": [None], **LEVELS}
    boot = 100 if a.quick else a.boot
    ref_cache: dict = {}

    def ref_measure(i, frame_s):
        key = (i, frame_s)
        if key not in ref_cache:
            ref_cache[key] = in_group_speeds(tracks[i], frame_s=frame_s, v_b=vbs[i])
        return ref_cache[key]

    rows = []
    for what, values in levels.items():
        for val in values:
            deg = dict(BASE) if what == "base" else {**BASE, what: val}
            for mode in ("v_b given", "v_b from the tracks"):
                tally = {m: {"right": 0, "wrong": 0, "cannot tell": 0} for m in mechs}
                for i, (truth, _) in enumerate(runs):
                    meas_tr = degrade(tracks[i], seed=1000 + i, **deg)
                    meas = in_group_speeds(meas_tr, v_b=vbs[i] if mode == "v_b given" else None)
                    refs = {m: [ref_measure(j, deg["frame_s"]) for j, (mj, _) in enumerate(runs)
                                if mj == m and j != i] for m in mechs}
                    res = compare(meas, refs, n_boot=boot, seed=i)
                    got = "cannot tell" if res["strength"] == "none" else ("right" if res["nearest"] == truth
                                                                          else "wrong")
                    tally[truth][got] += 1
                rows.append({"degradation": what, "level": val, **{k: v for k, v in deg.items()}, "mode": mode,
                             "tally": tally})
                print(f"{what} {val} {mode}: " + "; ".join(f"{m} {t['right']}/{sum(t.values())}"
                                                          for m, t in tally.items()), file=sys.stderr)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    counts = {m: sum(1 for mm, _ in runs if mm == m) for m in mechs}
    meta = {"runs": counts, "base": BASE, "boot": boot, "seconds": round(time.time() - t0, 1)}
    (out / "tracks_validation.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    lines = ["# Tracks validation: the mechanism report on degraded simulated tracks", "",
             f"Runs per mechanism: {', '.join(f'{m} {n}' for m, n in counts.items())}; each the measured one in "
             f"turn against the others (leave one out). Base degradation: frame {BASE['frame_s']:g} s, noise "
             f"{BASE['noise_um']:g} µm, {BASE['missed']:.0%} detections missed, {BASE['swaps_per_track_hour']:g} "
             f"identity swaps per track-hour; each row changes one of them. {boot} bootstrap replicates. Cell: "
             "right / wrong / cannot tell over the runs of that mechanism.", "",
             "| degradation | level | v_b | " + " | ".join(mechs) + " |", "|---|---|---|" + "---|" * len(mechs)]
    for r in rows:
        cells = [f"{t['right']} / {t['wrong']} / {t['cannot tell']}" for t in (r["tally"][m] for m in mechs)]
        level = "" if r["level"] is None else f"{r['level']:g}"
        mode = "given" if r["mode"] == "v_b given" else "from tracks"
        lines.append(f"| {r['degradation']} | {level} | {mode} | " + " | ".join(cells) + " |")
    lines += ["", f"Made in {meta['seconds']:.0f} s by `python benchmarks/tracks_validation.py REFS`, REFS the runs of "
              "`python -m taichimyxo sweep sweeps/mechanisms.toml --out REFS`."]
    (out / "tracks_validation.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
