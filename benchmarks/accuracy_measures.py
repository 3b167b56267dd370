"""The measures of the accuracy study (benchmarks/accuracy.py), one method at a time, in a worker process:

    python benchmarks/accuracy_measures.py --method JSON --measures free,follow,... [--threads 1] [--quick] [--ref F]

prints one JSON line. Each method runs in a fresh process: Taichi fixes thread count and compiled constants per
process, and every simulation compiles its kernels. What is measured, against a converged reference (the paper's
explicit step in f64 at 0.25 ms):

  free      a single free straight cell far from the origin (near the 200 µm box corner, where f32 positions are
            coarsest): the largest deviation of a particle's windowed (1 s) speed from v_b;
  follow    active following: a follower starting 0.24 µm (of d_g = 0.25) behind a leader's tail, pulled toward
            the 3 v_b limit: peak and mean follower speed over the approach, relative to the reference;
  strain    a dense cluster (high-density aligned patch, cells tilted a little, jamming) at k_c = 0.002 N/m, and
  strain01  the same at k_c = 0.01 N/m (the contact stiffness inside low-density aggregates): the strain energy
            (docs/model.md) averaged over the second half of the run, relative to the reference;
  aggregate a prearranged rotating aggregate (spiral start, active following): the mean speed of the outer quarter
            of the cells late in the run, relative to the reference;
  horizon   the chaotic many-cell system (50 cells, low density, active following): the simulated time for which
            every particle stays within W of the reference (not an end-point difference);
  cost      wall time per step at paper scale on all cores: S3 from its start (2000 cells, 200 x 200 µm, few
            contacts) and S13 (1440 cells at area fraction 1, all in contact).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from benchlib import L0, W_UM, Method, Unstable, make, run, scene_for, steps, straight


def measure_free(method: Method, quick: bool) -> dict:
    """One free straight cell near (190, 190) µm in a 200 µm box, moving diagonally; windowed (1 s) particle
    speeds."""
    T = 10.0 if quick else 60.0
    sc = scene_for({"domain": {"width_um": 200.0, "height_um": 200.0}, "population": {"cells": 1}}, method)
    pos = straight((190.0, 190.0), math.radians(30.0))[None]
    sim = make(sc, method, pos, np.array([1]))
    v_b = sc.v_b_um_per_min
    per = steps(1.0, method.dt_ms)
    dev = []
    p0 = sim.positions().mean(1)[0]
    for _ in range(int(T)):
        sim.snapshot_speed()
        run(sim, per)
        dev.append(np.abs(sim.particle_speed() / v_b - 1.0).max())
    d = sim.positions().mean(1)[0] - p0
    d -= 200.0 * np.round(d / 200.0)
    mean = np.linalg.norm(d) / sim.time * 60.0 / v_b - 1.0
    sim.close()
    return {"free_max_dev": float(max(dev)), "free_mean_dev": float(abs(mean))}


def measure_follow(method: Method, quick: bool) -> dict:
    """Active following: follower 0.24 µm behind the leader's tail (pull 192 pN), both heading +x. Follower centroid
    speed every 0.1 s over 3 s (in units of v_b)."""
    sc = scene_for({"domain": {"width_um": 30.0, "height_um": 30.0}, "population": {"cells": 2},
                    "guiding": {"kind": "active"}}, method)
    cf = 8.0
    cl = cf + (7 * L0) + W_UM + 0.24
    pos = np.stack([straight((cf, 15.0), 0.0), straight((cl, 15.0), 0.0)])
    sim = make(sc, method, pos, np.array([-1, -1]))        # k_e = -1: particle N-1 (at +x) is the head
    v_b = sc.v_b
    dt_s = max(0.1, method.dt_ms * 1e-3)
    per = steps(dt_s, method.dt_ms)
    xs = [sim.positions()[0, :, 0].mean()]
    for _ in range(int(round(3.0 / dt_s))):
        run(sim, per)
        xs.append(sim.positions()[0, :, 0].mean())
    sim.close()
    v = np.diff(np.unwrap(np.array(xs) * 2 * np.pi / 30.0) * 30.0 / (2 * np.pi)) / dt_s / v_b
    return {"follow_speed_vb": v.tolist(), "follow_dt_s": dt_s}


def measure_strain(method: Method, quick: bool, k_c: float = 0.002) -> dict:
    """A dense cluster: the high-density aligned patch (15 x 15 µm, 90 cells at area fraction 1, flexible, random
    polarities), each cell tilted by up to 3 degrees, relaxing and jamming. Total strain energy (J) every second;
    compared by its mean over the second half of the run. At k_c = 0.002 N/m (the paper's high-density value) and
    0.01 N/m (low density: the stiffness inside S3's aggregates)."""
    from taichimyxo.physics.placement import initial_configuration
    T = 6.0 if quick else 20.0
    sc = scene_for({"domain": {"width_um": 15.0, "height_um": 15.0},
                    "population": {"start": "aligned", "density_cells_per_cm2": 4e7},
                    "collisions": {"k_c_N_per_m": k_c}, "output": {"strain": True}}, method)
    pos, ke = initial_configuration(sc)
    rng = np.random.default_rng(5)              # tilt each cell by up to 3 degrees: rows that are exactly straight
    for c, a in enumerate(np.radians(rng.uniform(-3.0, 3.0, len(pos)))):   # would stay one-dimensional
        m = pos[c].mean(0)
        R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        pos[c] = m + (pos[c] - m) @ R.T
    sim = make(sc, method, pos, ke)
    per = steps(1.0, method.dt_ms)
    e = []
    for _ in range(int(T)):
        run(sim, per)
        e.append(float(sim.segment_strain().sum()))
    sim.close()
    return {("strain_J" if k_c == 0.002 else "strain01_J"): e}


def measure_aggregate(method: Method, quick: bool) -> dict:
    """Spiral start (60 cells head to tail, all the same way round, active following, flexible) in 40 x 40 µm: mean
    windowed (1 s) speed of the outer quarter of the cells (by distance from the centre) over the last third."""
    T = 15.0 if quick else 90.0
    sc = scene_for({"domain": {"width_um": 40.0, "height_um": 40.0},
                    "population": {"start": "spiral", "cells": 60}, "guiding": {"kind": "active"}}, method)
    sim = make(sc, method)
    v_b = sc.v_b_um_per_min
    per = steps(1.0, method.dt_ms)
    edge = []
    for i in range(int(T)):
        sim.snapshot_speed()
        run(sim, per)
        if i >= 2 * T / 3:
            pos = sim.positions()
            c = pos.mean(1) - 20.0
            c -= 40.0 * np.round(c / 40.0)
            r = np.linalg.norm(c, axis=1)
            outer = r >= np.quantile(r, 0.75)
            edge.append(float(sim.particle_speed()[outer].mean() / v_b))
    sim.close()
    return {"edge_speed_vb": float(np.mean(edge))}


def measure_horizon(method: Method, quick: bool, reference: dict | None) -> dict:
    """50 cells at low density with active following, sampled every 5 s. With a reference trajectory: the first
    sample time at which some particle is more than W from its reference position (stops there)."""
    T = 60.0 if quick else 600.0
    sc = scene_for({"domain": {"width_um": 31.6, "height_um": 31.6}, "population": {"cells": 50},
                    "guiding": {"kind": "active"}, "run": {"seed": 7}}, method)
    sim = make(sc, method)
    L = np.array(sc.box)
    per = steps(5.0, method.dt_ms)
    traj = [sim.positions()]
    horizon = None
    dev = []
    for i in range(int(T / 5.0)):
        try:
            run(sim, per)
        except Unstable:
            horizon = horizon if horizon is not None else sim.time
            break
        p = sim.positions()
        traj.append(p)
        if reference is not None:
            d = p - np.asarray(reference["traj"][i + 1])
            d -= L * np.round(d / L)
            m = float(np.sqrt((d * d).sum(-1)).max())
            dev.append(m)
            if m > W_UM:
                horizon = (i + 1) * 5.0
                break
    sim.close()
    out = {"horizon_s": horizon if horizon is not None else T, "horizon_capped": horizon is None,
           "horizon_T": T, "horizon_dev": dev}
    if reference is None:
        out["traj"] = np.array(traj).tolist()
    return out


def measure_cost(method: Method, quick: bool, state: str = "start") -> dict:
    """Wall and CPU time per step at paper scale: 'start' is S3 (2000 cells, 200 x 200 µm, active following) from
    its random start (few contacts); 'dense' is S13 (1440 cells in 60 x 60 µm at area fraction 1, k_c = 0.002 N/m,
    active following) after 1 simulated second, where every cell is in contact (the cost of an aggregate core)."""
    from taichimyxo.io.scene import Scene
    name = "S3" if state == "start" else "S13"
    sc = Scene.load(name, {"output": {"movie": False, "strain": False}, "run": method.run_overrides()})
    sim = make(sc, method)
    reps, n = (2, 40) if quick else (3, 100)
    if method.integrator == "explicit":
        n *= 4
    run(sim, 5 if state == "start" else steps(1.0, method.dt_ms))
    walls, cpus = [], []
    if hasattr(sim, "reset_stats"):             # integrators with a solver count its iterations
        sim.reset_stats()
    for _ in range(reps):
        t, c = time.perf_counter(), time.process_time()
        run(sim, n)
        walls.append((time.perf_counter() - t) / n)
        cpus.append((time.process_time() - c) / n)
    out = {f"cost_{state}_ms_per_step": 1e3 * min(walls), f"cost_{state}_cpu_ms_per_step": 1e3 * min(cpus)}
    if hasattr(sim, "solver_stats") and "cg_per_step" in sim.solver_stats():
        out[f"cost_{state}_cg_per_step"] = sim.solver_stats()["cg_per_step"]
    sim.close()
    return out


MEASURES = {"free": measure_free, "follow": measure_follow, "strain": measure_strain,
            "strain01": lambda m, q: measure_strain(m, q, 0.01), "aggregate": measure_aggregate}


def worker(method: Method, measures: list[str], quick: bool, threads: int, ref_file: str | None) -> dict:
    from taichimyxo.runtime import backend
    backend.init("cpu", threads, default_fp="f64" if method.precision == "f64" else "f32")
    out = {"method": asdict(method), "label": method.label, "family": method.family}
    for m in measures:
        t0 = time.perf_counter()
        try:
            if m == "horizon":
                ref = json.loads(Path(ref_file).read_text()) if ref_file else None
                out.update(measure_horizon(method, quick, ref))
            elif m.startswith("cost"):
                out.update(measure_cost(method, quick, m.split(":")[1] if ":" in m else "start"))
            else:
                out.update(MEASURES[m](method, quick))
        except Unstable as e:
            out[f"{m}_unstable"] = str(e)
        except Exception as e:          # noqa: BLE001 - one failed measure must not lose the others
            out[f"{m}_failed"] = f"{type(e).__name__}: {e}"[:300]
        out[f"{m}_wall_s"] = time.perf_counter() - t0
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="worker of benchmarks/accuracy.py: one method, one JSON line")
    p.add_argument("--method", required=True, help="JSON of benchlib.Method's fields")
    p.add_argument("--measures", required=True, help="comma-separated: " + ", ".join([*MEASURES, "horizon",
                                                                                     "cost:start", "cost:dense"]))
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--ref", help="the reference's trajectory (JSON) for the horizon")
    a = p.parse_args(argv)
    print(json.dumps(worker(Method(**json.loads(a.method)), a.measures.split(","), a.quick, a.threads, a.ref)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
