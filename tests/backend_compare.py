"""One scene computed by two backends (an arch and a loop shape each, taichimyxo/runtime/launch.py) and compared: the
code of the `gpu` tests (CUDA against the CPU) and of their CPU stand-in (the GPU-shaped kernels on the CPU against the
CPU-shaped ones), tests/test_gpu.py.

What is compared, and how closely (TOLERANCES, per precision):
  lists       the contact rows, their `rev` slots, the guiding rows and the grid's bin starts at the start: exactly
              (a list is integers; both shapes sort every row)
  forces      internal (springs + bending), contact and total forces at the start: max |difference| over the
              largest total force
  run         positions after a short run: max |difference| in µm; engine directions (reversals, suppression):
              equal but for a few cells; the slime grid: elements differing by more than 1e-3, as a fraction
Gather, don't scatter: every force is summed in list order on any shape, so the CPU's two shapes agree bit for bit
where the compiler keeps the arithmetic (measured: they do); a GPU may round differently (fast math, fused
multiply-adds), which the tolerances allow.

With TAICHIMYXO_GPU_REPORT=path every comparison appends one JSON line (what, precision, the measured differences)
to that file: benchmarks/gpu_check.sh keeps the numbers a GPU run measured.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

TOLERANCES = {              # precision -> largest accepted difference
    "f64": {"force_rel": 1e-9, "pos_um": 1e-8, "slime_frac": 1e-3, "ke_cells": 0},
    "mixed": {"force_rel": 1e-4, "pos_um": 1e-4, "slime_frac": 1e-2, "ke_cells": 1},
    "f32": {"force_rel": 1e-4, "pos_um": 1e-3, "slime_frac": 1e-2, "ke_cells": 1},
}


@dataclass(frozen=True)
class Backend:
    arch: str                       # cpu | cuda
    loop_shape: str | None = None   # cpu | gpu (None: the arch's)

    def __str__(self):
        return f"{self.arch}/{self.loop_shape or 'native'}"


def start_backend(backend: Backend, precision: str) -> None:
    """Taichi on the backend's arch, no fallback, with the literals the command line uses for this precision
    (f64 for f64 scenes, f32 otherwise), 2 threads on the CPU (the tests' count)."""
    from taichimyxo.runtime import backend as tb
    tb.init(backend.arch, int(os.environ.get("TAICHIMYXO_THREADS", "2")), fallback=False,
            default_fp="f64" if precision == "f64" else "f32")


def _rows(field, counts):
    a = field.to_numpy()
    return [a[r, :n].copy() for r, n in enumerate(counts)]


def capture(scene, positions, engine_direction, backend: Backend, steps: int, forces: bool = True) -> dict:
    """What the backend computes for the scene from these positions: lists and forces at the start, then the state
    after `steps` steps. Builds, uses and closes its own Simulation."""
    from taichimyxo.runtime.simulation import Simulation
    start_backend(backend, scene.precision)
    sim = Simulation.from_positions(scene, positions, engine_direction, loop_shape=backend.loop_shape)
    try:
        nl = sim.neighbours
        n = nl.nbr_n.to_numpy()
        out = {"nbr": _rows(nl.nbr, n), "rev": _rows(nl.rev, n), "bin_start": nl.bin_start.to_numpy(),
               "shape": sim.state.loops.kind}
        if nl.guide_lists:
            out["guide"] = _rows(nl.guide, nl.guide_n.to_numpy())
        if forces:
            out["forces"] = {k: v for k, v in sim.forces().items() if k != "tangent"}
        sim.advance(steps)
        out.update(positions=sim.positions(), ke=sim.engine_direction().astype(int), rebuilds=sim.rebuilds,
                   cg_iterations=sim.solver_stats().get("cg_iterations", 0))
        if sim.model.slime is not None:
            out["slime"] = sim.model.slime.slime.to_numpy()
    finally:
        sim.close()
    return out


def differences(ref: dict, cand: dict) -> dict:
    """The measured differences between two captures."""
    d = {"lists_equal": all(len(ref[k]) == len(cand[k]) and all(np.array_equal(a, b) for a, b in zip(ref[k], cand[k]))
                            for k in ("nbr", "rev", "guide") if k in ref) and
         np.array_equal(ref["bin_start"], cand["bin_start"])}
    if "forces" in ref:
        scale = max(np.abs(ref["forces"]["total"]).max(), 1e-30)
        d["force_rel"] = max(float(np.abs(ref["forces"][k] - cand["forces"][k]).max()) / scale for k in ref["forces"])
    d["pos_um"] = float(np.abs(ref["positions"] - cand["positions"]).max())
    d["ke_cells"] = int(np.count_nonzero(ref["ke"] != cand["ke"]))
    d["rebuilds"] = (int(ref["rebuilds"]), int(cand["rebuilds"]))
    d["cg_iterations"] = (int(ref["cg_iterations"]), int(cand["cg_iterations"]))
    if "slime" in ref:
        diff = np.abs(ref["slime"] - cand["slime"]).max(-1)
        d["slime_frac"] = float(np.count_nonzero(diff > 1e-3)) / diff.size
    return d


def report(what: str, precision: str, diffs: dict, **extra) -> None:
    path = os.environ.get("TAICHIMYXO_GPU_REPORT")
    if path:
        with open(path, "a") as f:
            f.write(json.dumps({"what": what, "precision": precision, **diffs, **extra}, default=str) + "\n")


def check(diffs: dict, precision: str) -> list[str]:
    """The differences beyond the precision's tolerances (empty: within)."""
    tol = TOLERANCES[precision]
    bad = [] if diffs["lists_equal"] else ["neighbour lists differ"]
    bad += [f"{k} = {diffs[k]:.3g} > {tol[k]:g}" for k in ("force_rel", "pos_um", "slime_frac", "ke_cells")
            if k in diffs and diffs[k] > tol[k]]
    return bad


def compare(scene, positions, engine_direction, ref: Backend, cand: Backend, steps: int, what: str,
            forces: bool = True) -> dict:
    """Capture the scene on both backends, report the differences, and return them with any beyond tolerance
    ('beyond')."""
    a = capture(scene, positions, engine_direction, ref, steps, forces)
    b = capture(scene, positions, engine_direction, cand, steps, forces)
    d = differences(a, b)
    d["beyond"] = check(d, scene.precision)
    report(what, scene.precision, d, reference=str(ref), candidate=str(cand), shapes=(a["shape"], b["shape"]))
    d["shapes"] = (a["shape"], b["shape"])
    return d
