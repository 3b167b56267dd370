"""The particles and cells: positions, engine directions and the layout every unit indexes by.

Layout. Particle p = c * N + k is particle k of cell c; segment s = c * (N - 1) + k joins particles k and k + 1.
Positions are stored wrapped into the box; all differences use the minimum image. Positions are in position
precision (f64 for 'f64' and 'mixed'), forces and offsets in force precision (f32 for 'f32' and 'mixed'): in f32 a
200 µm coordinate resolves ~1.5e-5 µm while a cell moves ~1.3e-4 µm per 2 ms step (docs/model.md "Precision").
"""

import math
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..io.frame import unwrap_chains
from ..runtime.launch import LoopShape, shape_for, spread_stride
from .geometry import SEGMENT_LENGTH_TOL  # noqa: F401,E402  (re-exported; defined where taichi is not imported)
from .geometry import min_image as np_min_image


@ti.func
def min_image(d, Lx: ti.template(), Ly: ti.template()):
    """Minimum image of the difference of two positions stored in the box (|d| < L per axis, true of every use):
    d - L round(d / L), bit for bit, as a compare and select per axis (the division and the libm round call cost
    as much as a contact's arithmetic; measured in benchmarks/results/perf/README.md)."""
    return ti.Vector([_wrap_diff(d[0], Lx), _wrap_diff(d[1], Ly)])


@ti.func
def _wrap_diff(a, L: ti.template()):
    r = a
    if a >= 0.5 * L:
        r = a - L
    elif a <= -0.5 * L:
        r = a + L
    return r


@ti.func
def _wrap_coord(a, L: ti.template()):
    """a - L floor(a / L) for a in [-L, 2L), bit for bit (positions move far less than a box per step)."""
    r = a
    if a < 0.0:
        r = a + L
    elif a >= L:
        r = a - L
    return r


@ti.func
def perp(v):
    return ti.Vector([-v[1], v[0]])


@ti.func
def closest_points(p1, q1, p2, q2):
    """Closest points of segments p1-q1 and p2-q2: returns (s, t, c1, c2) with s, t in [0, 1]. Parallel overlapping
    segments take the middle of the overlap (see taichimyxo/physics/geometry.py, the numpy twin)."""
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = d1.dot(d1)
    e = d2.dot(d2)
    f = d2.dot(r)
    c = d1.dot(r)
    b = d1.dot(d2)
    eps = 1e-12
    s = a * 0.0          # typed like the inputs (f32 or f64), not the default float
    t = a * 0.0
    if a > eps and e > eps:
        denom = a * e - b * b
        if denom > 1e-9 * a * e:
            s = ti.math.clamp((b * f - c * e) / denom, 0.0, 1.0)
        else:
            t0 = ti.math.clamp(-c / a, 0.0, 1.0)
            t1 = ti.math.clamp((b - c) / a, 0.0, 1.0)
            s = 0.5 * (t0 + t1)
        t = (b * s + f) / e
        if t < 0.0:
            t = 0.0
            s = ti.math.clamp(-c / a, 0.0, 1.0)
        elif t > 1.0:
            t = 1.0
            s = ti.math.clamp((b - c) / a, 0.0, 1.0)
    elif a > eps:
        s = ti.math.clamp(-c / a, 0.0, 1.0)
    elif e > eps:
        t = ti.math.clamp(f / e, 0.0, 1.0)
    return s, t, p1 + d1 * s, p2 + d2 * t


@dataclass(frozen=True)
class Layout:
    """Compile-time sizes and settings shared by every unit (everything else belongs to the unit that uses it)."""
    n_cells: int
    N: int
    Lx: float
    Ly: float
    W: float              # cell width, µm: contacts, guiding gaps and the neighbour-list radius use it
    l0: float             # rest length of a segment, µm
    precision: str        # f32 | f64 | mixed
    seed: int
    dt: float             # the scene's step, s

    @classmethod
    def from_scene(cls, sc) -> "Layout":
        return cls(n_cells=sc.n_cells, N=sc.N, Lx=sc.box[0], Ly=sc.box[1], W=sc.width, l0=sc.rest_length,
                   precision=sc.precision, seed=sc.seed, dt=sc.dt)

    @property
    def n_particles(self) -> int:
        return self.n_cells * self.N

    @property
    def n_segments(self) -> int:
        return self.n_cells * (self.N - 1)


