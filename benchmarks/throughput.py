"""Throughput: first the states users' runs spend their time in (benchmarks/states.py: S3 after one simulated hour
at paper scale and S13 dense, beside S3's start) with the full 6 h S3 each projects; then particle-steps per second
per scene and size, measured in one run, with the cost of each effect as a ratio to the non-guided scene (S1) on the
same start.

    python benchmarks/throughput.py [--quick] [--out DIR]

Writes states.csv, throughput.csv (throughput_quick.csv with --quick) and a .txt naming the machine into the output
folder
(default benchmarks-results/ in the current directory) and prints a table. Rates, never timed asserts: these
machines are shared and noisy; ratios within one run are what to compare. The measuring itself is the package's
(taichimyxo/interface/bench.py, also `python -m taichimyxo bench throughput`: S1, S3, S11 at 1x, 4x, 16x the paper's
area, on the CPU or a GPU, with the projected wall time of a full 6 h S3).
"""
from __future__ import annotations

import os
import platform
import time
from pathlib import Path

from benchlib import DEFAULT_OUT, parser, write_csv

# (scene, what it adds over S1)
SCENES = [
    ("S1", "baseline: springs, bending, engine, contacts"),
    ("S2", "passive following"),
    ("S3", "active following"),
    ("S4", "adhesion"),
    ("S15", "active following + reversals + suppression"),
    ("S17", "slime trails"),
    ("S11", "high density, aligned (k_c = 0.002 N/m)"),
]


def measure(name: str, scale: float, n_steps: int, warm: int, precision: str | None = None,
            integrator: str | None = None) -> dict:
    """One row: taichimyxo.interface.bench.measure at `scale` times the scene's side (its area times scale^2)."""
    from taichimyxo.interface.bench import measure as package_measure
    run = {k: v for k, v in (("precision", precision), ("integrator", integrator)) if v}
    row = package_measure(name, scale * scale, n_steps, warm, run or None)
    row["scale"] = scale
    return row


def main(quick: bool = False, out_dir: str = DEFAULT_OUT) -> list[dict]:
    from states import measure as measure_states
    from taichimyxo.runtime import backend
    backend.init("cpu")
    rows = []
    sizes = [1.0] if quick else [1.0, 0.5, 0.25]
    n_steps = 500 if quick else 2000
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    states = measure_states(n_steps, warm=200)
    for r in states:
        print(f"{r['state']:>10} {r['particles']:>6} particles {r['ms_per_step']:7.3f} ms/step at {r['dt_ms']:g} ms "
              f"{r['particle_steps_per_s'] / 1e6:6.2f} M particle-steps/s: a full 6 h S3 in "
              f"{r['full_S3_6h_wall_h']:.2f} h", flush=True)
    write_csv(out / ("states_quick.csv" if quick else "states.csv"), states)
    for scale in sizes:
        base = None
        for name, what in SCENES:
            if quick and name not in ("S1", "S3", "S17"):
                continue
            r = measure(name, scale, n_steps if scale == 1.0 else n_steps * 4, warm=200)
            r["adds"] = what
            if name == "S1":
                base = r["steps_per_s"]
            r["cost_vs_S1"] = round(base / r["steps_per_s"], 3) if base and name != "S11" else ""
            rows.append(r)
            print(f"{name:>4} x{scale:<5} {r['cells']:>5} cells {r['particles']:>6} particles "
                  f"{r['steps_per_s']:>8.0f} steps/s {r['particle_steps_per_s'] / 1e6:6.2f} M particle-steps/s "
                  f"cost vs S1 {r['cost_vs_S1'] or '-':>6}  ({what})", flush=True)
    if not quick:
        for prec in ("f32", "f64"):
            r = measure("S1", 1.0, n_steps, warm=200, precision=prec)
            r["adds"] = f"S1 in {prec}"
            r["cost_vs_S1"] = round(rows[0]["steps_per_s"] / r["steps_per_s"], 3)
            rows.append(r)
            print(f"  S1 {prec}: {r['particle_steps_per_s'] / 1e6:6.2f} M particle-steps/s, cost vs mixed "
                  f"{r['cost_vs_S1']}", flush=True)
    path = out / ("throughput_quick.csv" if quick else "throughput.csv")
    write_csv(path, rows)
    with open(path.with_suffix(".txt"), "w") as f:
        f.write(f"machine: {platform.machine()} {os.cpu_count()} cores, {platform.python_version()}, "
                f"{time.strftime('%Y-%m-%d %H:%M')}\n")
    print(f"wrote {path}")
    return rows


def build_parser():
    return parser(__doc__, "S1, S3, S17 at full size only, 500 steps each (a few minutes)")


if __name__ == "__main__":
    a = build_parser().parse_args()
    main(quick=a.quick, out_dir=a.out)
