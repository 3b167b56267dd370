"""What the CLI's writers cost: the same stretch of steps advanced bare (`sim.advance`) and through the run loop
with every writer a `scene` run attaches (taichimyxo.runtime.scene_run.scene_writers: invariant checks, trajectory,
event table, movie, checkpoints, summary), alternating, on a paper-scale S3 benchmark state (after one hour, or
with --state "S3 6 h" as the figures' 6 h run ends) at S3's own step.

    python benchmarks/writers_cost.py [--state "S3 1 h"] [--steps 15000] [--rounds 2] [--threads 2] [--out DIR]

Each stretch is timed in wall and process CPU seconds; the ratio of the run loop's to the bare steps' is the
writers' cost. 15 000 steps of 4 ms are 60 simulated seconds: one movie and trajectory frame, 7 chunks of invariant
checks and event-table updates; a 6 h run has the same per simulated minute. Writes writers_cost.csv (S3 1 h) or
writers_cost_S3-6h.csv.
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from benchlib import parser, write_csv


def main() -> None:
    p = parser(__doc__, "1500 steps, one round")
    p.add_argument("--steps", type=int, default=15000)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--state", default="S3 1 h", choices=("S3 1 h", "S3 6 h"), help="the benchmark state")
    a = p.parse_args()
    steps, rounds = (1500, 1) if a.quick else (a.steps, a.rounds)
    if steps < 1 or rounds < 1 or a.threads < 1:
        raise SystemExit("writers_cost: --steps, --rounds and --threads must be at least 1")
    import taichi as ti

    import states
    from taichimyxo.io.outdir import outputs
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime.run_loop import drive
    from taichimyxo.runtime.scene_run import scene_writers
    from taichimyxo.runtime.simulation import Simulation, init_backend
    _, _, start = states.load(a.state)
    scene = Scene.load("S3")
    init_backend(scene, "cpu", a.threads)
    sim = Simulation.from_positions(scene, *start)
    sim.advance(300)
    ti.sync()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            for how in ("advance", "run loop"):
                t0, c0, load = time.perf_counter(), time.process_time(), os.getloadavg()[0]
                if how == "advance":
                    sim.advance(steps)
                    ti.sync()
                else:
                    files = outputs(Path(tmp), f"S3-{r}")
                    drive(sim, steps, scene_writers(scene, files, progress=False))
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                rows.append(dict(round=r + 1, how=how, steps=steps, threads=a.threads, wall_s=round(wall, 2),
                                 cpu_s=round(cpu, 2), ms_per_step=round(1e3 * wall / steps, 3),
                                 load_before=round(load, 2)))
                print(f"round {r + 1} {how:<9} {steps} steps: {wall:.1f} s wall, {cpu:.1f} s CPU, "
                      f"{1e3 * wall / steps:.3f} ms/step (load {load:.2f})", flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "writers_cost.csv" if a.state == "S3 1 h" else "writers_cost_S3-6h.csv"
    write_csv(out / name, rows)
    bare = sum(x["wall_s"] for x in rows if x["how"] == "advance")
    loop = sum(x["wall_s"] for x in rows if x["how"] == "run loop")
    print(f"run loop with writers / bare steps: {loop / bare:.3f} (wall, {rounds} rounds)")


if __name__ == "__main__":
    main()
