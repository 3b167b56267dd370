"""`python -m taichimyxo bench throughput`: particle-steps per second of scenes at the paper's size and at multiples of
its area, on the CPU or a GPU, and the wall time a full 6 h S3 would take.

    python -m taichimyxo bench throughput [--arch cpu|cuda] [--sizes 1,4,16] [--scenes S1,S3,S11] [--steps N]
                                          [--warm N] [--out DIR]

A size is a multiple of the scene's area: the box's sides grow by its square root and the cell count with the area
(a scene given by density keeps its density), so 16 is S3's 200 x 200 µm box at 800 x 800 µm with 32 000 cells.
Each (scene, size) builds its simulation, runs `warm` steps (compiling the kernels, settling the neighbour list)
and times `steps` more (time_steps): placement, compiling and the warm steps are reported apart (setup_s), never in
the rate.

Projection of a full 6 h S3 at paper scale (docs/performance.md): its 5.4 M steps (6 h at S3's 4 ms step) at the cost
per particle-step measured at S3's start (sparse: cells far apart) and at S11's (dense: aligned at area fraction ~1,
every cell in contact), each scaled to S3's particles: the range between a run that stayed as sparse as its start
and one as dense as S11. Written with the rows to throughput.csv and throughput.json in --out; rows already there
for other (scene, size, arch) are kept, so sizes measured by separate invocations (each under its own time limit,
benchmarks/gpu_check.sh) end in one table. Rates, not asserts: shared machines are noisy.

The measuring code lives here so an installed wheel has it; benchmarks/throughput.py (the per-effect table) and
benchmarks/benchlib.py use it.
"""
from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from pathlib import Path

DEFAULT_SCENES = ("S1", "S3", "S11")
DEFAULT_SIZES = (1.0, 4.0, 16.0)
FULL_S3_HOURS = 6.0


def scaled_scene(name: str, area: float = 1.0, run: dict | None = None):
    """Scene `name` with its area multiplied by `area` (sides by its square root; a cell count with the area, a
    density kept), the movie off, `run` overrides (precision, integrator, ...) applied."""
    from ..io.scene import Scene
    over = {"output": {"movie": False}}
    if area != 1.0:
        sc0 = Scene.load(name)
        s = area ** 0.5
        over.update(sc0.resized(sc0.box[0] * s, sc0.box[1] * s))
    if run:
        over["run"] = dict(run)
    return Scene.load(name, over)


def time_steps(sim, steps: int, warm: int) -> dict:
    """Wall time of `steps` steps after `warm` steps (compilation and the first list builds excluded): ms per step,
    particle-steps per second and the neighbour-list rebuilds they included."""
    import taichi as ti
    sim.advance(warm)
    ti.sync()
    r0 = sim.rebuilds
    t0 = time.perf_counter()
    sim.advance(steps)
    ti.sync()
    wall = time.perf_counter() - t0
    return {"particles": sim.n_p, "steps": steps, "wall_s": round(wall, 3), "ms_per_step": round(1e3 * wall / steps, 4),
            "particle_steps_per_s": sim.n_p * steps / wall, "rebuilds": sim.rebuilds - r0}


def measure(name: str, area: float, steps: int, warm: int, run: dict | None = None, start=None,
            state: str = "start") -> dict:
    """One row: scene `name` at `area` times its area on the arch Taichi runs on (initialised by the caller).
    start: (positions, engine_direction) to begin from instead of the scene's start, a benchmark state named by
    `state` (benchmarks/states.py)."""
    from ..runtime.simulation import Simulation
    sc = scaled_scene(name, area, run)
    t0 = time.perf_counter()
    sim = Simulation(sc) if start is None else Simulation.from_positions(sc, start[0], start[1])
    try:
        sim.advance(warm)                                 # compiles the step, settles the list
        import taichi as ti
        ti.sync()
        setup = time.perf_counter() - t0              # placement, fields, compiling, warm steps
        t = time_steps(sim, steps, 0)
        row = {"scene": name, "state": state, "area": area, "box_um": f"{sc.box[0]:g}x{sc.box[1]:g}",
               "cells": sc.n_cells, "particles": sim.n_p, "precision": sc.precision, "integrator": sc.integrator,
               "dt_ms": sc.dt * 1e3,
               "steps": steps, "wall_s": t["wall_s"], "ms_per_step": t["ms_per_step"],
               "steps_per_s": round(steps / t["wall_s"], 1) if t["wall_s"] else float("inf"),
               "particle_steps_per_s": round(t["particle_steps_per_s"]),
               "simulated_s_per_wall_s": round(steps * sc.dt / t["wall_s"], 3) if t["wall_s"] else float("inf"),
               "setup_s": round(setup, 2), "rebuilds": t["rebuilds"], "loop_shape": sim.state.loops.kind,
               "serial_loops": sim.serial}
    finally:
        sim.close()
    return row


