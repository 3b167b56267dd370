"""Stability sweep: the largest stable time step per integrator over the paper's stiffness grid.

    python benchmarks/stability_sweep.py [--quick] [--out DIR]
    python benchmarks/stability_sweep.py --sparse [--out DIR]    # explicit: sparse start against the dense jam

Writes stability.csv, stability.md and stability_limits.json into the output folder (default benchmarks-results/ in
the current directory). The limits the program enforces are package data, taichimyxo/physics/stability_limits.json,
which a person updates: the sweep never rewrites it; to adopt a new measurement, review it and copy
<out>/stability_limits.json over taichimyxo/physics/stability_limits.json. Each (integrator, k_a, k_c) runs in a worker
process (`--worker`), two at a time on one thread each.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchlib import (
    DEFAULT_OUT,
    Method,
    Unstable,
    fmt,
    json_from_worker,
    make,
    parser,
    run,
    scene_for,
    steps,
    write_csv,
)

PACKAGE_LIMITS = "taichimyxo/physics/stability_limits.json"     # in a clone; a person copies the sweep's file here
STAB_DT_MS = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0, 20.0, 30.0, 50.0, 75.0, 100.0, 150.0, 200.0)
# the paper's stiffness grid: k_a (N m) x k_c (N/m)
K_A = (1e-18, 1e-17, 1e-16, 1e-15)
K_C = (0.01, 0.002)
# the largest step of each integrator within the tolerance (SPEED_TOL, STRAIN_TOL) of the accuracy study
# (benchmarks/results/accuracy.csv, read in ACCURACY.md); a scene's default is this, capped at half the measured
# stability limit for its stiffness
ACCURATE_DT_MS = {"explicit": 2.0, "imex": 1.0}


def _stab_scene(method: Method, k_a: float, k_c: float, config: str = "dense"):
    if config == "sparse":
        # what a step-size controller would exploit: the paper's low-density random start (S1, 80 cells in a
        # 40 x 40 µm box) where few cells touch; the limit here is the cell's own springs and bending
        return scene_for({"domain": {"width_um": 40.0, "height_um": 40.0},
                          "population": {"start": "random", "density_cells_per_cm2": 5e6},
                          "cell": {"k_a_N_m": k_a}, "collisions": {"k_c_N_per_m": k_c},
                          "guiding": {"kind": "active"}, "run": {"seed": 3}}, method)
    return scene_for({"domain": {"width_um": 15.0, "height_um": 15.0},
                      "population": {"start": "aligned", "density_cells_per_cm2": 4e7},
                      "cell": {"k_a_N_m": k_a}, "collisions": {"k_c_N_per_m": k_c},
                      "guiding": {"kind": "active"}, "run": {"seed": 3}}, method)


def _max_speed_vb(before: np.ndarray, after: np.ndarray, box, seconds: float, v_b: float) -> float:
    """The fastest particle over a window, from the stored positions at its two ends (minimum image), in v_b."""
    L = np.array(box)
    d = after.astype(np.float64) - before.astype(np.float64)
    d -= L * np.round(d / L)
    return float(np.sqrt((d * d).sum(-1)).max() / seconds / v_b)


def stability_worker(integrator: str, contacts: str, k_a: float, k_c: float, dts: list[float], n_steps: int,
                     config: str = "dense") -> dict:
    """Hard configuration: a high-density aligned patch with random polarities and active following (cells jam,
    push and bend), relaxed first with the explicit step at 0.5 ms for 5 s. From that state, each step size runs
    `n_steps` steps (at least 10 s simulated); stable = finite, segment lengths within +-20 % of l0, no particle faster
    than max(5 v_b, twice the fastest windowed speed of a 10 s, 0.5 ms explicit run from the same state) over the
    last window, no segments closer than 0.3 W (taichimyxo/physics/invariants.py)."""
    from taichimyxo.physics.invariants import Bounds, measure
    from taichimyxo.physics.placement import initial_configuration
    from taichimyxo.runtime import backend
    backend.init("cpu", 1, default_fp="f32")
    relax = Method("explicit", dt_ms=0.5, precision="mixed")
    sc0 = _stab_scene(relax, k_a, k_c, config)
    pos, ke0 = initial_configuration(sc0)       # no reversals here: the engine directions stay as they start
    prep = make(sc0, relax, pos, ke0)
    prep.advance(steps(5.0, 0.5))
    pos0 = prep.positions()
    # the fastest windowed (1 s) particle speed of the physics itself (explicit, 0.5 ms, over the next 10 s): in
    # this jam, with guiding, flexible cells whip past 5 v_b, so the speed bound is twice this, and at least 5 v_b
    v_ref = 0.0
    for _ in range(10):
        prep.snapshot_speed()
        prep.advance(steps(1.0, 0.5))
        v_ref = max(v_ref, float(prep.particle_speed().max() / sc0.v_b_um_per_min))
    prep.close()
    b = Bounds()
    v_bound = max(b.speed_factor, 2.0 * v_ref)
    out = {"v_ref": v_ref, "v_bound": v_bound}
    sim = None
    fails = 0
    for dt in dts:
        if fails >= 2:          # two failures in a row: larger steps are not tried
            out[str(dt)] = {"stable": False, "why": "not run (two smaller steps failed)"}
            continue
        m = Method(integrator, contacts, dt_ms=dt, precision="mixed")
        sc = _stab_scene(m, k_a, k_c, config)
        # one compiled simulation per (k_a, k_c): the step size only enters through run's dt
        if sim is None:
            sim = make(sc, m, pos0, ke0)
        sim.set_state(pos0, ke0)
        n = max(n_steps, steps(10.0, dt))
        win = max(10, steps(1.0, dt))
        ok, why = True, ""
        try:
            run(sim, n - win, dt)
            before = sim.wrapped_positions()
            run(sim, win, dt)
            vmax = _max_speed_vb(before, sim.wrapped_positions(), sc.box, win * dt * 1e-3, sc.v_b)
            q = measure(sim.positions(), sc.box, sc.rest_length, sc.width, sc.k_s, sc.k_a, sc.k_c)
            if not q["finite"]:
                ok, why = False, "non-finite"
            elif not (1 - b.length_tol <= q["len_min"] and q["len_max"] <= 1 + b.length_tol):
                ok, why = False, f"length {q['len_min']:.2f}..{q['len_max']:.2f} l0"
            elif vmax > v_bound:
                ok, why = False, f"speed {vmax:.1f} v_b"
            elif min(q["d_other_min"], q["d_self_min"]) < b.min_distance_W:
                ok, why = False, f"overlap: distance {min(q['d_other_min'], q['d_self_min']):.2f} W"
        except (Unstable, FloatingPointError, ValueError) as e:
            ok, why = False, str(e)[:60]
        out[str(dt)] = {"stable": ok, "why": why}
        fails = 0 if ok else fails + 1
    if sim is not None:
        sim.close()
    return out


def _spawn(integrator, contacts, k_a, k_c, dts, n_steps, config="dense") -> dict:
    cmd = [sys.executable, __file__, "--worker", json.dumps({"integrator": integrator, "contacts": contacts,
                                                             "k_a": k_a, "k_c": k_c, "dts": dts, "n_steps": n_steps,
                                                             "config": config})]
    r = json_from_worker(cmd, timeout=3600)
    if "error" in r:
        return {str(d): {"stable": False, "why": f"worker failed: {r['error'][:80]}"} for d in dts}
    return r


def _limit(res: dict) -> float:
    """Largest step such that it and every smaller tested step were stable."""
    lim = 0.0
    for dt in sorted((k for k in res if k[0].isdigit()), key=float):
        if not res[dt]["stable"]:
            break
        lim = float(dt)
    return lim


def _tested(res: dict) -> tuple[list[str], str]:
    """The step sizes a worker ran (ms, as its keys, ascending) and its first failure ("" when none failed)."""
    dts_run = sorted((k for k in res if k[0].isdigit()), key=float)
    return dts_run, next((f"{float(d):g} ms: {res[d]['why']}" for d in dts_run if not res[d]["stable"]), "")


def default_steps(limits: dict) -> dict:
    out = {}
    for integ, acc in ACCURATE_DT_MS.items():
        out[integ] = {}
        for key, lim in limits.get(integ, {}).items():
            if lim <= 0:
                continue
            d = min(acc, 0.5 * lim)
            grid = [g for g in (0.25,) + STAB_DT_MS if g <= d]          # round down onto the grid of tested steps
            out[integ][key] = grid[-1] if grid else 0.25
    return out


def write_limits(out_dir, table: dict) -> Path:
    """The measured limits and the defaults they give, as taichimyxo/physics/stability_limits.json is laid out, into
    <out_dir>/stability_limits.json (never the package's file). Integrators the sweep did not measure keep the
    package's current values."""
    from taichimyxo.physics.stability import measured_limits
    data = dict(measured_limits())
    data.update(table)
    data["defaults"] = default_steps(data)
    path = Path(out_dir) / "stability_limits.json"
    path.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    return path


def main(quick: bool = False, out_dir: str = DEFAULT_OUT) -> int:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    n_steps = 200 if quick else 400
    k_as = (1e-17, 1e-15) if quick else K_A
    k_cs = (0.01,) if quick else K_C
    integrators = [("explicit", "coupled", [d for d in STAB_DT_MS if d <= 15.0]),
                   ("imex", "coupled", [d for d in STAB_DT_MS if d >= 5.0]),
                   ("imex", "explicit", [d for d in STAB_DT_MS if 2.0 <= d <= 100.0])]
    jobs = [(i, c, ka, kc, dts, n_steps) for (i, c, dts) in integrators for ka in k_as for kc in k_cs]
    with ThreadPoolExecutor(2) as ex:
        results = list(ex.map(lambda j: _spawn(*j), jobs))
    rows, table = [], {}
    for (i, c, ka, kc, dts, _), res in zip(jobs, results):
        name = i if (i == "explicit" or c == "coupled") else f"imex-{c}"
        lim = _limit(res)
        dts_run, first_bad = _tested(res)
        table.setdefault(name, {})[f"{ka:g}/{kc:g}"] = lim
        rows.append({"integrator": name, "k_a_N_m": ka, "k_c_N_per_m": kc, "limit_ms": lim,
                     "first_unstable": first_bad, "speed_bound_vb": round(res.get("v_bound", float("nan")), 2),
                     "tested_ms": " ".join(f"{float(d):g}" for d in dts_run)})
    write_csv(out / "stability.csv", rows)
    from taichimyxo.io.scene import STIFFNESS_NAMES
    names = list(table)
    lines = ["# Largest stable time step (ms)", "",
             f"`python benchmarks/stability_sweep.py{' --quick' if quick else ''}` "
             f"({(time.perf_counter() - t0) / 60:.1f} min). Configuration: 15 x 15 µm high-density aligned patch "
             "(90 cells, area fraction 1), random polarities, active following, relaxed 5 s; each step size runs at "
             f"least {n_steps} steps and 10 s. Stable: finite, segment lengths within ±20 % of l0, windowed (≥ 1 s) "
             "speed ≤ max(5 v_b, twice the fastest windowed speed in 10 s of a 0.5 ms explicit run from the same "
             "state: flexible cells in this jam whip past 5 v_b), no segments closer than 0.3 W. A limit is the "
             "largest tested step at which it and all smaller ones were stable.", "",
             "| k_a (N·m) | k_c (N/m) | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for ka in k_as:
        for kc in k_cs:
            key = f"{ka:g}/{kc:g}"
            lines.append(f"| {ka:g} ({STIFFNESS_NAMES[ka]}) | {kc:g} | " +
                         " | ".join(fmt(table[n].get(key, float('nan')), "g") for n in names) + " |")
    lines += ["", "First failure per row:", ""]
    for r in rows:
        if r["first_unstable"]:
            lines.append(f"- {r['integrator']} k_a={r['k_a_N_m']:g} k_c={r['k_c_N_per_m']:g}: {r['first_unstable']}")
    (out / "stability.md").write_text("\n".join(lines) + "\n")
    limits = write_limits(out, table)
    print("\n".join(lines))
    print(f"\nwrote {out / 'stability.csv'}, {out / 'stability.md'}, {limits}; to adopt these limits (they set every "
          f"scene's step limit and default), review them and copy {limits} to {PACKAGE_LIMITS}"
          + (" (a --quick sweep covers only part of the grid)" if quick else ""))
    return 0


def sparse_main(out_dir: str = DEFAULT_OUT) -> int:
    """--sparse: the explicit step's limit in the sparse start against the dense jam, at the paper's low-density
    contact stiffness, for the four bending stiffnesses: how much larger a step a step-size controller could take
    while the system is sparse. Writes stability_sparse.{csv,md}; never the limits."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    dts = [d for d in STAB_DT_MS if d <= 30.0]
    jobs = [("explicit", "coupled", ka, 0.01, dts, 400, cfg) for ka in K_A for cfg in ("sparse", "dense")]
    with ThreadPoolExecutor(2) as ex:
        results = list(ex.map(lambda j: _spawn(*j), jobs))
    rows = []
    for (_, _, ka, kc, _, _, cfg), res in zip(jobs, results):
        first_bad = _tested(res)[1]
        rows.append({"config": cfg, "k_a_N_m": ka, "k_c_N_per_m": kc, "limit_ms": _limit(res),
                     "first_unstable": first_bad})
    write_csv(out / "stability_sparse.csv", rows)
    lim = {(r["config"], r["k_a_N_m"]): r for r in rows}
    lines = ["# Explicit step limit: sparse start against dense jam (ms)", "",
             f"`python benchmarks/stability_sweep.py --sparse` ({(time.perf_counter() - t0) / 60:.1f} min). Sparse: "
             "the S1 start (40 x 40 µm, 80 cells at 5e6 cells/cm², random), dense: the 15 x 15 µm jam of "
             "stability.md; both with active following and k_c = 0.01 N/m, relaxed 5 s, the same stability tests.", "",
             "| k_a (N·m) | sparse | dense | first failure, sparse | first failure, dense |", "|---|---|---|---|---|"]
    for ka in K_A:
        sp, de = lim[("sparse", ka)], lim[("dense", ka)]
        lines.append(f"| {ka:g} | {sp['limit_ms']:g} | {de['limit_ms']:g} | {sp['first_unstable']} | "
                     f"{de['first_unstable']} |")
    (out / "stability_sparse.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = parser(__doc__, "reduced version: 2 stiffnesses, 200 steps per step size")
    p.add_argument("--worker", help=argparse.SUPPRESS)       # JSON: one (integrator, k_a, k_c) in this process
    p.add_argument("--sparse", action="store_true", help="the explicit limit in a sparse start against the dense jam")
    return p


if __name__ == "__main__":
    a = build_parser().parse_args()
    if a.worker:
        print(json.dumps(stability_worker(**json.loads(a.worker))))
        raise SystemExit(0)
    raise SystemExit(sparse_main(a.out) if a.sparse else main(quick=a.quick, out_dir=a.out))
