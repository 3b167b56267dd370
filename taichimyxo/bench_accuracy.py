"""Accuracy versus cost (issue 4): `python -m taichimyxo bench accuracy` and `bench stability`.

What is measured, for each method (integrator, contact treatment, time step, precision), against a converged
reference (the paper's explicit step in f64 at 0.25 ms):

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
            contacts) and S13 (1440 cells at area fraction 1, all in contact); S3's wall time per simulated hour
            is taken at the mean of the two (aggregate cores are as dense as S13).

Tolerance (SPEED_TOL, STRAIN_TOL) and the defaults it sets: benchmarks/results/ACCURACY.md.

Each method runs in a fresh subprocess (Taichi fixes thread count and compiled constants per process, and every
Simulation compiles its kernels). Accuracy runs use one thread each, two at a time; cost runs are serial and use all
cores. Results, in the output folder (default benchmarks-results/ in the current directory; the study's own results
are kept in benchmarks/results/): accuracy.csv, accuracy.png (error against wall time per simulated hour, one curve
per method), accuracy.md (tables). The stability sweep (`stability_main`) writes stability.csv, stability.md and,
only with --write-limits, taichimyxo/stability_limits.json, which stability.py reads for step limits and defaults.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

# results go to benchmarks-results/ in the current directory unless --out names a folder; the stability limits the
# program enforces (stability_limits.json, in the package) are rewritten only with --write-limits
DEFAULT_OUT = "benchmarks-results"
REF_DT_MS = 0.25
# the tolerance that sets the defaults (ACCURACY.md): speeds (free cell, follower, aggregate edge) within 2 % of
# the reference, and the strain energy of dense clusters within 10 % (strain shows how deep cells press into each
# other; larger errors mean the cores of aggregates compact differently: a qualitative change)
SPEED_TOL = 0.02
STRAIN_TOL = 0.10
W_UM = 0.5
L0 = 4.5 / 7
CACHE = Path(os.environ.get("TAICHIMYXO_BENCH_CACHE", Path.home() / ".cache" / "taichimyxo-bench"))
LIMITS_JSON = Path(__file__).with_name("stability_limits.json")

# the stiffness grid of issue 5: k_a (N m) x k_c (N/m)
K_A = (1e-18, 1e-17, 1e-16, 1e-15)
K_C = (0.01, 0.002)
K_A_NAME = {1e-18: "very flexible", 1e-17: "flexible", 1e-16: "rigid", 1e-15: "very rigid"}


@dataclass(frozen=True)
class Method:
    integrator: str = "explicit"      # explicit | imex
    contacts: str = "coupled"         # imex only: coupled | diagonal | explicit
    dt_ms: float = 1.0
    precision: str = "f64"            # f32 | f64 | mixed
    tol: float = 1e-3                 # imex coupled: CG tolerance
    skin_um: float = 0.3

    @property
    def family(self) -> str:
        """One curve per family in the plot."""
        if self.integrator == "explicit":
            return f"explicit {self.precision}"
        extra = ("" if self.tol == 1e-3 else f" tol {self.tol:g}")
        return f"imex-{self.contacts} {self.precision}{extra}"

    @property
    def label(self) -> str:
        return f"{self.family} dt={self.dt_ms:g} ms" + ("" if self.skin_um == 0.3 else f" skin={self.skin_um:g}")

    def run_overrides(self) -> dict:
        return {"integrator": self.integrator, "dt_ms": self.dt_ms, "precision": self.precision,
                "skin_um": self.skin_um}


REFERENCE = Method("explicit", dt_ms=REF_DT_MS, precision="f64")


# ====================================================================================== worker side (one method)
def _scene(data: dict, method: Method):
    from .scene import Scene
    d = json.loads(json.dumps(data))
    d.setdefault("output", {})["movie"] = False
    d.setdefault("run", {}).update(method.run_overrides())
    return Scene.from_dict(d, where="bench")


def _make(scene, method: Method, positions=None, ke=None):
    from .sim import Simulation
    if method.integrator == "imex":
        from .implicit import ImplicitSimulation
        return ImplicitSimulation(scene, positions=positions, engine_direction=ke, contacts=method.contacts,
                                  tol=method.tol)
    return Simulation(scene, positions=positions, engine_direction=ke)


def _steps(t_s: float, dt_ms: float) -> int:
    return max(1, int(round(t_s / (dt_ms * 1e-3))))


class Unstable(RuntimeError):
    pass


def _run(sim, steps: int):
    from .sim import NeighbourOverflow
    try:
        sim.run(steps)
    except NeighbourOverflow as e:
        raise Unstable(str(e)) from None
    x = sim.x.to_numpy()
    if not np.all(np.isfinite(x)):
        raise Unstable("non-finite positions")


def _straight(centre, angle, N=8):
    from .init import straight_cell
    return straight_cell(np.asarray(centre, float), angle, N, L0)


def measure_free(method: Method, quick: bool) -> dict:
    """One free straight cell near (190, 190) µm in a 200 µm box, moving diagonally; windowed (1 s) particle speeds."""
    T = 10.0 if quick else 60.0
    sc = _scene({"domain": {"width_um": 200.0, "height_um": 200.0}, "population": {"cells": 1}}, method)
    pos = _straight((190.0, 190.0), math.radians(30.0))[None]
    sim = _make(sc, method, pos, np.array([1]))
    v_b = sc.raw["cell"]["speed_um_per_min"]
    per = _steps(1.0, method.dt_ms)
    dev = []
    p0 = sim.positions().mean(1)[0]
    for _ in range(int(T)):
        sim.snapshot_speed()
        _run(sim, per)
        dev.append(np.abs(sim.particle_speed() / v_b - 1.0).max())
    d = sim.positions().mean(1)[0] - p0
    d -= 200.0 * np.round(d / 200.0)
    mean = np.linalg.norm(d) / sim.time * 60.0 / v_b - 1.0
    sim.close()
    return {"free_max_dev": float(max(dev)), "free_mean_dev": float(abs(mean))}


def measure_follow(method: Method, quick: bool) -> dict:
    """Active following: follower 0.24 µm behind the leader's tail (pull 192 pN), both heading +x. Follower centroid
    speed every 0.1 s over 3 s (in units of v_b)."""
    sc = _scene({"domain": {"width_um": 30.0, "height_um": 30.0}, "population": {"cells": 2},
                 "guiding": {"kind": "active"}}, method)
    cf = 8.0
    cl = cf + (7 * L0) + W_UM + 0.24
    pos = np.stack([_straight((cf, 15.0), 0.0), _straight((cl, 15.0), 0.0)])
    sim = _make(sc, method, pos, np.array([-1, -1]))        # k_e = -1: particle N-1 (at +x) is the head
    v_b = sc.v_b
    dt_s = max(0.1, method.dt_ms * 1e-3)
    per = _steps(dt_s, method.dt_ms)
    xs = [sim.positions()[0, :, 0].mean()]
    for _ in range(int(round(3.0 / dt_s))):
        _run(sim, per)
        xs.append(sim.positions()[0, :, 0].mean())
    sim.close()
    v = np.diff(np.unwrap(np.array(xs) * 2 * np.pi / 30.0) * 30.0 / (2 * np.pi)) / dt_s / v_b
    return {"follow_speed_vb": v.tolist(), "follow_dt_s": dt_s}


def measure_strain(method: Method, quick: bool, k_c: float = 0.002) -> dict:
    """A dense cluster: the high-density aligned patch (15 x 15 µm, 90 cells at area fraction 1, flexible, random
    polarities), each cell tilted by up to 3 degrees, relaxing and jamming. Total strain energy (J) every second;
    compared by its mean over the second half of the run. At k_c = 0.002 N/m (the paper's high-density value) and
    0.01 N/m (low density: the stiffness inside S3's aggregates)."""
    T = 6.0 if quick else 20.0
    sc = _scene({"domain": {"width_um": 15.0, "height_um": 15.0},
                 "population": {"start": "aligned", "density_cells_per_cm2": 4e7},
                 "collisions": {"k_c_N_per_m": k_c}, "output": {"strain": True}}, method)
    from .init import initial_configuration
    pos, ke = initial_configuration(sc)
    rng = np.random.default_rng(5)              # tilt each cell by up to 3 degrees: rows that are exactly straight
    for c, a in enumerate(np.radians(rng.uniform(-3.0, 3.0, len(pos)))):   # would stay one-dimensional
        m = pos[c].mean(0)
        R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        pos[c] = m + (pos[c] - m) @ R.T
    sim = _make(sc, method, pos, ke)
    per = _steps(1.0, method.dt_ms)
    e = []
    for _ in range(int(T)):
        _run(sim, per)
        e.append(float(sim.segment_strain().sum()))
    sim.close()
    return {("strain_J" if k_c == 0.002 else "strain01_J"): e}


def measure_aggregate(method: Method, quick: bool) -> dict:
    """Spiral start (60 cells head to tail, all the same way round, active following, flexible) in 40 x 40 µm: mean
    windowed (1 s) speed of the outer quarter of the cells (by distance from the centre) over the last third."""
    T = 15.0 if quick else 90.0
    sc = _scene({"domain": {"width_um": 40.0, "height_um": 40.0},
                 "population": {"start": "spiral", "cells": 60}, "guiding": {"kind": "active"}}, method)
    sim = _make(sc, method)
    v_b = sc.raw["cell"]["speed_um_per_min"]
    per = _steps(1.0, method.dt_ms)
    edge = []
    for i in range(int(T)):
        sim.snapshot_speed()
        _run(sim, per)
        if i >= 2 * T / 3:
            pos = sim.positions()
            c = pos.mean(1) - 20.0
            c -= 40.0 * np.round(c / 40.0)
            r = np.linalg.norm(c, axis=1)
            outer = r >= np.quantile(r, 0.75)
            edge.append(float(sim.particle_speed()[outer].mean() / v_b))
    sim.close()
    return {"edge_speed_vb": float(np.mean(edge))}


def _horizon_scene(method: Method):
    return _scene({"domain": {"width_um": 31.6, "height_um": 31.6}, "population": {"cells": 50},
                   "guiding": {"kind": "active"}, "run": {"seed": 7}}, method)


def measure_horizon(method: Method, quick: bool, reference: dict | None) -> dict:
    """50 cells at low density with active following, sampled every 5 s. With a reference trajectory: the first
    sample time at which some particle is more than W from its reference position (stops there)."""
    T = 60.0 if quick else 600.0
    sc = _horizon_scene(method)
    sim = _make(sc, method)
    L = np.array(sc.box)
    per = _steps(5.0, method.dt_ms)
    traj = [sim.positions()]
    horizon = None
    dev = []
    for i in range(int(T / 5.0)):
        try:
            _run(sim, per)
        except Unstable:
            horizon = horizon if horizon is not None else sim.time
            break
        p = sim.positions()
        traj.append(p)
        if reference is not None:
            ref = np.asarray(reference["traj"][i + 1])
            d = p - ref
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
    from .scene import Scene
    name = "S3" if state == "start" else "S13"
    sc = Scene.load(name, {"output": {"movie": False, "strain": False}, "run": method.run_overrides()})
    sim = _make(sc, method)
    reps, n = (2, 40) if quick else (3, 100)
    if method.integrator == "explicit":
        n *= 4
    _run(sim, 5 if state == "start" else _steps(1.0, method.dt_ms))
    walls, cpus = [], []
    if hasattr(sim, "reset_stats"):
        sim.reset_stats()
    for _ in range(reps):
        t, c = time.perf_counter(), time.process_time()
        _run(sim, n)
        walls.append((time.perf_counter() - t) / n)
        cpus.append((time.process_time() - c) / n)
    out = {f"cost_{state}_ms_per_step": 1e3 * min(walls), f"cost_{state}_cpu_ms_per_step": 1e3 * min(cpus)}
    if hasattr(sim, "solver_stats"):
        out[f"cost_{state}_cg_per_step"] = sim.solver_stats()["cg_per_step"]
    sim.close()
    return out


MEASURES = {"free": measure_free, "follow": measure_follow, "strain": measure_strain,
            "strain01": lambda m, q: measure_strain(m, q, 0.01), "aggregate": measure_aggregate}


def worker(method: Method, measures: list[str], quick: bool, threads: int, ref_file: str | None) -> dict:
    from . import backend
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


def _spawn(method: Method, measures: list[str], quick: bool, threads: int, ref_file=None, timeout=1800) -> dict:
    cmd = [sys.executable, "-m", "taichimyxo.bench_accuracy", "worker", "--method", json.dumps(asdict(method)),
           "--measures", ",".join(measures), "--threads", str(threads)] + (["--quick"] if quick else []) + \
          (["--ref", str(ref_file)] if ref_file else [])
    env = dict(os.environ, TI_LOG_LEVEL="error")
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        return {"method": asdict(method), "label": method.label, "family": method.family, "error": "timeout"}
    for line in reversed(p.stdout.splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    return {"method": asdict(method), "label": method.label, "family": method.family,
            "error": (p.stderr or p.stdout).strip().splitlines()[-1:] or ["no output"]}


# ====================================================================================== the study (parent side)
def methods(quick: bool) -> list[Method]:
    """The methods of the study. Quick: a few points per family."""
    E, I = "explicit", "imex"
    if quick:
        return [Method(E, dt_ms=2.0, precision="f64"), Method(E, dt_ms=1.0, precision="f32"),
                Method(I, dt_ms=10.0, precision="mixed"), Method(I, dt_ms=50.0, precision="mixed")]
    out = [Method(E, dt_ms=d, precision="f64") for d in (0.5, 1.0, 2.0, 3.0, 4.0, 5.0)]
    out += [Method(E, dt_ms=d, precision="mixed") for d in (1.0, 2.0)]
    out += [Method(E, dt_ms=d, precision="f32") for d in (1.0, 2.0)]
    out += [Method(I, dt_ms=d, precision="mixed") for d in (1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)]
    out += [Method(I, dt_ms=d, precision="f32") for d in (5.0, 20.0)]
    out += [Method(I, dt_ms=d, precision="f64") for d in (5.0, 20.0)]
    out += [Method(I, "explicit", dt_ms=d, precision="mixed") for d in (5.0, 10.0, 20.0)]
    out += [Method(I, "diagonal", dt_ms=d, precision="mixed") for d in (5.0, 20.0)]
    out += [Method(I, dt_ms=10.0, precision="mixed", tol=t) for t in (1e-2, 1e-4)]
    return out


def skin_methods(quick: bool) -> list[Method]:
    if quick:
        return []
    skins = (0.15, 0.5, 0.8)          # 0.3 (the default) is in methods()
    base = [Method("explicit", dt_ms=1.0, precision="mixed"), Method("imex", dt_ms=10.0, precision="mixed")]
    return [replace(m, skin_um=s) for m in base for s in skins]


def _rel(a, b):
    return abs(a - b) / abs(b) if b else float("nan")


def errors(r: dict, ref: dict) -> dict:
    """Per-measure errors of one method's raw results against the reference's."""
    e = {}
    if "free_max_dev" in r:
        e["err_free"] = r["free_max_dev"]
    if "follow_speed_vb" in r and "follow_speed_vb" in ref:
        v, vr = np.array(r["follow_speed_vb"]), np.array(ref["follow_speed_vb"])
        k = int(round(r["follow_dt_s"] / ref["follow_dt_s"]))      # the reference samples at least as often
        vr_c = vr[: len(vr) // k * k].reshape(-1, k).mean(1)[: len(v)]
        n = min(len(v), len(vr_c))
        half = max(1, n // 2)
        e["follow_peak_vb"] = float(v.max())
        e["err_follow"] = max(_rel(v.max(), vr_c[:n].max()), _rel(v[:half].mean(), vr_c[:half].mean()))
    for key, name in (("strain_J", "strain"), ("strain01_J", "strain01")):
        if key in r and key in ref:
            s, sr = np.array(r[key]), np.array(ref[key])
            h = len(s) // 2
            e[f"{name}_mean_J"] = float(s[h:].mean())
            e[f"err_{name}"] = _rel(s[h:].mean(), sr[h:].mean())
    if "edge_speed_vb" in r and "edge_speed_vb" in ref:
        e["edge_speed_vb"] = r["edge_speed_vb"]
        e["err_edge"] = _rel(r["edge_speed_vb"], ref["edge_speed_vb"])
    if "horizon_s" in r:
        e["horizon_s"] = r["horizon_s"]
    for m in ("free", "follow", "strain", "strain01", "aggregate", "horizon"):
        if f"{m}_unstable" in r:
            e[f"err_{m if m != 'aggregate' else 'edge'}"] = float("inf")
            if m == "horizon":
                e["horizon_s"] = 0.0
    speeds = [e.get(k) for k in ("err_free", "err_follow", "err_edge") if e.get(k) is not None]
    strains = [e.get(k) for k in ("err_strain", "err_strain01") if e.get(k) is not None]
    e["err_speed"] = max(speeds) if speeds else float("nan")
    e["err_strain_max"] = max(strains) if strains else float("nan")
    e["err_max"] = max(speeds + strains) if speeds + strains else float("nan")
    e["within_tolerance"] = (bool(e["err_speed"] <= SPEED_TOL and e["err_strain_max"] <= STRAIN_TOL)
                             if speeds and strains else "")       # skin rows: follow + horizon only
    return e


def _pool(jobs, workers: int):
    with ThreadPoolExecutor(workers) as ex:
        return list(ex.map(lambda j: _spawn(*j), jobs))


def main(quick: bool = False, out_dir: str = DEFAULT_OUT) -> int:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    CACHE.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    acc = ["free", "follow", "strain", "strain01", "aggregate", "horizon"]
    reference = REFERENCE
    if quick:       # minutes, not half an hour: fewer measures, shorter runs, a 0.5 ms reference
        acc = ["free", "follow", "strain01", "aggregate", "horizon"]
        reference = replace(REFERENCE, dt_ms=0.5)
    # 1. the reference (also the horizon's reference trajectory)
    ref_file = CACHE / f"reference{'-quick' if quick else ''}.json"
    print(f"reference: {reference.label}", flush=True)
    ref = _spawn(reference, acc, quick, 1)
    if "error" in ref:
        print(f"reference failed: {ref['error']}", file=sys.stderr)
        return 1
    ref_file.write_text(json.dumps({"traj": ref.pop("traj")}))
    # 2. every method, two at a time on one thread each
    ms = methods(quick)
    print(f"{len(ms)} methods, accuracy runs ...", flush=True)
    res = _pool([(m, acc, quick, 1, ref_file) for m in ms], 2)
    # skin: cost only matters (results must not change): accuracy on 'follow' + 'horizon', then cost
    sk = skin_methods(quick)
    res_sk = _pool([(m, ["follow", "horizon"], quick, 1, ref_file) for m in sk], 2)
    # 3. cost, one at a time on all cores (explicit cost does not depend on dt: one per precision)
    threads = os.cpu_count() or 1
    print("cost runs ...", flush=True)
    cost_of = {}
    for m in ms + sk + [reference]:
        key = (m.integrator, m.contacts, m.precision, m.tol, m.skin_um, m.dt_ms if m.integrator == "imex" else 0)
        if key in cost_of:
            continue
        states = ["cost:start"] if quick else ["cost:start", "cost:dense"]
        cost_of[key] = _spawn(m, states, quick, threads)
    rows = []
    for r in [ref] + res + res_sk:
        m = Method(**r["method"])
        key = (m.integrator, m.contacts, m.precision, m.tol, m.skin_um, m.dt_ms if m.integrator == "imex" else 0)
        c = cost_of.get(key, {})
        row = {"label": r["label"], "family": r["family"], **r["method"], **errors(r, ref),
               "error": r.get("error", "")}
        for k, v in c.items():
            if k.startswith("cost_"):
                row[k] = v
        steps_per_h = 3600.0 / (m.dt_ms * 1e-3)
        # S3 over 6 h: from few contacts (its start) to aggregates whose cores are as dense as S13: the mean
        parts = [c.get(f"cost_{k}_ms_per_step") for k in ("start", "dense")]
        parts = [x for x in parts if x]
        ms_step = float(np.mean(parts)) if parts else None
        row["wall_s_per_sim_hour"] = steps_per_h * ms_step * 1e-3 if ms_step else float("nan")
        row["skin_study"] = r in res_sk
        rows.append(row)
    _write_csv(out / "accuracy.csv", rows)
    _plot(out / "accuracy.png", [r for r in rows if not r["skin_study"]])
    _write_md(out / "accuracy.md", rows, quick, time.perf_counter() - t_start, reference)
    print(f"wrote {out / 'accuracy.csv'}, {out / 'accuracy.png'}, {out / 'accuracy.md'} "
          f"({time.perf_counter() - t_start:.0f} s)")
    return 0


# ---------------------------------------------------------------------------------------------- outputs
CSV_COLS = ["label", "family", "integrator", "contacts", "dt_ms", "precision", "tol", "skin_um", "skin_study",
            "err_free", "err_follow", "follow_peak_vb", "err_strain", "strain_mean_J", "err_edge", "edge_speed_vb",
            "horizon_s", "err_max", "cost_start_ms_per_step", "cost_start_cpu_ms_per_step",
            "cost_start_cg_per_step", "cost_dense_ms_per_step", "cost_dense_cpu_ms_per_step",
            "cost_dense_cg_per_step", "wall_s_per_sim_hour", "err_strain01", "strain01_mean_J", "err_speed",
            "err_strain_max", "within_tolerance", "error"]


def _write_csv(path: Path, rows: list[dict]) -> None:
    import csv
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, CSV_COLS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items() if k in CSV_COLS})


def _plot(path: Path, rows: list[dict]) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    fams = sorted({r["family"] for r in rows})
    for fam in fams:
        rs = sorted([r for r in rows if r["family"] == fam and np.isfinite(r.get("wall_s_per_sim_hour", np.nan))],
                    key=lambda r: r["dt_ms"])
        if not rs:
            continue
        x = [r["wall_s_per_sim_hour"] / 60.0 for r in rs]
        y = [max(r.get("err_max", np.nan), 1e-6) if np.isfinite(r.get("err_max", np.nan)) else 10.0 for r in rs]
        ln, = axes[0].loglog(x, y, "o-", label=fam)
        for xi, yi, r in zip(x, y, rs):
            axes[0].annotate(f"{r['dt_ms']:g}", (xi, yi), fontsize=7, textcoords="offset points", xytext=(3, 3))
        h = [r.get("horizon_s", np.nan) / 60.0 for r in rs]
        axes[1].semilogx(x, h, "o-", color=ln.get_color(), label=fam)
    axes[0].axhline(SPEED_TOL, color="k", lw=0.8, ls="--")
    axes[0].axhline(STRAIN_TOL, color="k", lw=0.8, ls=":")
    axes[0].set_xlabel("wall time per simulated hour, S3 paper scale, 2 cores (min)")
    axes[0].set_ylabel("max relative error (speeds, strain energies)")
    axes[0].set_title("error vs cost (labels: dt in ms; tolerances: speeds --, strain :)")
    axes[1].set_xlabel("wall time per simulated hour, S3 paper scale, 2 cores (min)")
    axes[1].set_ylabel("horizon: time within W of the reference (min)")
    axes[1].set_title("50-cell chaotic patch")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _fmt(v, spec=".3g"):
    if isinstance(v, float):
        if math.isnan(v):
            return "–"
        if math.isinf(v):
            return "unstable"
        return format(v, spec)
    return str(v)


def _write_md(path: Path, rows: list[dict], quick: bool, wall: float, reference: Method) -> None:
    cols = [("label", "method"), ("err_free", "free-cell speed dev"), ("err_follow", "follower speed err"),
            ("follow_peak_vb", "follower peak (v_b)"), ("err_strain", "strain err"), ("err_edge", "edge speed err"),
            ("edge_speed_vb", "edge (v_b)"), ("horizon_s", "horizon (s)"),
            ("err_strain01", "strain err k_c=0.01"),
            ("cost_start_ms_per_step", "ms/step S3 start"), ("cost_dense_ms_per_step", "ms/step S13 dense"),
            ("cost_dense_cg_per_step", "CG it/step dense"), ("wall_s_per_sim_hour", "wall min / sim h"),
            ("within_tolerance", "within tol")]
    lines = [f"# Accuracy versus cost{' (quick)' if quick else ''}", "",
             f"Generated by `python -m taichimyxo bench accuracy{' --quick' if quick else ''}` in {wall / 60:.1f} min "
             f"on {os.cpu_count()} cores. Reference: {reference.label}. Errors are relative to the reference "
             "(free cell: to v_b). See ACCURACY.md for the reading.", "",
             "| " + " | ".join(c[1] for c in cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        vals = []
        for k, _ in cols:
            v = r.get(k, float("nan"))
            if k == "wall_s_per_sim_hour" and isinstance(v, float):
                v = v / 60.0
            vals.append(_fmt(v))
        lines.append("| " + " | ".join(vals) + " |")
    path.write_text("\n".join(lines) + "\n")


# ====================================================================================== stability sweep
STAB_DT_MS = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0, 20.0, 30.0, 50.0, 75.0, 100.0, 150.0, 200.0)


def _stab_scene(method: Method, k_a: float, k_c: float):
    return _scene({"domain": {"width_um": 15.0, "height_um": 15.0},
                   "population": {"start": "aligned", "density_cells_per_cm2": 4e7},
                   "cell": {"k_a_N_m": k_a}, "collisions": {"k_c_N_per_m": k_c},
                   "guiding": {"kind": "active"}, "run": {"seed": 3}}, method)


def stability_worker(integrator: str, contacts: str, k_a: float, k_c: float, dts: list[float], steps: int) -> dict:
    """Hard configuration: a high-density aligned patch with random polarities and active following (cells jam,
    push and bend), relaxed first with the explicit step at 0.5 ms for 5 s. From that state, each step size runs
    `steps` steps (at least 10 s simulated); stable = finite, segment lengths within +-20 % of l0, no particle faster
    than max(5 v_b, twice the fastest windowed speed of a 10 s, 0.5 ms explicit run from the same state) over the
    last window, no segments closer than 0.3 W (taichimyxo/invariants.py)."""
    from . import backend
    from .invariants import Bounds, measure
    backend.init("cpu", 1, default_fp="f32")
    prep = _make(_stab_scene(Method("explicit", dt_ms=0.5, precision="mixed"), k_a, k_c),
                 Method("explicit", dt_ms=0.5, precision="mixed"))
    prep.run(_steps(5.0, 0.5))
    pos0, ke0 = prep.positions(), prep.engine_direction()
    # the fastest windowed (1 s) particle speed of the physics itself (explicit, 0.5 ms, over the next 10 s): in
    # this jam, with guiding, flexible cells whip past 5 v_b, so the speed bound is twice this, and at least 5 v_b
    v_ref = 0.0
    for _ in range(10):
        prep.snapshot_speed()
        prep.run(_steps(1.0, 0.5))
        v_ref = max(v_ref, float(prep.particle_speed().max() / prep.scene.raw["cell"]["speed_um_per_min"]))
    prep.close()
    b = Bounds()
    v_bound = max(b.speed_factor, 2.0 * v_ref)
    out = {"v_ref": v_ref, "v_bound": v_bound}
    sims = {}
    fails = 0
    for dt in dts:
        if fails >= 2:          # two failures in a row: larger steps are not tried
            out[str(dt)] = {"stable": False, "why": "not run (two smaller steps failed)"}
            continue
        m = Method(integrator, contacts, dt_ms=dt, precision="mixed")
        sc = _stab_scene(m, k_a, k_c)
        # one compiled simulation per (k_a, k_c): the step size only enters through the time step argument and
        # the neighbour-check interval, which _run_dt handles
        key = "sim"
        if key not in sims:
            sims[key] = _make(sc, m, pos0, ke0)
        sim = sims[key]
        sim.set_state(pos0, ke0)
        n = max(steps, _steps(10.0, dt))
        win = max(10, _steps(1.0, dt))
        ok, why = True, ""
        try:
            _run_dt(sim, n - win, dt)
            sim.snapshot_speed()
            _run_dt(sim, win, dt)
            pos = sim.positions()
            q = measure(pos, sc.box, sc.rest_length, sc.width, sc.k_s, sc.k_a, sc.k_c)
            steps_done = sim.step_count - sim._snap_step
            L = np.array(sc.box)
            d = sim.x.to_numpy().astype(np.float64) - sim.x_snap.to_numpy().astype(np.float64)
            d -= L * np.round(d / L)
            vmax = float(np.sqrt((d * d).sum(-1)).max() / (steps_done * dt * 1e-3) / sc.v_b)
            if not q["finite"]:
                ok, why = False, "non-finite"
            elif not (1 - b.length_tol <= q["len_min"] and q["len_max"] <= 1 + b.length_tol):
                ok, why = False, f"length {q['len_min']:.2f}..{q['len_max']:.2f} l0"
            elif vmax > v_bound:
                ok, why = False, f"speed {vmax:.1f} v_b"
            elif min(q["d_other_min"], q["d_self_min"]) < b.min_distance_W:
                ok, why = False, f"overlap: distance {min(q['d_other_min'], q['d_self_min']):.2f} W"
        except Unstable as e:
            ok, why = False, str(e)[:60]
        except (FloatingPointError, ValueError) as e:
            ok, why = False, str(e)[:60]
        out[str(dt)] = {"stable": ok, "why": why}
        fails = 0 if ok else fails + 1
    for s in sims.values():
        s.close()
    return out


def _run_dt(sim, n: int, dt_ms: float) -> None:
    """sim.run with an arbitrary step; a neighbour overflow (cells blown apart) is an instability."""
    from .sim import NeighbourOverflow
    try:
        sim.run(n, dt_ms * 1e-3)
    except NeighbourOverflow as e:
        raise Unstable(str(e)) from None
    if not np.all(np.isfinite(sim.x.to_numpy())):
        raise Unstable("non-finite positions")


def _stab_spawn(integrator, contacts, k_a, k_c, dts, steps) -> dict:
    cmd = [sys.executable, "-m", "taichimyxo.bench_accuracy", "stability-worker", "--integrator", integrator,
           "--contacts", contacts, "--k-a", repr(k_a), "--k-c", repr(k_c), "--dts", ",".join(map(str, dts)),
           "--steps", str(steps)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
    for line in reversed(p.stdout.splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    why = ((p.stderr or p.stdout).strip().splitlines() or ["no output"])[-1][:80]
    return {str(d): {"stable": False, "why": f"worker failed: {why}"} for d in dts}


def _limit(res: dict) -> float:
    """Largest step such that it and every smaller tested step were stable."""
    lim = 0.0
    for dt in sorted((k for k in res if k[0].isdigit()), key=float):
        if not res[dt]["stable"]:
            break
        lim = float(dt)
    return lim


def stability_main(quick: bool = False, out_dir: str = DEFAULT_OUT, write_limits: bool = False) -> int:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    steps = 200 if quick else 400
    k_as = (1e-17, 1e-15) if quick else K_A
    k_cs = (0.01,) if quick else K_C
    integrators = [("explicit", "coupled", [d for d in STAB_DT_MS if d <= 15.0]),
                   ("imex", "coupled", [d for d in STAB_DT_MS if d >= 5.0]),
                   ("imex", "explicit", [d for d in STAB_DT_MS if d >= 2.0 and d <= 100.0])]
    jobs = [(i, c, ka, kc, dts, steps) for (i, c, dts) in integrators for ka in k_as for kc in k_cs]
    with ThreadPoolExecutor(2) as ex:
        results = list(ex.map(lambda j: _stab_spawn(*j), jobs))
    rows = []
    table = {}
    for (i, c, ka, kc, dts, _), res in zip(jobs, results):
        name = i if (i == "explicit" or c == "coupled") else f"imex-{c}"
        lim = _limit(res)
        dts_run = sorted((k for k in res if k[0].isdigit()), key=float)
        first_bad = next((f"{float(d):g} ms: {res[d]['why']}" for d in dts_run if not res[d]["stable"]), "")
        table.setdefault(name, {})[f"{ka:g}/{kc:g}"] = lim
        rows.append({"integrator": name, "k_a_N_m": ka, "k_c_N_per_m": kc, "limit_ms": lim,
                     "first_unstable": first_bad, "speed_bound_vb": round(res.get("v_bound", float("nan")), 2),
                     "tested_ms": " ".join(f"{float(d):g}" for d in dts_run)})
    import csv
    with open(out / "stability.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    names = list(table)
    lines = ["# Largest stable time step (ms)", "",
             f"`python -m taichimyxo bench stability{' --quick' if quick else ''}` ({(time.perf_counter() - t0) / 60:.1f}"
             " min). Configuration: 15 x 15 µm high-density aligned patch (90 cells, area fraction 1), random "
             "polarities, active following, relaxed 5 s; each step size runs at least "
             f"{steps} steps and 10 s. Stable: finite, segment lengths within ±20 % of l0, windowed (≥ 1 s) speed "
             "≤ max(5 v_b, twice the fastest windowed speed in 10 s of a 0.5 ms explicit run from the same state: flexible "
             "cells in this jam whip past 5 v_b), no segments closer than 0.3 W. A limit is the largest tested step at which it and all smaller ones "
             "were stable.", "",
             "| k_a (N·m) | k_c (N/m) | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for ka in k_as:
        for kc in k_cs:
            key = f"{ka:g}/{kc:g}"
            lines.append(f"| {ka:g} ({K_A_NAME[ka]}) | {kc:g} | " +
                         " | ".join(_fmt(table[n].get(key, float('nan')), "g") for n in names) + " |")
    lines += ["", "First failure per row:", ""]
    for r in rows:
        if r["first_unstable"]:
            lines.append(f"- {r['integrator']} k_a={r['k_a_N_m']:g} k_c={r['k_c_N_per_m']:g}: {r['first_unstable']}")
    (out / "stability.md").write_text("\n".join(lines) + "\n")
    if write_limits and not quick:
        data = {}
        if LIMITS_JSON.is_file():
            try:
                data = json.loads(LIMITS_JSON.read_text())
            except ValueError:
                data = {}
        for n in names:
            data[n] = table[n]
        data["defaults"] = default_steps(data)
        LIMITS_JSON.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    print("\n".join(lines))
    return 0


# the largest step of each integrator within the tolerance (SPEED_TOL, STRAIN_TOL) in the accuracy study
# (benchmarks/results/accuracy.csv, read in ACCURACY.md); a scene's default is this, capped at half the measured
# stability limit for its stiffness
ACCURATE_DT_MS = {"explicit": 2.0, "imex": 1.0}


def default_steps(limits: dict) -> dict:
    out = {}
    for integ, acc in ACCURATE_DT_MS.items():
        tab = limits.get(integ, {})
        out[integ] = {}
        for key, lim in tab.items():
            if lim <= 0:
                continue
            d = min(acc, 0.5 * lim)
            # round down onto the grid of tested steps
            grid = [g for g in (0.25,) + STAB_DT_MS if g <= d]
            out[integ][key] = grid[-1] if grid else 0.25
    return out


# ====================================================================================== entry point for workers
def _cli(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m taichimyxo.bench_accuracy")
    sub = p.add_subparsers(dest="cmd", required=True)
    w = sub.add_parser("worker")
    w.add_argument("--method", required=True)
    w.add_argument("--measures", required=True)
    w.add_argument("--threads", type=int, default=1)
    w.add_argument("--quick", action="store_true")
    w.add_argument("--ref")
    s = sub.add_parser("stability-worker")
    s.add_argument("--integrator", required=True)
    s.add_argument("--contacts", default="coupled")
    s.add_argument("--k-a", type=float, required=True)
    s.add_argument("--k-c", type=float, required=True)
    s.add_argument("--dts", required=True)
    s.add_argument("--steps", type=int, default=400)
    a = sub.add_parser("accuracy")
    a.add_argument("--quick", action="store_true")
    a.add_argument("--out", default=DEFAULT_OUT)
    st = sub.add_parser("stability")
    st.add_argument("--quick", action="store_true")
    st.add_argument("--out", default=DEFAULT_OUT)
    st.add_argument("--write-limits", action="store_true", help="also write taichimyxo/stability_limits.json")
    args = p.parse_args(argv)
    if args.cmd == "worker":
        r = worker(Method(**json.loads(args.method)), args.measures.split(","), args.quick, args.threads, args.ref)
        print(json.dumps(r))
        return 0
    if args.cmd == "stability-worker":
        r = stability_worker(args.integrator, args.contacts, args.k_a, args.k_c,
                             [float(x) for x in args.dts.split(",")], args.steps)
        print(json.dumps(r))
        return 0
    if args.cmd == "accuracy":
        return main(args.quick, args.out)
    return stability_main(args.quick, args.out, write_limits=args.write_limits)


if __name__ == "__main__":
    raise SystemExit(_cli())
