"""Shared pieces of the benchmarks in this folder (not part of the installed package).

Every benchmark is a script run from a clone, `python benchmarks/<name>.py [--quick] [--out DIR]`, writing into
benchmarks-results/ in the current directory unless --out names a folder (`--out benchmarks/results` updates the
committed results). They use only taichimyxo's public API (taichimyxo.io.scene, taichimyxo.runtime.simulation,
taichimyxo.physics.placement, taichimyxo.physics.invariants, taichimyxo.runtime.backend).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
try:                                    # a clone without `pip install -e .`: the package is next door
    import taichimyxo  # noqa: F401
except ImportError:
    sys.path.insert(0, str(HERE.parent))

DEFAULT_OUT = "benchmarks-results"      # relative to the current directory: never the source tree or the package
REF_DT_MS = 0.25
W_UM = 0.5
L0 = 4.5 / 7


def parser(doc: str, quick_help: str = "a reduced version (minutes)") -> argparse.ArgumentParser:
    """The common command line: --quick and --out."""
    p = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    p.add_argument("--quick", action="store_true", help=quick_help)
    p.add_argument("--out", default=DEFAULT_OUT,
                   help=f"folder for the results (default {DEFAULT_OUT}/ in the current directory)")
    return p


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


class Unstable(RuntimeError):
    pass


def scene_for(data: dict, method: Method):
    """A scene from a partial scene dict, with the method's run settings and no movie."""
    from taichimyxo.io.scene import Scene
    d = json.loads(json.dumps(data))
    d.setdefault("output", {})["movie"] = False
    d.setdefault("run", {}).update(method.run_overrides())
    return Scene.from_dict(d, where="bench")


def make(scene, method: Method, positions=None, ke=None):
    """The scene's simulation; imex with the method's contact treatment and CG tolerance."""
    from taichimyxo.runtime.simulation import Simulation
    if method.integrator == "imex":
        return Simulation.from_positions(scene, positions, ke, contacts=method.contacts,
                                         tol=method.tol)
    return Simulation.from_positions(scene, positions, ke)


def time_steps(sim, steps: int, warm: int) -> dict:
    """Wall time of `steps` steps after `warm` steps: taichimyxo.interface.bench.time_steps (in the package, so the
    installed
    `python -m taichimyxo bench` has it too)."""
    from taichimyxo.interface.bench import time_steps as package_time_steps
    return package_time_steps(sim, steps, warm)


def steps(t_s: float, dt_ms: float) -> int:
    return max(1, int(round(t_s / (dt_ms * 1e-3))))


def run(sim, n: int, dt_ms: float | None = None) -> None:
    """sim.run (at dt_ms, or the scene's step); a neighbour overflow (cells blown apart) or a non-finite position
    is an instability."""
    from taichimyxo.runtime.simulation import NeighbourOverflow
    try:
        sim.advance(n, None if dt_ms is None else dt_ms * 1e-3)
    except NeighbourOverflow as e:
        raise Unstable(str(e)) from None
    if not np.all(np.isfinite(sim.wrapped_positions())):
        raise Unstable("non-finite positions")


def straight(centre, angle, N=8):
    from taichimyxo.physics.placement import straight_cell
    return straight_cell(np.asarray(centre, float), angle, N, L0)


def json_from_worker(cmd: list[str], timeout: float, env=None) -> dict:
    """Run a worker process; its result is the last line of its stdout that is a JSON object. Raises
    subprocess.TimeoutExpired; returns {"error": last line of its output} when there is none."""
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
    for line in reversed(p.stdout.splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    return {"error": ((p.stderr or p.stdout).strip().splitlines() or ["no output"])[-1][:300]}


def fmt(v, spec=".3g"):
    if isinstance(v, float):
        if math.isnan(v):
            return "–"
        if math.isinf(v):
            return "unstable"
        return format(v, spec)
    return str(v)


def write_csv(path: Path, rows: list[dict], cols: list[str] | None = None, float_fmt: str | None = None) -> None:
    """rows as CSV with the columns `cols` (default: the first row's keys; other keys are left out)."""
    import csv
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, cols or list(rows[0]), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (format(v, float_fmt) if float_fmt and isinstance(v, float) else v) for k, v in r.items()})


def run_in_tree(tree, code: str, args: list, timeout: float = 1800):
    """Run `code` (python -c) with `args` in the source tree `tree` (its own process, the package imported from
    there); the dict of the last JSON line it prints, or RuntimeError with the end of its error output."""
    import os
    env = dict(os.environ, PYTHONPATH=str(tree))
    p = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, cwd=tree,
                       env=env, timeout=timeout)
    for line in reversed(p.stdout.splitlines()):
        if line.startswith("{"):
            return json.loads(line)
    raise RuntimeError(f"the worker in {tree} failed: {(p.stderr or p.stdout).strip()[-300:]}")


@contextlib.contextmanager
def worktree(commit: str):
    """An earlier commit checked out into a temporary git worktree (removed afterwards); yields its path."""
    import tempfile
    with tempfile.TemporaryDirectory(prefix="worktree-") as tmp:
        path = Path(tmp) / "tree"
        subprocess.run(["git", "-C", str(HERE.parent), "worktree", "add", "-f", "--detach", str(path), commit],
                       check=True, capture_output=True)
        try:
            yield path
        finally:
            subprocess.run(["git", "-C", str(HERE.parent), "worktree", "remove", "--force", str(path)],
                           capture_output=True)
