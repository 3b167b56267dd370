"""Before and after a change, side by side in one run: the cost of S3's state after one simulated hour at paper
scale (benchmarks/states.py; with --state "S3 6 h", as the figures' 6 h run ends) under an earlier commit and under
the working tree, alternating, so a machine that drifts weighs on both alike.

    python benchmarks/before_after.py --before COMMIT [--rounds 2] [--steps 1500] [--threads 2] [--scale 1]
                                      [--state "S3 1 h"] [--out DIR]

The earlier commit is checked out into a temporary git worktree; each measurement is its own process (one
Simulation per process) through the public API only (Scene.load, Simulation.from_positions, advance, or an earlier
commit's equivalents), so any commit with that API can be measured. Each side runs at its own S3 default step, and
the working tree also at `--also-dt-ms` (default 2): the change of code and the change of step are told apart. Writes
before_after.csv (every round; before_after_scale<S>_t<N>.csv for another --scale or --threads,
before_after_S3-6h_t<N>.csv for the 6 h state) and prints ms per
step and wall seconds per simulated second.
"""
from __future__ import annotations

import os
from pathlib import Path

from benchlib import HERE, parser, run_in_tree, worktree, write_csv

REPO = HERE.parent
WORKER = r"""
import json, sys, time
import numpy as np
try:                                    # the package's layout in folders
    from taichimyxo.runtime import backend
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime.simulation import Simulation
except ImportError:                     # an earlier commit's flat layout
    from taichimyxo import backend
    from taichimyxo.scene import Scene
    from taichimyxo.simulation import Simulation
backend.init("cpu", int(sys.argv[3]))
import taichi as ti
dt, steps = float(sys.argv[1]), int(sys.argv[2])
z = np.load(sys.argv[4])
over = {"output": {"movie": False}}
if dt:
    over["run"] = {"dt_ms": dt}
scale = float(sys.argv[5])
if scale < 1:                           # S3's own start in a box scaled by `scale` (the density is kept)
    over["domain"] = {"width_um": 200.0 * scale, "height_um": 200.0 * scale}
sc = Scene.load("S3", over)
if scale < 1:
    sim = Simulation(sc)
elif hasattr(Simulation, "from_positions"):
    sim = Simulation.from_positions(sc, z["positions"], z["engine_direction"])
else:                                   # commits before Simulation.from_positions
    sim = Simulation(sc, positions=z["positions"], engine_direction=z["engine_direction"])
advance = sim.advance if hasattr(sim, "advance") else sim.run
advance(200)
ti.sync()
r0 = sim.rebuilds
t = time.perf_counter()
advance(steps)
ti.sync()
w = time.perf_counter() - t
print(json.dumps({"dt_ms": sc.dt * 1e3, "ms_per_step": round(1e3 * w / steps, 3),
                  "wall_s_per_simulated_s": round(w / (steps * sc.dt), 3),
                  "rebuilds_per_1000_steps": round(1e3 * (sim.rebuilds - r0) / steps, 1)}))
"""


STATE_FILES = {"S3 1 h": "S3-1h.npz", "S3 6 h": "S3-6h.npz"}


def measure(tree: Path, dt_ms: float, steps: int, threads: int, scale: float = 1.0, state: str = "S3 1 h") -> dict:
    try:
        return run_in_tree(tree, WORKER, [dt_ms, steps, threads, HERE / "states" / STATE_FILES[state], scale])
    except RuntimeError as e:
        raise SystemExit(f"before_after: {e}") from None


def main() -> None:
    p = parser(__doc__)
    p.add_argument("--before", required=True, help="the earlier commit")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--steps", type=int, default=1500)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--also-dt-ms", type=float, default=2.0, help="the working tree also at this step (0: skip)")
    p.add_argument("--scale", type=float, default=1.0, help="below 1: S3's start in a box scaled by this (0.5: the "
                   "figures' half scale) instead of the state after one hour; writes before_after_scale<S>_t<N>.csv")
    p.add_argument("--state", default="S3 1 h", choices=tuple(STATE_FILES), help="the benchmark state (scale 1)")
    a = p.parse_args()
    if a.rounds < 1 or a.steps < 1 or a.threads < 1:
        raise SystemExit("before_after: --rounds, --steps and --threads must be at least 1")
    rows = []
    with worktree(a.before) as old:
        sides = [("before", old, 0.0), ("after", REPO, 0.0)]
        if a.also_dt_ms:
            sides.append((f"after at {a.also_dt_ms:g} ms", REPO, a.also_dt_ms))
        for rnd in range(a.rounds):
            for label, tree, dt in sides:
                r = {"side": label, "round": rnd, "scale": a.scale, "threads": a.threads,
                     "state": a.state, **measure(tree, dt, a.steps, a.threads, a.scale, a.state)}
                rows.append(r)
                print(f"round {rnd} {label:>16}: {r['dt_ms']:g} ms step, {r['ms_per_step']:.3f} ms/step, "
                      f"{r['wall_s_per_simulated_s']:.3f} wall s per simulated s, "
                      f"{r['rebuilds_per_1000_steps']:g} rebuilds per 1000 steps", flush=True)
    print(f"load average (1, 5, 15 min): {[round(x, 2) for x in os.getloadavg()]}")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "before_after.csv" if (a.scale, a.threads) == (1.0, 2) else f"before_after_scale{a.scale:g}_t{a.threads}.csv"
    if a.state == "S3 6 h" and a.scale == 1.0:
        name = f"before_after_S3-6h_t{a.threads}.csv"
    write_csv(out / name, rows)
    print(f"wrote {out / name}")


if __name__ == "__main__":
    main()
