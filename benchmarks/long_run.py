"""Long run: 30 simulated minutes of an S13-like high-density population keep every invariant.

S13 is the paper's hardest default scene for the integrator: aligned start at area fraction 1 (4e7 cells/cm²),
soft contacts k_c = 0.002 N/m, flexible cells with active following. Here on a reduced periodic box (15 x 15 µm,
90 cells, by default: 20 x 20 µm runs at ~1400 steps/s on 2 cores, 21 min for the 1.8 M steps; 15 x 15 takes
~13 min) at the default step. Every `--sample-s` simulated seconds the script measures, over one
speed window (1 s), the invariants of taichimyxo.physics.invariants (finite positions, segment lengths within +-20 % of
l0, particle and cell-centre speeds, closest approach of segments of different cells, spring / bending / contact
energies), prints one line, and at the end writes long_run.csv (into benchmarks-results/ in the current directory
unless --out names a folder: `--out benchmarks/results` updates the committed result) and checks the bounds.

    python benchmarks/long_run.py                    # 30 simulated min on 15 x 15 µm, ~13 min of wall time
    python benchmarks/long_run.py --minutes 30 --box 20
    python benchmarks/long_run.py --quick            # 1 simulated min: that it runs and writes its file

Exit status 0 when every invariant held, 1 otherwise.
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import re
import sys
import time
from pathlib import Path

from benchlib import DEFAULT_OUT

COLUMNS = ["t_min", "step", "len_min", "len_max", "speed_max_vb", "centre_speed_max_vb", "d_other_min_W",
           "d_self_min_W", "e_spring_pN_um", "e_bend_pN_um", "e_contact_pN_um", "wall_s"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="S13", help="scene to run (default S13)")
    ap.add_argument("--minutes", type=float, default=30.0, help="simulated minutes (default 30)")
    ap.add_argument("--box", type=float, default=15.0, help="side of the periodic box, µm (default 15)")
    ap.add_argument("--sample-s", type=float, default=10.0, help="simulated seconds between samples (default 10)")
    ap.add_argument("--dt-ms", type=float, default=0.0, help="time step, ms (default: the scene's)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--quick", action="store_true", help="1 simulated minute, samples every 10 s (overrides --minutes)")
    ap.add_argument("--out", default=DEFAULT_OUT,
                    help=f"folder for long_run.csv (default {DEFAULT_OUT}/ in the current directory; a path ending in "
                         ".csv names the file itself)")
    args = ap.parse_args(argv)
    if args.quick:
        args.minutes = 1.0

    from taichimyxo.io.scene import Scene, SceneError
    from taichimyxo.physics.invariants import Bounds, InvariantMonitor
    from taichimyxo.runtime import backend
    from taichimyxo.runtime.simulation import Simulation

    over = {"domain": {"width_um": args.box, "height_um": args.box}, "output": {"movie": False},
            "run": {"hours": args.minutes / 60.0, "seed": args.seed}}
    if args.dt_ms:
        over["run"]["dt_ms"] = args.dt_ms
    try:
        sc = Scene.load(args.scene, over)
    except SceneError as e:
        print(f"long_run: error: {e}", file=sys.stderr)
        return 2
    backend.init("cpu", args.threads)
    t_setup = time.perf_counter()
    sim = Simulation(sc)
    bounds = Bounds.for_scene(sc)
    mon = InvariantMonitor(sim, bounds)
    window = mon.default_window()
    every = max(window, int(round(args.sample_s / sc.dt)))
    total = sc.steps
    print(f"{sc.name} on {args.box:g} x {args.box:g} µm: {sc.n_cells} cells, start {sc.start}, guiding {sc.guiding}, "
          f"k_a {sc.raw['cell']['k_a_N_m']:g} N·m, k_c {sc.raw['collisions']['k_c_N_per_m']:g} N/m, "
          f"dt {sc.dt * 1e3:g} ms, {total} steps ({args.minutes:g} min); sample every {every} steps over "
          f"{window}-step windows", flush=True)
    print(f"bounds: length 1 +- {bounds.length_tol}, particle speed <= {bounds.speed_factor:.3g} v_b, centre speed <= "
          f"{bounds.centre_speed_factor:.3g} v_b, segment distance >= {bounds.min_distance_W} W, energy late <= "
          f"{bounds.energy_growth} x early + {bounds.energy_floor_pN_um_per_cell} pN·µm per cell", flush=True)
    mon.sample(measure_only=True)
    print(f"setup (placement, compile) {time.perf_counter() - t_setup:.1f} s", flush=True)
    hdr = (f"{'t/min':>6} {'len min..max /l0':>17} {'v_p/v_b':>8} {'v_c/v_b':>8} {'d_min/W':>8} {'self/W':>7} "
           f"{'E_spr':>8} {'E_bend':>8} {'E_cont':>8} {'steps/s':>8}")
    print(hdr, flush=True)
    wall0 = time.perf_counter()
    rows = []

    def row(r):
        d = {"t_min": r["t_s"] / 60.0, "step": r["step"], "len_min": r["len_min"], "len_max": r["len_max"],
             "speed_max_vb": r["speed_max_vb"], "centre_speed_max_vb": r["centre_speed_max_vb"],
             "d_other_min_W": r["d_other_min"], "d_self_min_W": r["d_self_min"], "e_spring_pN_um": r["e_spring"],
             "e_bend_pN_um": r["e_bend"], "e_contact_pN_um": r["e_contact"], "wall_s": time.perf_counter() - wall0}
        rows.append(d)
        rate = r["step"] / max(d["wall_s"], 1e-9)
        print(f"{d['t_min']:6.2f} {d['len_min']:8.4f}..{d['len_max']:7.4f} {d['speed_max_vb']:8.2f} "
              f"{d['centre_speed_max_vb']:8.2f} {d['d_other_min_W']:8.3f} {d['d_self_min_W']:7.3f} "
              f"{d['e_spring_pN_um']:8.2f} {d['e_bend_pN_um']:8.1f} {d['e_contact_pN_um']:8.1f} {rate:8.0f}",
              flush=True)

    row(mon.records[0])
    while sim.step_count < total:
        nxt = min(total, sim.step_count + every)
        sim.advance(max(0, nxt - window - sim.step_count))
        r = mon.sample(nxt - sim.step_count)
        row(r)
        if not r["finite"]:
            break
    wall = time.perf_counter() - wall0

    out = Path(args.out) if args.out.endswith(".csv") else Path(args.out) / "long_run.csv"
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        for d in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in d.items()})

    bad = mon.violations()
    fin = [r for r in mon.records if r["finite"]]

    def mx(key):
        v = [r[key] for r in fin if not math.isnan(r[key])]
        return max(v) if v else float("nan")

    print(f"\n{sim.step_count} steps in {wall:.0f} s wall ({sim.step_count / max(wall, 1e-9):.0f} steps/s, "
          f"{sim.step_count * sim.n_p / max(wall, 1e-9) / 1e6:.2f} M particle-steps/s, "
          f"{sim.rebuilds} neighbour rebuilds)")
    print(f"over {len(fin)} samples: segment length {min(r['len_min'] for r in fin):.4f}..{mx('len_max'):.4f} l0; "
          f"particle speed <= {mx('speed_max_vb'):.2f} v_b; cell centre speed <= {mx('centre_speed_max_vb'):.2f} v_b; "
          f"closest segments of different cells {min(r['d_other_min'] for r in fin):.3f} W, of one cell "
          f"{min(r['d_self_min'] for r in fin):.3f} W; spring energy <= {mx('e_spring'):.3g}, bending <= "
          f"{mx('e_bend'):.3g}, contact <= {mx('e_contact'):.3g} pN·µm")
    print(f"wrote {os.path.relpath(out)}")          # the log is committed: no machine path in it
    sim.close()
    if bad:
        kinds = {}
        for b in bad:
            k = re.sub(r"\d[\d.e+-]*", "#", b.split(": ", 1)[-1] if b.startswith("t=") else b)
            kinds.setdefault(k, []).append(b)
        print(f"{len(bad)} invariant violation(s) in {len(mon.records) - 1} samples:")
        for k, v in kinds.items():
            print(f"  {len(v)} x {k}; first: {v[0]}")
        return 1
    print("every invariant held")
    return 0


if __name__ == "__main__":
    sys.exit(main())
