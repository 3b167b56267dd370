"""The neighbour-list skin: cost per step, rebuilds included, for a few skins on a guided scene from its start (fast
heads, many rebuilds) and on a dense one (many partners), in one run.

    python benchmarks/skin.py [--quick] [--out DIR] [--skins 0.1,0.2,0.3,0.45]

A wider skin lists more pairs (more work per step, more memory); a narrower one rebuilds more often (a build costs
several steps). Writes skin.csv into the output folder and prints ms/step, rebuilds per 1000 steps and mean listed
partners per segment. Rates, never timed asserts.
"""
from __future__ import annotations

from benchlib import parser, time_steps, write_csv


def measure(name: str, skin: float, scale: float, steps: int, warm: int) -> dict:
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime.simulation import Simulation
    over = {"output": {"movie": False}, "run": {"skin_um": skin}}
    if scale != 1.0:
        sc0 = Scene.load(name)
        over["domain"] = {"width_um": sc0.box[0] * scale, "height_um": sc0.box[1] * scale}
        if sc0.raw["population"]["cells"]:
            over["population"] = {"cells": max(1, round(sc0.n_cells * scale * scale))}
    sc = Scene.load(name, over)
    sim = Simulation(sc)
    t = time_steps(sim, steps, warm)
    partners = float(sim.neighbours.nbr_n.to_numpy().mean())
    row = {"scene": name, "scale": scale, "particles": sim.n_p, "skin_um": skin, "steps": steps,
           "ms_per_step": t["ms_per_step"], "rebuilds_per_1000_steps": round(1e3 * t["rebuilds"] / steps, 2),
           "partners_per_segment": round(partners, 2), "list_capacity": sim.neighbours.max_nbrs}
    sim.close()
    return row


def main() -> None:
    p = parser(__doc__)
    p.add_argument("--skins", default="0.1,0.2,0.3,0.45")
    p.add_argument("--scenes", default="S3,S11")
    a = p.parse_args()
    from taichimyxo.runtime import backend
    backend.init("cpu")
    scale, steps = (0.5, 500) if a.quick else (1.0, 2000)
    rows = []
    for name in a.scenes.split(","):
        for skin in (float(x) for x in a.skins.split(",")):
            rows.append(measure(name, skin, scale, steps, warm=50))
            r = rows[-1]
            print(f"{name} skin {skin:.2f} µm: {r['ms_per_step']:.3f} ms/step, {r['rebuilds_per_1000_steps']} "
                  f"rebuilds per 1000 steps, {r['partners_per_segment']} partners per segment", flush=True)
    from pathlib import Path
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / ("skin_quick.csv" if a.quick else "skin.csv"), rows)
    print(f"written {out}")


if __name__ == "__main__":
    main()
