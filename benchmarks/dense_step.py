"""The dense step's cost, split into its parts by counted instructions (callgrind), and the forces check that goes
with every change to it (benchmarks/results/dense_step.md).

    python benchmarks/dense_step.py profile --state "S13 dense" [--skin 0.1] [--dt-ms 4] [--reps 2] [--branch-sim]
    python benchmarks/dense_step.py rebuilds --state "S13 dense" [--skin 0.1] [--dt-ms 4] [--steps 1000]
    python benchmarks/dense_step.py forces --save OUT.npz [--threads 1]   # then: compare A.npz B.npz

profile runs itself under `valgrind --tool=callgrind` (one thread, instrumentation off until the kernels are loaded
and warm) and counts, at one fixed state (the positions restored and the lists rebuilt before each repetition): the
step kernel as a run calls it, the pair loop alone (a kernel with only `Model.pairs`), a neighbour-list build and an
empty kernel's launch; per call, the median of --reps. Taichi's compiled loops have no symbols: each offloaded loop is
one address, so `step_tasks_Ir` lists the step kernel's loops in compile order (the pair loop, then the per-cell
loop; the pair loop is the one `pairs_tasks_Ir` shares). Run it once with `--native` first, so the kernels come from
Taichi's offline cache: a compile under valgrind takes many minutes; with `--native --reps 50` it also gives each
part's best wall time on one thread (`*_best_ms`), the denominator of instructions per second. --branch-sim adds
callgrind's branch simulation: conditional branches executed (Bc) and mispredicted by its model predictor (Bcm), per
part and loop (the model's mispredictions, not the CPU's: an estimate of how branchy a loop is).
rebuilds counts neighbour-list builds over --steps steps from the state (a count, the same under any load).
forces saves Simulation.forces() and both neighbour lists at the check states (S13's start, a jam S13 reaches after
300 steps, S11's lattice at exactly W, a quarter-area S3 after 2000 steps or, with DENSE_STEP_S3_1H=1, the S3 state
after one hour); compare prints, per array, whether two saves are bit for bit equal and their largest difference.
States: "S3 6 h", "S3 1 h" and "S13 dense" (benchmarks/states.py) or a check state ("S13 jam", ...).
"""
from __future__ import annotations

import ctypes
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchlib import HERE

CG_SRC = r"""
#include <valgrind/callgrind.h>
void cg_start(void) { CALLGRIND_START_INSTRUMENTATION; }
void cg_zero(void) { CALLGRIND_ZERO_STATS; }
void cg_dump(const char *label) { CALLGRIND_DUMP_STATS_AT(label); }
"""
CHECK_STATES = ("S13 start", "S13 jam", "S11 start", "S3 guided")


def _callgrind_lib():
    """A tiny shared library issuing callgrind's client requests (no-ops outside valgrind)."""
    tag = hashlib.sha1(CG_SRC.encode()).hexdigest()[:10]
    so = Path(tempfile.gettempdir()) / f"dense_step_cg_{tag}.so"
    if not so.is_file():
        c = so.with_suffix(".c")
        c.write_text(CG_SRC)
        subprocess.run(["gcc", "-O1", "-shared", "-fPIC", "-o", str(so), str(c)], check=True)
    return ctypes.CDLL(str(so))


def make_sim(state: str, skin: float | None, dt_ms: float | None):
    """The Simulation of a benchmark state (benchmarks/states.py) or check state, with the skin and step given."""
    from taichimyxo.interface.bench import scaled_scene
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime.simulation import Simulation
    if state in CHECK_STATES:
        scene, area, *start = check_state(state)
    elif state in ("S3 6 h", "S3 1 h", "S13 dense"):
        import states
        scene, area, start = states.load(state)
    else:
        scene, area, start = state.split()[0], 1.0, None
    # the explicit step kernel is what this profiles: a scene run otherwise (S13: imex-explicit) takes the explicit
    # 2 ms its states were first measured at
    run = {"integrator": "explicit"}
    if Scene.load(scene).integrator != "explicit":
        run["dt_ms"] = 2.0
    if skin is not None:
        run["skin_um"] = skin
    if dt_ms is not None:
        run["dt_ms"] = dt_ms
    sc = scaled_scene(scene, area, run)
    if start is None:
        return Simulation(sc)
    return Simulation.from_positions(sc, start[0], start[1])


