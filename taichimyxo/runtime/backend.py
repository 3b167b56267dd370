"""Taichi initialisation: one place that picks the arch and thread count, with a clear fallback message."""
from __future__ import annotations

import contextlib
import io
import os
import sys

import taichi as ti

_state = {"arch": None, "threads": None, "fp": None}
# Simulations in this process: how many are open, how many were built since Taichi was (re)initialised, and whether
# to restart Taichi before a new one when none is open (see simulation_starting)
_sims = {"open": 0, "built": 0, "restart_when_idle": False}


class BackendError(RuntimeError):
    pass


def init(arch: str = "cpu", threads: int | None = None, fallback: bool = True, quiet: bool = True,
         default_fp: str | None = None) -> str:
    """Initialise Taichi once per (arch, threads). Returns the arch actually used.

    default_fp ("f32" or "f64") types the float literals and constants in kernels: an f64 scene wants "f64" so its
    constants (rest length, stiffnesses) are not rounded to f32. None keeps the current setting (f32 at first init).
    An unavailable GPU arch falls back to CPU with one line on stderr (or raises BackendError if fallback=False)."""
    threads = threads or int(os.environ.get("TAICHIMYXO_THREADS", "0")) or (os.cpu_count() or 1)
    fp = default_fp or _state["fp"] or "f32"
    if _state["arch"] in (arch, "cpu" if arch != "cpu" and _state.get("fell_back") else None) \
            and _state["threads"] == threads and _state["fp"] == fp:
        return _state["arch"]
    arches = {"cpu": ti.cpu, "cuda": ti.cuda, "vulkan": ti.vulkan, "metal": ti.metal, "gpu": ti.gpu}
    if arch not in arches:
        raise BackendError(f"--arch {arch!r}: allowed values are cpu, cuda, vulkan, metal, gpu")
    kw = dict(cpu_max_num_threads=threads, offline_cache=True, log_level=ti.ERROR if quiet else ti.INFO,
              default_fp=ti.f64 if fp == "f64" else ti.f32, random_seed=0)
    used = arch
    if arch != "cpu":
        ti.init(arch=arches[arch], **kw)
        if ti.lang.impl.current_cfg().arch == ti.cpu or ti.lang.impl.current_cfg().arch == ti.x64 or \
                ti.lang.impl.current_cfg().arch == ti.arm64:
            if not fallback:
                _state.update(arch=None, threads=None, fp=None)    # Taichi was restarted (on the CPU): re-init next
                raise BackendError(f"--arch {arch}: not available on this machine")
            print(f"taichimyxo: arch {arch} is not available here; running on the CPU instead", file=sys.stderr)
            used = "cpu"
    else:
        ti.init(arch=ti.cpu, **kw)
    _state.update(arch=used, threads=threads, fp=fp, fell_back=used != arch)
    return used


def ensure(arch: str | None = None, threads: int | None = None, default_fp: str | None = None) -> str:
    """Taichi on `arch` with `threads` and the float literals `default_fp`; what is None stays as Taichi already
    runs (when it does not: the CPU, all cores or TAICHIMYXO_THREADS). Returns the arch used."""
    if _state["arch"] is not None:
        arch = arch or _state["arch"]
        threads = threads or _state["threads"]
    return init(arch or "cpu", threads, default_fp=default_fp)


def threads() -> int | None:
    """The CPU threads Taichi runs with (None before it starts)."""
    return _state["threads"]


def reset() -> None:
    ti.reset()
    _state.update(arch=None, threads=None, fp=None)
    _sims.update(open=0, built=0)


def restart_between_simulations(on: bool = True) -> None:
    """Restart Taichi before each Simulation built while no other is open (for the test suite and for callers that
    build many Simulations one after another in one process). Taichi's offline cache keys a compiled kernel by the
    ids of the fields it touches (taichi/analysis/gen_offline_cache_key.cpp), ids that only a restart starts again:
    without it, a second Simulation of the same scene compiles every kernel again (~10 s) where, after a restart, it
    loads them from the cache (~1 s). Off by default: a restart frees every Taichi field of the process, also ones
    a caller made itself."""
    _sims["restart_when_idle"] = bool(on)


def simulation_starting() -> None:
    """Called by each Simulation before it allocates its fields."""
    if _sims["restart_when_idle"] and _sims["open"] == 0 and _sims["built"] > 0 and _state["arch"] is not None:
        with contextlib.redirect_stdout(io.StringIO()):    # Taichi's start banner, not the caller's output
            restart()
    _sims["open"] += 1
    _sims["built"] += 1


def simulation_closed() -> None:
    """Called once by each Simulation when it frees its fields."""
    _sims["open"] = max(0, _sims["open"] - 1)


def restart() -> str:
    """Taichi restarted with the current arch, threads and float literals, so the next fields get the ids of a fresh
    process (Taichi's offline cache keys a kernel by them: a kernel compiled by another process is then loaded)."""
    arch, threads, fp = _state["arch"], _state["threads"], _state["fp"]
    if arch is None:
        raise BackendError("restart: Taichi is not initialised")
    reset()
    return init(arch, threads, fallback=False, default_fp=fp)
