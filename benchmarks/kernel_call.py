"""What Taichi's Python kernel call costs a step: the same steps launched through Taichi's own call and directly
(taichimyxo/kernel_call.py), alternating in one process per state, so the two compare on one machine and load.

    python benchmarks/kernel_call.py [--rounds 2] [--out DIR]

States (each at its scene's own step; threads as a run of that size uses them):
  tiny        5 cells in 20 x 20 µm, 1 thread: the call overhead nearly alone
  S3 quarter  S3's start at quarter scale (125 cells, the outcome checks' size), 1 thread
  S3 half     S3's start at half scale (500 cells, the figures' size), 1 thread
  S3 1 h      the paper-scale state after one hour (benchmarks/states.py), 2 threads
  S1          S1's paper-scale start (the LAMMPS comparison's), 2 threads
Each stretch is timed in wall and process CPU seconds; rebuilds are launched the same way as the steps. Writes
kernel_call.csv (a row per stretch) and prints each state's ratio of direct to Taichi's wall time per step.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from benchlib import HERE, json_from_worker, parser, write_csv

STATES = {"tiny": (1, 20000), "S3 quarter": (1, 6000), "S3 half": (1, 3000), "S3 1 h": (2, 1500), "S1": (2, 3000)}


def _simulation(name: str, threads: int):
    from taichimyxo.bench import scaled_scene
    from taichimyxo.simulation import Simulation, init_backend
    if name == "tiny":
        sys.path.insert(0, str(HERE.parent / "tests"))
        from simtools import build_small_scene
        scene = build_small_scene(5, box=(20.0, 20.0))
        init_backend(scene, "cpu", threads)
        return Simulation(scene)
    if name == "S3 1 h":
        import states
        from taichimyxo.scene import Scene
        _, _, start = states.load("S3 1 h")
        scene = Scene.load("S3", {"output": {"movie": False}})
        init_backend(scene, "cpu", threads)
        return Simulation.from_positions(scene, *start)
    scene, area = {"S3 quarter": ("S3", 1 / 16), "S3 half": ("S3", 1 / 4), "S1": ("S1", 1.0)}[name]
    sc = scaled_scene(scene, area)
    init_backend(sc, "cpu", threads)
    return Simulation(sc)


def _set_calls(sim, how: str, direct_calls: dict) -> None:
    """Launch the step and the list build the way `how` says (the integrator is explicit in every state)."""
    if how == "taichi":
        sim.integrator._launch_step = sim.integrator._step
        sim.neighbours._launch_build = sim.neighbours._build
    else:
        sim.integrator._launch_step = direct_calls["step"]
        sim.neighbours._launch_build = direct_calls["build"]


def worker(name: str, rounds: int) -> None:
    import taichi as ti
    threads, steps = STATES[name]
    sim = _simulation(name, threads)
    direct_calls = {"step": sim.integrator._launch_step, "build": sim.neighbours._launch_build}
    sim.advance(300)                               # compiles, and the direct calls' first (Taichi) call
    ti.sync()
    rows = []
    for r in range(rounds):
        for how in ("taichi", "direct"):
            _set_calls(sim, how, direct_calls)
            rb, load = sim.rebuilds, os.getloadavg()[0]
            t0, c0 = time.perf_counter(), time.process_time()
            sim.advance(steps)
            ti.sync()
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            rows.append(dict(state=name, particles=sim.n_p, threads=threads, round=r + 1, call=how, steps=steps,
                             wall_s=round(wall, 3), cpu_s=round(cpu, 3), us_per_step=round(1e6 * wall / steps, 1),
                             cpu_us_per_step=round(1e6 * cpu / steps, 1), rebuilds=sim.rebuilds - rb,
                             load_before=round(load, 2)))
    print(json.dumps({"rows": rows}))


def main() -> None:
    p = parser(__doc__, "one round, a tenth of the steps")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.worker:
        if a.quick:
            STATES[a.worker] = (STATES[a.worker][0], STATES[a.worker][1] // 10)
        worker(a.worker, a.rounds)
        return
    rows = []
    for name in STATES:
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", name,
               "--rounds", str(1 if a.quick else a.rounds)] + (["--quick"] if a.quick else [])
        res = json_from_worker(cmd, timeout=3600, env={**os.environ, "PYTHONPATH": str(HERE)})
        if "rows" not in res:
            print(f"{name}: {res.get('error')}")
            continue
        rows += res["rows"]
        t = sum(x["wall_s"] for x in res["rows"] if x["call"] == "taichi")
        d = sum(x["wall_s"] for x in res["rows"] if x["call"] == "direct")
        n = sum(x["steps"] for x in res["rows"] if x["call"] == "taichi")
        print(f"{name:<10} {res['rows'][0]['particles']:>6} particles: Taichi's call {1e6 * t / n:8.1f} µs/step, "
              f"direct {1e6 * d / n:8.1f} µs/step, direct / Taichi {d / t:.3f}", flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "kernel_call.csv", rows)
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
