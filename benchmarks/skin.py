"""The neighbour-list skin: cost per step, rebuilds included, for a few skins on a guided scene from its start (fast
heads, many rebuilds) and on a dense one (many partners), in one run; or, with --state, from a benchmark state.

    python benchmarks/skin.py [--quick] [--out DIR] [--skins 0.1,0.2,0.3,0.45]
    python benchmarks/skin.py --state "S3 6 h" [--skins 0.05,0.1,0.15,0.2,0.3] [--rounds 3] [--threads 2]

A wider skin lists more pairs (more work per step, more memory); a narrower one rebuilds more often (a build costs
several steps). Writes skin.csv (skin_<state>.csv with --state) into the output folder and prints ms/step, rebuilds
per 1000 steps and mean listed partners per segment. With --state each (round, skin) is its own process (one
Simulation per process), the skins alternating within each round so a drifting machine weighs on all alike; the
state is where a run spends its late hours (benchmarks/states.py). Rates, never timed asserts.
"""
from __future__ import annotations

import os
import sys

from benchlib import HERE, json_from_worker, parser, time_steps, write_csv

STATE_WORKER = r"""
import json, sys
sys.path.insert(0, sys.argv[1])
from taichimyxo.runtime import backend
backend.init("cpu", int(sys.argv[4]))
from taichimyxo.interface.bench import scaled_scene, time_steps
from taichimyxo.runtime.simulation import Simulation
import states
scene, area, start = states.load(sys.argv[2])
sc = scaled_scene(scene, area, {**states.STATE_RUN.get(sys.argv[2], {}), "skin_um": float(sys.argv[3])})
sim = Simulation.from_positions(sc, start[0], start[1])
t = time_steps(sim, int(sys.argv[5]), 200)
print(json.dumps({**t, "partners_per_segment": round(float(sim.neighbours.nbr_n.to_numpy().mean()), 3),
                  "list_capacity": sim.neighbours.max_nbrs, "dt_ms": sc.dt * 1e3}))
"""


def measure_state(state: str, skin: float, steps: int, threads: int) -> dict:
    """One (state, skin) in its own process: ms/step over `steps` steps after 200 (compiling, the first builds)."""
    r = json_from_worker([sys.executable, "-c", STATE_WORKER, str(HERE), state, str(skin), str(threads), str(steps)],
                         timeout=3600)
    if "error" in r:
        raise SystemExit(f"skin: the worker for {state!r} at skin {skin} failed: {r['error']}")
    return {"state": state, "skin_um": skin, "threads": threads, "steps": steps, "ms_per_step": r["ms_per_step"],
            "rebuilds_per_1000_steps": round(1e3 * r["rebuilds"] / steps, 2),
            "partners_per_segment": r["partners_per_segment"], "list_capacity": r["list_capacity"],
            "particles": r["particles"], "dt_ms": r["dt_ms"]}


def by_state(a) -> None:
    rows = []
    skins = [float(x) for x in a.skins.split(",")]
    for rnd in range(a.rounds):
        for skin in skins:
            r = {"round": rnd, **measure_state(a.state, skin, a.steps or 1000, a.threads)}
            rows.append(r)
            print(f"round {rnd} {a.state} skin {skin:.3f} µm: {r['ms_per_step']:.3f} ms/step, "
                  f"{r['rebuilds_per_1000_steps']} rebuilds per 1000 steps, {r['partners_per_segment']} partners per "
                  f"segment", flush=True)
    print(f"load average (1, 5, 15 min): {[round(x, 2) for x in os.getloadavg()]}")
    from pathlib import Path
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "skin_" + a.state.replace(" h", "h").replace(" ", "-") + ".csv"
    write_csv(out / name, rows)
    print(f"written {out / name}")


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
    p.add_argument("--state", help='a benchmark state (benchmarks/states.py), e.g. "S3 6 h", instead of the scenes\' '
                   "starts")
    p.add_argument("--rounds", type=int, default=3, help="with --state: rounds, the skins alternating in each")
    p.add_argument("--threads", type=int, default=2, help="with --state: CPU threads")
    p.add_argument("--steps", type=int, default=0, help="with --state: steps timed per measurement (default 1000)")
    a = p.parse_args()
    if a.state:
        return by_state(a)
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