def projection(rows: list[dict], arch: str) -> dict | None:
    """Wall hours of a full 6 h S3 at paper scale, from the rows of S3 and S11 at area 1 on `arch` (None without
    them)."""
    by = {r["scene"]: r for r in rows if r.get("arch") == arch and float(r["area"]) == 1.0}
    if "S3" not in by or "S11" not in by:
        return None
    from ..io.scene import Scene
    s3 = Scene.load("S3")
    steps = FULL_S3_HOURS * 3600.0 / s3.dt
    n_p = s3.n_cells * s3.N
    sparse = steps * n_p / float(by["S3"]["particle_steps_per_s"])
    dense = steps * n_p / float(by["S11"]["particle_steps_per_s"])
    return {"arch": arch, "steps": round(steps), "particles": n_p,
            "sparse_wall_h": round(sparse / 3600.0, 3), "dense_wall_h": round(dense / 3600.0, 3),
            "method": "6 h of S3's steps at the cost per particle-step of S3's start (sparse) and of S11 (dense, "
                      "every cell in contact), each scaled to S3's particles; the simulation alone (a movie and a "
                      "trajectory add their frames' cost)"}


def _device_name(arch: str) -> str:
    if arch == "cpu":
        return f"{platform.machine()} {os.cpu_count()} cores"
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                             text=True, timeout=20).stdout.strip()
        return out.splitlines()[0] if out else arch
    except (OSError, subprocess.SubprocessError):
        return arch


ROW_KEY = ("scene", "area", "arch", "precision", "integrator")


def _merge(old: list[dict], new: list[dict]) -> list[dict]:
    keys = {tuple(str(r.get(k)) for k in ROW_KEY) for r in new}
    return [r for r in old if tuple(str(r.get(k)) for k in ROW_KEY) not in keys] + new


def throughput(arch: str = "cpu", sizes=DEFAULT_SIZES, scenes=DEFAULT_SCENES, steps: int = 200, warm: int = 50,
               out_dir: str | Path = "benchmarks-results", threads: int | None = None, echo=print) -> dict:
    """Measure every scene at every size on `arch` (no fallback: a GPU that is not there is an error), write
    throughput.csv / throughput.json into out_dir (merged with rows already there) and return the JSON's content."""
    from ..runtime import backend
    used = backend.init(arch, threads, fallback=False)
    device = _device_name(used)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = {}
    for area in sizes:
        for name in scenes:
            backend.restart()                 # fresh field ids: kernels another process compiled are loaded
            r = measure(name, float(area), steps, warm)
            r.update(arch=used, device=device)
            echo(f"{name:>4} {area:g}x area {r['box_um']:>11} µm {r['cells']:>6} cells {r['particles']:>7} particles "
                 f"{r['ms_per_step']:9.3f} ms/step {r['particle_steps_per_s'] / 1e6:9.2f} M particle-steps/s "
                 f"({used}, setup {r['setup_s']:.0f} s)")
            doc = _write(out, [r])            # after every row: a run stopped by a time limit keeps what it measured
    for a, p in doc.get("projection_full_S3", {}).items():
        echo(f"full 6 h S3 at paper scale on {a}: {p['sparse_wall_h'] * 60:.1f} min (as sparse as its start) to "
             f"{p['dense_wall_h'] * 60:.1f} min (as dense as S11), simulation alone")
    echo(f"wrote {out / 'throughput.csv'} and {out / 'throughput.json'}")
    return doc


def _write(out: Path, rows: list[dict]) -> dict:
    """Merge rows into out/throughput.json (replacing rows of the same scene, size, arch, precision, integrator),
    recompute the projections, write the JSON and the CSV; returns the JSON's content."""
    jpath = out / "throughput.json"
    old = []
    if jpath.exists():
        try:
            old = json.loads(jpath.read_text()).get("rows", [])
        except (OSError, ValueError):
            old = []
    all_rows = _merge(old, rows)
    proj = {a: projection(all_rows, a) for a in sorted({str(r.get("arch")) for r in all_rows})}
    doc = {"date": time.strftime("%Y-%m-%d %H:%M"), "host": f"{platform.node()} {platform.machine()}, "
           f"{os.cpu_count()} cores, Python {platform.python_version()}", "rows": all_rows,
           "projection_full_S3": {a: p for a, p in proj.items() if p is not None}}
    jpath.write_text(json.dumps(doc, indent=1))
    _write_csv(out / "throughput.csv", all_rows)
    return doc


def _write_csv(path: Path, rows: list[dict]) -> None:
    import csv
    cols = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, cols)
        w.writeheader()
        w.writerows(rows)


def parse_sizes(text: str) -> list[float]:
    """'1,4,16' -> [1.0, 4.0, 16.0]; each a positive number (a multiple of the paper's area)."""
    try:
        vals = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--sizes {text!r}: comma-separated numbers, multiples of the paper's area, e.g. 1,4,16") \
            from None
    if not vals or any(not v > 0 for v in vals):
        raise ValueError(f"--sizes {text!r}: each size must be a positive multiple of the paper's area")
    return vals