@ti.data_oriented
class State:
    """Positions x (wrapped), engine directions ke = ±1 (+1: particle 0 is the head) and the speed-window snapshot.
    `loops` (taichimyxo/runtime/launch.py) is how every unit's kernels launch their loops: the arch's shape unless
    given."""

    def __init__(self, layout: Layout, builder: ti.FieldsBuilder, loops: LoopShape | None = None):
        self.layout = L = layout
        self.N, self.Lx, self.Ly = L.N, L.Lx, L.Ly
        self.n_cells, self.n_p, self.n_s = L.n_cells, L.n_particles, L.n_segments
        self.pdt = ti.f64 if L.precision in ("f64", "mixed") else ti.f32
        self.fdt = ti.f64 if L.precision == "f64" else ti.f32
        self.loops = loops or shape_for(self.n_s)
        self.serial = self.loops.serial                     # loops over items in one thread (CPU, small systems)
        self.stride = spread_stride(self.n_cells)           # cell_of's order
        self.x = self.vec(builder, self.n_p, self.pdt)            # positions, wrapped
        self.x_snap = self.vec(builder, self.n_p, self.pdt)       # positions at the start of the speed window
        self.ke = self.scalar(builder, self.n_cells, ti.i32)      # engine direction k_e = ±1
        self.snap_step = 0

    @staticmethod
    def vec(builder, n, dtype):
        f = ti.Vector.field(2, dtype=dtype)
        builder.dense(ti.i, n).place(f)
        return f

    @staticmethod
    def scalar(builder, n, dtype):
        f = ti.field(dtype=dtype)
        builder.dense(ti.i, n).place(f)
        return f

    # ------------------------------------------------------------------ layout, in kernels
    @ti.func
    def cell_of(self, i):
        """The cell the i-th iteration of a loop over cells handles: i, or in the spread order of the CPU's parallel
        loops (taichimyxo/runtime/launch.py) i * stride mod n_cells, every cell once."""
        c = i
        if ti.static(self.loops.spread):
            c = ti.cast(ti.cast(i, ti.i64) * ti.static(self.stride) % ti.static(self.n_cells), ti.i32)
        return c

    @ti.func
    def segment_of(self, i):
        """The segment the i-th iteration of a loop over segments handles: cell_of's order, each cell's segments
        together."""
        return self.cell_of(i // (self.N - 1)) * (self.N - 1) + i % (self.N - 1)

    @ti.func
    def seg_ends(self, s):
        c = s // (self.N - 1)
        p = c * self.N + s % (self.N - 1)
        return p, p + 1

    @ti.func
    def mi(self, d):
        """Minimum image of a difference vector."""
        return min_image(d, self.Lx, self.Ly)

    @ti.func
    def seg_mid(self, s):
        a, b = self.seg_ends(s)
        m = self.x[a] + 0.5 * self.mi(self.x[b] - self.x[a])
        return ti.Vector([_wrap_coord(m[0], self.Lx), _wrap_coord(m[1], self.Ly)])

    @ti.func
    def head_seg(self, c):
        return c * (self.N - 1) + (0 if self.ke[c] > 0 else self.N - 2)

    @ti.func
    def tail_seg(self, c):
        return c * (self.N - 1) + (self.N - 2 if self.ke[c] > 0 else 0)

    @ti.func
    def wrap(self, xn):
        return ti.Vector([_wrap_coord(xn[0], self.Lx), _wrap_coord(xn[1], self.Ly)])

    # ------------------------------------------------------------------ host side
    def load(self, positions, engine_direction) -> None:
        pos = np.asarray(positions, dtype=np.float64).reshape(self.n_cells, self.N, 2)
        L = np.array([self.Lx, self.Ly])
        self.x.from_numpy(np.mod(pos, L).reshape(-1, 2).astype(np.float64 if self.pdt == ti.f64 else np.float32))
        self.ke.from_numpy(np.where(np.asarray(engine_direction) >= 0, 1, -1).astype(np.int32))

    def positions(self) -> np.ndarray:
        """(n_cells, N, 2) float64, chains unwrapped, particle 0 in the box."""
        x = self.x.to_numpy().astype(np.float64).reshape(self.n_cells, self.N, 2)
        return unwrap_chains(x, (self.Lx, self.Ly))

    @ti.kernel
    def _copy_snap(self):
        ti.loop_config(**self.loops.items)
        for p in range(self.n_p):
            self.x_snap[p] = self.x[p]

    def snapshot(self, step: int) -> None:
        self._copy_snap()
        self.snap_step = step

    def _window(self, step: int, dt: float):
        """Displacement (n_p, 2) f64 since the snapshot and the elapsed time, s (None if none elapsed)."""
        steps = step - self.snap_step
        if steps <= 0:
            return None, 0.0
        d = np_min_image(self.x.to_numpy().astype(np.float64) - self.x_snap.to_numpy().astype(np.float64),
                         (self.Lx, self.Ly))
        return d, steps * dt

    def speed_since_snapshot(self, step: int, dt: float) -> np.ndarray:
        """(n_cells, N) µm/min: displacement since the snapshot over the elapsed time (zeros if none elapsed)."""
        d, t = self._window(step, dt)
        if d is None:
            return np.zeros((self.n_cells, self.N), np.float32)
        sp = np.sqrt((d * d).sum(-1)) / t * 60.0
        return sp.reshape(self.n_cells, self.N).astype(np.float32)

    def velocity_since_snapshot(self, step: int, dt: float) -> np.ndarray:
        """(n_cells, N, 2) µm/min: the displacement vector since the snapshot over the elapsed time (the speed is
        its norm; zeros if none elapsed)."""
        d, t = self._window(step, dt)
        if d is None:
            return np.zeros((self.n_cells, self.N, 2), np.float32)
        return (d / t * 60.0).reshape(self.n_cells, self.N, 2).astype(np.float32)


def list_capacity(cutoff: float, l0: float, W: float, fraction: float = 1.0) -> int:
    """List capacity per segment: segments (or, with fraction < 1, that share of them) whose closest points lie within
    `cutoff` of one segment at the densest packing (area fraction 1: one segment per l0 W), with a margin of 1.6x + 8
    for overlapping cells in aggregates. The region: a segment of length l_max = 1.25 l0 dilated by cutoff, swept by
    the other segment at every orientation (mean area of the Minkowski sum: pi r^2 + 4 r l + 2 l^2 / pi)."""
    r, l = cutoff, 1.25 * l0
    area = math.pi * r * r + 4 * r * l + 2 * l * l / math.pi
    return int(math.ceil(1.6 * fraction * area / (l0 * W))) + 8


def list_capacities(scene) -> dict:
    """The neighbour lists' sizes for a scene (NeighbourList keywords): contact partners within W + skin
    (run.max_neighbours overrides), and, when guiding or suppression is on, the guiding range and the partners per
    cell end (only end segments: 2 of every N - 1 segments)."""
    l0, W, skin = scene.rest_length, scene.width, scene.skin
    out = {"capacity": scene.max_neighbours or list_capacity(W + skin, l0, W)}
    if scene.guiding != "none" or scene.suppression:
        d_g = scene.guiding_range
        out.update(guiding_range=d_g, guiding_capacity=list_capacity(W + d_g + skin, l0, W, 2.0 / (scene.N - 1)))
    return out
