"""How kernels launch their loops, per arch, decided in one place.

Every kernel writes, before each top-level loop,

    ti.loop_config(**loops.items)       a loop over particles, cells, segments, grid bins or blocks of them
    ti.loop_config(**loops.one_thread)  a loop of one iteration (scalar updates inside a kernel), or a scan or
                                        reduction that runs in one thread

and selects the few algorithms that differ with `ti.static(loops.gpu)`; `loops` is the State's LoopShape, fixed when
the Simulation is built, so every choice is made at compile time and a kernel holds one shape only.

  cpu  exactly the choices measured on a 2-core CPU (docs/performance.md): Taichi's CPU backend spends ~75 µs
       launching a parallel loop, so below SERIAL_BELOW_SEGMENTS segments, and at any size when Taichi runs on one
       thread, every loop over items runs serially, otherwise in parallel; the neighbour grid's prefix sum runs in
       one thread; the implicit step sums per-block partials of at most 64 blocks (one below SERIAL_BELOW_SEGMENTS,
       whatever the threads, so one and two threads sum alike). Serial and parallel loops give the same numbers.
  gpu  no loop over items is serialized, blocks of GPU_BLOCK_DIM threads (Taichi's default, not yet tuned on a GPU);
       the grid's prefix sum is a two-level blocked scan (blocks of ~sqrt(bins) bins: block totals in parallel, their
       scan in one thread, each block's own scan in parallel); the implicit step keeps one partial per cell and sums
       them in a two-level reduction. Sums keep a fixed order (no atomics in any force or reduction), so a GPU run
       is reproducible from run to run; it differs from the CPU's by rounding (fast math, other groupings).
  spread  on the CPU's parallel shape the heavy loops over cells and segments (the pair loop, the per-cell loop,
       the neighbour search) visit the cells in a spread order, i -> i * stride mod n_cells (State.cell_of): the
       threads' shares of such a loop follow the index range, and a late S3 holds more contacts in some part of it,
       so in index order one thread idles while the other finishes (docs/performance.md, "The threads' shares").
       Each item's result does not depend on the order, so the numbers are the same.

The shape follows the arch Taichi runs on (CUDA, Vulkan, Metal, ...: gpu), unless forced: the environment variable
TAICHIMYXO_LOOP_SHAPE=cpu|gpu, or Simulation(..., loop_shape="gpu"). Forced to gpu on the CPU, the CPU compiles and
runs the GPU-shaped kernels: that is how the GPU's algorithms are tested on a machine without one
(tests/test_gpu.py).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import taichi as ti

SHAPES = ("cpu", "gpu")
# Taichi's CPU backend spends ~75 µs launching a parallel loop; below a few thousand segments one thread running the
# loops serially is faster than two threads (measured: benchmarks/throughput.py).
SERIAL_BELOW_SEGMENTS = int(os.environ.get("TAICHIMYXO_SERIAL_BELOW", "3000"))
CPU_MAX_BLOCKS = 64            # the implicit step's partial sums on the CPU: at most this many blocks of cells
GPU_BLOCK_DIM = 128            # threads per GPU block for every loop over items


class LoopShapeError(ValueError):
    pass


def arch_kind() -> str:
    """'gpu' when Taichi runs on a GPU arch, else 'cpu' (Taichi must be initialised)."""
    arch = ti.lang.impl.current_cfg().arch
    gpus = [getattr(ti, a) for a in ("cuda", "vulkan", "metal", "opengl", "gles", "dx11", "dx12", "amdgpu")
            if hasattr(ti, a)]
    return "gpu" if arch in gpus else "cpu"


@dataclass(frozen=True)
class LoopShape:
    kind: str                  # "cpu" | "gpu"
    serial: bool               # loops over items run in one thread (CPU: small systems, or Taichi on one thread)
    small: bool = False        # below SERIAL_BELOW_SEGMENTS: what the implicit step's blocks follow

    @property
    def gpu(self) -> bool:
        return self.kind == "gpu"

    @property
    def items(self) -> dict:
        """ti.loop_config keywords for a loop over items."""
        return {"block_dim": GPU_BLOCK_DIM} if self.gpu else {"serialize": self.serial}

    @property
    def one_thread(self) -> dict:
        """ti.loop_config keywords for a loop of one iteration, or a scan in one thread (any arch)."""
        return {"serialize": True}

    @property
    def spread(self) -> bool:
        """Parallel loops over cells and segments visit the cells in a spread order (State.cell_of): the CPU's."""
        return not self.gpu and not self.serial

    def cell_blocks(self, n_cells: int) -> int:
        """Blocks of cells whose partial sums the implicit step reduces in a fixed order."""
        if self.gpu:
            return n_cells
        return 1 if self.small else min(n_cells, CPU_MAX_BLOCKS)      # by size only: 1 and 2 threads sum alike


def spread_stride(n: int) -> int:
    """The stride of State.cell_of's order, i -> i * stride mod n: the integer nearest n (sqrt 5 - 1) / 2 that is
    coprime with n (so the order visits every cell once), whose multiples spread evenly over the range."""
    k = max(1, round(n * (math.sqrt(5.0) - 1.0) / 2.0))
    while math.gcd(k, n) != 1:
        k += 1
    return k


def scan_block(n: int) -> int:
    """Entries per block of the two-level scans and reductions of the gpu shape: ~sqrt(n), so the one-thread step
    over block totals and each block's own pass are equally short."""
    return max(1, math.isqrt(max(1, n - 1)) + 1)


def shape_for(n_segments: int, kind: str | None = None) -> LoopShape:
    """The loop shape of a system of n_segments: `kind` if given, else TAICHIMYXO_LOOP_SHAPE, else the arch's."""
    kind = kind or os.environ.get("TAICHIMYXO_LOOP_SHAPE") or arch_kind()
    if kind not in SHAPES:
        raise LoopShapeError(f"loop shape {kind!r}: one of {', '.join(SHAPES)} (TAICHIMYXO_LOOP_SHAPE)")
    small = kind == "cpu" and n_segments < SERIAL_BELOW_SEGMENTS
    # on one thread a parallel loop is the launch cost and nothing gained (docs/performance.md "The step kernel")
    one_thread = kind == "cpu" and ti.lang.impl.current_cfg().cpu_max_num_threads == 1
    return LoopShape(kind, serial=small or one_thread, small=small)