def profile(a) -> dict:
    import taichi as ti

    from taichimyxo.runtime import backend
    backend.init("cpu", 1)
    cg = _callgrind_lib()
    sim = make_sim(a.state, a.skin, a.dt_ms)
    model, nl = sim.model, sim.neighbours
    dt = sim.layout.dt

    @ti.kernel
    def pairs_only():
        model.pairs()

    @ti.kernel
    def empty():
        for _ in range(1):
            pass

    x0 = sim.state.x.to_numpy()
    sim.advance(2)                        # compiles (or loads) the step and the build
    pairs_only()
    empty()
    ti.sync()

    def at_state():
        sim.state.x.from_numpy(x0)
        nl.rebuild()
        ti.sync()

    parts = {"step": lambda: sim.integrator.step(dt), "pairs": pairs_only, "rebuild": nl.rebuild, "empty": empty}
    walls = {name: [] for name in parts}
    cg.cg_start()
    for rep in range(a.reps):
        for name, fn in parts.items():
            at_state()
            cg.cg_zero()
            t0 = time.perf_counter()
            fn()
            ti.sync()
            walls[name].append(time.perf_counter() - t0)
            cg.cg_dump(f"{name}:{rep}".encode())
    at_state()
    n = nl.nbr_n.to_numpy()
    info = {"state": a.state, "particles": sim.n_p, "skin_um": sim.scene.skin, "dt_ms": dt * 1e3,
            "listed_pairs": int(n.sum()) // 2, "partners_per_segment": round(float(n.mean()), 2)}
    if a.native:                          # wall times mean something only outside valgrind: best of --reps, ms
        info.update({f"{name}_best_ms": round(1e3 * min(w), 4) for name, w in walls.items()})
    sim.close()
    return info


def _dumps(prefix: str) -> dict:
    """label -> ({event: count}, {JIT task address: {event: count}}) of each callgrind dump written under prefix
    (events: Ir, and Bc, Bcm with --branch-sim). The counts are sums over functions: the dump's own total also counts
    Taichi's idle worker thread spinning, which no function is charged with. Taichi's JIT-compiled tasks have no
    symbols; each is one address."""
    out = {}
    for f in Path(prefix).parent.glob(Path(prefix).name + ".*"):
        label = next((x.split("Client Request: ", 1)[1].strip() for x in f.read_text(errors="replace").splitlines()
                      if x.startswith("desc: Trigger: Client Request: ")), None)
        if label is None:
            continue
        ann = subprocess.run(["callgrind_annotate", "--threshold=100", str(f)], capture_output=True, text=True).stdout
        events, total, jit, body = ["Ir"], {}, {}, False
        for line in ann.splitlines():
            if line.startswith("Events shown:"):
                events = line.split(":", 1)[1].split()
            if "file:function" in line:
                body = True
                continue
            parts = [x for x in line.split() if not x.startswith("(")]     # counts, without their percentages
            if not (body and parts and parts[0].replace(",", "").isdigit()):
                continue
            counts = {}
            for ev, x in zip(events, parts):
                if not x.replace(",", "").isdigit():
                    break
                counts[ev] = int(x.replace(",", ""))
            for ev, n in counts.items():
                total[ev] = total.get(ev, 0) + n
            if "???:0x" in line and line.rstrip().endswith("[???]"):
                jit[line.split("???:")[1].split()[0]] = counts
        out[label] = (total, jit)
    return out


def run_profile(a) -> dict:
    """profile under callgrind; per part the median of its repetitions' counts (instructions; branches with
    --branch-sim)."""
    with tempfile.TemporaryDirectory() as tmp:
        prefix = f"{tmp}/cg.out"
        cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={prefix}"]
        if a.branch_sim:
            cmd.append("--branch-sim=yes")
        cmd += [sys.executable, __file__, "profile", "--inside", "--state", a.state, "--reps", str(a.reps)]
        if a.skin is not None:
            cmd += ["--skin", str(a.skin)]
        if a.dt_ms is not None:
            cmd += ["--dt-ms", str(a.dt_ms)]
        p = subprocess.run(cmd, capture_output=True, text=True)
        info = next((json.loads(x) for x in reversed(p.stdout.splitlines()) if x.startswith("{")), None)
        if info is None:
            raise SystemExit(f"profile failed:\n{p.stdout[-2000:]}\n{p.stderr[-3000:]}")
        d = _dumps(prefix)
    events = ("Ir", "Bc", "Bcm") if a.branch_sim else ("Ir",)
    per, tasks = {}, {}
    for label, (total, jit) in d.items():
        name = label.split(":")[0]
        per.setdefault(name, []).append(total)
        tasks[name] = [jit[k] for k in sorted(jit)]     # by address: the order Taichi compiled them in
    for ev in events:
        info.update({f"{k}_{ev}": int(np.median([t.get(ev, 0) for t in v])) for k, v in per.items()})
        for part in ("step", "rebuild", "pairs"):        # the step kernel's offloaded loops, and the others'
            info[f"{part}_tasks_{ev}"] = [t.get(ev, 0) for t in tasks[part]]
    return info


def rebuilds(a) -> dict:
    from taichimyxo.runtime import backend
    backend.init("cpu", a.threads)
    sim = make_sim(a.state, a.skin, a.dt_ms)
    r0 = sim.rebuilds
    sim.advance(a.steps)
    out = {"state": a.state, "skin_um": sim.scene.skin, "dt_ms": sim.layout.dt * 1e3, "steps": a.steps,
           "rebuilds_per_1000_steps": round(1e3 * (sim.rebuilds - r0) / a.steps, 2)}
    sim.close()
    return out


def check_state(name: str):
    """(scene name, area multiple, positions, engine directions) of a forces-check state, the same whatever the code
    under test (states reached by stepping are stored the first time and reused)."""
    from states import EXACT_ROWS
    from taichimyxo.io.scene import Scene
    from taichimyxo.physics.placement import initial_configuration
    if name in ("S13 start", "S11 start"):
        sc = Scene.load(name.split()[0], EXACT_ROWS)
        pos, ke = initial_configuration(sc)
        return sc.name, 1.0, pos, ke
    if name == "S3 guided" and os.environ.get("DENSE_STEP_S3_1H"):
        import states
        z = np.load(states.S3_1H)
        return "S3", 1.0, z["positions"], z["engine_direction"]
    scene, area, steps = ("S13", 1.0, 300) if name == "S13 jam" else ("S3", 0.25, 2000)
    store = Path(tempfile.gettempdir()) / f"dense_step_{name.replace(' ', '_')}.npz"
    if not store.is_file():
        from taichimyxo.interface.bench import scaled_scene
        from taichimyxo.runtime.simulation import Simulation
        sc = scaled_scene(scene, area, run={"integrator": "explicit", "dt_ms": 2})               # as first measured
        sim = Simulation(sc.with_overrides(EXACT_ROWS) if sc.start == "aligned" else sc)
        sim.advance(steps)
        np.savez(store, positions=sim.positions(), engine_direction=sim.engine_direction())
        sim.close()
    z = np.load(store)
    return scene, area, z["positions"], z["engine_direction"]


def forces(a) -> None:
    from taichimyxo.interface.bench import scaled_scene
    from taichimyxo.runtime import backend
    from taichimyxo.runtime.simulation import Simulation
    backend.init("cpu", a.threads)
    backend.restart_between_simulations()
    out = {}
    for name in (a.states.split(",") if a.states else CHECK_STATES):
        scene, area, pos, ke = check_state(name)
        sim = Simulation.from_positions(scaled_scene(scene, area), pos, ke)
        for k, v in sim.forces().items():
            out[f"{name}|{k}"] = v
        nl = sim.neighbours
        n = nl.nbr_n.to_numpy()
        out[f"{name}|contact list"] = np.concatenate([nl.nbr.to_numpy()[s, :n[s]] for s in range(len(n))] + [n])
        if nl.guide_n is not None:                 # the list exists only where a scene guides
            g = nl.guide_n.to_numpy()
            out[f"{name}|guiding list"] = np.concatenate([nl.guide.to_numpy()[r, :g[r]] for r in range(len(g))] + [g])
        sim.close()
    np.savez(a.save, **out)
    print(f"saved {a.save}")


def compare(a) -> None:
    za, zb = np.load(a.files[0]), np.load(a.files[1])
    for k in sorted(za.files):
        x, y = za[k], zb[k]
        same = x.shape == y.shape and np.array_equal(x, y)
        diff = float(np.max(np.abs(x - y))) if x.shape == y.shape and x.size else float("nan")
        scale = float(np.max(np.abs(x))) if x.size else 0.0
        print(f"{k:32s} {'bit for bit' if same else 'DIFFERENT':12s} max |diff| {diff:.3g} (max |f| {scale:.3g})")


def main() -> None:
    import argparse
    p = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    for name in ("profile", "rebuilds"):
        q = sub.add_parser(name)
        q.add_argument("--state", default="S13 dense")
        q.add_argument("--skin", type=float, default=None)
        q.add_argument("--dt-ms", type=float, default=None)
        q.add_argument("--threads", type=int, default=1)
    q = sub.choices["profile"]
    q.add_argument("--reps", type=int, default=2)
    q.add_argument("--inside", action="store_true", help=argparse.SUPPRESS)
    q.add_argument("--native", action="store_true", help="run the profile once without valgrind (fills the cache)")
    q.add_argument("--branch-sim", action="store_true", help="count branches and the model's mispredictions too")
    sub.choices["rebuilds"].add_argument("--steps", type=int, default=1000)
    q = sub.add_parser("forces")
    q.add_argument("--save", required=True)
    q.add_argument("--threads", type=int, default=1)
    q.add_argument("--states", default="", help="comma-separated check states (default all)")
    q = sub.add_parser("compare")
    q.add_argument("files", nargs=2)
    a = p.parse_args()
    if a.cmd == "profile":
        if a.inside or a.native:
            print(json.dumps(profile(a)), flush=True)
        else:
            print(json.dumps(run_profile(a)), flush=True)
    elif a.cmd == "rebuilds":
        print(json.dumps(rebuilds(a)), flush=True)
    elif a.cmd == "forces":
        forces(a)
    else:
        compare(a)


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    os.environ.setdefault("TAICHIMYXO_THREADS", "1")
    main()
