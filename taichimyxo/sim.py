"""The Simulation: Taichi fields for particles, cells and (only if used) the slime grid; kernels for force assembly
and the time step. Equations: docs/model.md (sections cited in each kernel's docstring).

Compile-time effects. A scene's effects (guiding kind, slime, reversals, suppression, strain energy, mass, integrator,
precision) are read into `self.cfg` before any field exists. Kernels branch on them with `ti.static`, so a disabled
effect is absent from the compiled code, and its fields are never allocated (`self.slime` is None without slime, and
so on). One Simulation per process compiles its kernels once; a second instance compiles again.

Layout. Particle p = c * N + k is particle k of cell c; segment s = c * (N - 1) + k joins particles k and k + 1.
Positions are stored wrapped into the box; all differences use the minimum image.

Determinism. Every force is gathered, never scattered: a contact pair is evaluated from both sides, and a segment's
neighbour list is sorted, so the summation order does not depend on thread scheduling. The only atomics are in the
neighbour-list build (whose result is sorted afterwards), the slime deposition claim (max of cell index: the highest
cell wins, a fixed rule), and flags.
"""

import math
import os
from dataclasses import dataclass

import numpy as np
import taichi as ti

from .frame import Frame, unwrap_chains
from .rng import STREAM_REVERSAL, uniform_ti


SERIAL_BELOW_SEGMENTS = int(os.environ.get("TAICHIMYXO_SERIAL_BELOW", "3000"))


class NeighbourOverflow(RuntimeError):
    pass


@dataclass(frozen=True)
class Config:
    """Compile-time configuration (everything a kernel reads through ti.static)."""
    n_cells: int
    N: int
    Lx: float
    Ly: float
    W: float
    l0: float
    k_s: float
    k_a: float
    k_c: float
    f_engine: float       # per particle, pN
    zeta_t: float
    zeta_n: float
    guiding: str          # none | passive | active | adhesion
    guide_particles: bool  # distance between head and tail particles instead of segments
    guide_self: bool
    k_g: float
    f_max_g: float
    d_g: float
    slime: bool
    slime_dx: float
    f_slime: float
    reversals: bool
    suppression: bool
    period_mean_steps: float
    period_sd_steps: float
    period_min_steps: float
    strain: bool
    mass: float           # pg -> pN s^2/µm: 1 pg = 1e-15 kg; F = m a: pN = 1e-12 N; a in µm/s^2 = 1e-6 m/s^2
    integrator: str
    precision: str
    seed: int
    skin: float
    max_nbrs: int
    dt: float

    @classmethod
    def from_scene(cls, sc) -> "Config":
        dt = sc.dt
        rv = sc.raw["reversals"]
        T = rv["period_min"] * 60.0 / dt
        guiding = sc.guiding
        head_tail = guiding != "none" or sc.suppression
        # neighbour capacity: segments whose midpoints are within r_list at the densest packing (area fraction 1)
        r = cls.list_radius_for(sc.rest_length, sc.width, sc.raw["guiding"]["range_um"] if head_tail else 0.0,
                                sc.raw["run"]["skin_um"])
        seg_area = sc.rest_length * sc.width
        cap = sc.raw["run"]["max_neighbours"] or int(math.ceil(1.6 * math.pi * r * r / seg_area)) + 8
        return cls(
            n_cells=sc.n_cells, N=sc.N, Lx=sc.box[0], Ly=sc.box[1], W=sc.width, l0=sc.rest_length,
            k_s=sc.k_s, k_a=sc.k_a, k_c=sc.k_c, f_engine=sc.engine_force / sc.N, zeta_t=sc.zeta_t, zeta_n=sc.zeta_n,
            guiding=guiding, guide_particles=sc.raw["guiding"]["distance"] == "particles",
            guide_self=sc.raw["guiding"]["self"], k_g=sc.k_g, f_max_g=sc.raw["guiding"]["f_max_pN"],
            d_g=sc.raw["guiding"]["range_um"],
            slime=sc.slime, slime_dx=sc.raw["slime"]["grid_um"], f_slime=sc.raw["slime"]["f_max_pN"],
            reversals=sc.reversals, suppression=sc.suppression, period_mean_steps=T,
            period_sd_steps=T * rv["period_sd_fraction"], period_min_steps=max(1.0, T * rv["min_period_fraction"]),
            strain=sc.strain, mass=sc.raw["run"]["mass_pg"] * 1e-9, integrator=sc.integrator,
            precision=sc.precision, seed=sc.seed, skin=sc.raw["run"]["skin_um"], max_nbrs=cap, dt=dt)

    @staticmethod
    def list_radius_for(l0, W, d_g, skin):
        # two segments no longer than l_max whose closest points are within W + d_g have midpoints within
        # l_max + W + d_g; the skin covers motion between rebuilds.
        return 1.25 * l0 + W + d_g + skin

    @property
    def head_tail(self) -> bool:
        """Head-to-tail distances are needed (guiding forces, or reversal suppression)."""
        return self.guiding != "none" or self.suppression

    @property
    def list_radius(self) -> float:
        return self.list_radius_for(self.l0, self.W, self.d_g if self.head_tail else 0.0, self.skin)


@ti.func
def _min_image(d, Lx: ti.template(), Ly: ti.template()):
    return ti.Vector([d[0] - Lx * ti.round(d[0] / Lx), d[1] - Ly * ti.round(d[1] / Ly)])


@ti.func
def _perp(v):
    return ti.Vector([-v[1], v[0]])


@ti.func
def closest_points(p1, q1, p2, q2):
    """Closest points of segments p1-q1 and p2-q2 (docs/model.md term 4): returns (s, t, c1, c2) with s, t in [0, 1].
    Parallel overlapping segments take the middle of the overlap (see geometry.py, the numpy twin)."""
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


@ti.data_oriented
class Simulation:
    def __init__(self, scene, positions: np.ndarray | None = None, engine_direction: np.ndarray | None = None):
        """Build fields for `scene` and load the initial configuration (from the scene's start unless positions,
        (n_cells, N, 2) µm, and engine_direction, (n_cells,) ±1, are given)."""
        self.scene = scene
        self.cfg = cfg = Config.from_scene(scene)
        self.pdt = ti.f64 if self.cfg.precision in ("f64", "mixed") else ti.f32
        self.fdt = ti.f64 if self.cfg.precision == "f64" else ti.f32
        self.n_p = self.cfg.n_cells * self.cfg.N
        self.n_s = self.cfg.n_cells * (self.cfg.N - 1)
        r = self.cfg.list_radius
        self.nbx = max(1, int(self.cfg.Lx // r))
        self.nby = max(1, int(self.cfg.Ly // r))
        self.step_count = 0
        self.rebuilds = 0
        # Taichi's CPU backend spends ~75 µs launching a parallel loop; below a few thousand segments one thread
        # running the loops serially is faster than two threads (measured: see benchmarks/throughput).
        self.serial = self.n_s < SERIAL_BELOW_SEGMENTS
        self._fb = ti.FieldsBuilder()
        fb = self._fb
        P, S, C = self.n_p, self.n_s, self.cfg.n_cells

        def vec(n, dt):
            f = ti.Vector.field(2, dtype=dt)
            fb.dense(ti.i, n).place(f)
            return f

        def scal(n, dt):
            f = ti.field(dtype=dt)
            fb.dense(ti.i, n).place(f)
            return f

        self.x = vec(P, self.pdt)            # positions, wrapped
        self.x_ref = vec(P, self.pdt)        # positions at the last neighbour-list build
        self.x_snap = vec(P, self.pdt)       # positions at the start of the speed window
        self.fa = vec(S, self.fdt)           # contact force on a segment's first particle
        self.fb_ = vec(S, self.fdt)          # ... and on its second particle
        self.ke = scal(C, ti.i32)            # engine direction k_e = +-1
        self.nbr = ti.field(ti.i32)
        fb.dense(ti.ij, (S, self.cfg.max_nbrs)).place(self.nbr)
        self.nbr_n = scal(S, ti.i32)
        self.bin_count = scal(self.nbx * self.nby, ti.i32)
        self.bin_start = scal(self.nbx * self.nby + 1, ti.i32)
        self.bin_cursor = scal(self.nbx * self.nby, ti.i32)
        self.bin_items = scal(S, ti.i32)
        self.seg_bin = scal(S, ti.i32)
        self.flags = scal(4, ti.i32)         # 0: neighbour overflow, 1: moved past half the skin
        # effects: allocated only when the scene uses them
        self.g_head = vec(C, self.fdt) if self.cfg.guiding != "none" else None
        self.g_tail = vec(C, self.fdt) if self.cfg.guiding == "adhesion" else None
        self.interacting = scal(C, ti.i32) if self.cfg.suppression else None
        if self.cfg.reversals:
            self.rev_clock = scal(C, ti.i32)    # steps since the last reversal (integer: exact over hours)
            self.rev_period = scal(C, ti.i32)   # this cycle's period, steps
            self.rev_count = scal(C, ti.i32)    # reversals so far (counter of the random stream)
        else:
            self.rev_clock = self.rev_period = self.rev_count = None
        if self.cfg.slime:
            self.sgx = max(1, int(round(self.cfg.Lx / self.cfg.slime_dx)))
            self.sgy = max(1, int(round(self.cfg.Ly / self.cfg.slime_dx)))
            self.slime = ti.Vector.field(2, dtype=ti.f32)
            self.slime_claim = ti.field(ti.i32)
            fb.dense(ti.ij, (self.sgx, self.sgy)).place(self.slime, self.slime_claim)
        else:
            self.slime = self.slime_claim = None
        self.strain_seg = scal(S, ti.f64) if self.cfg.strain else None
        self.v = vec(P, self.fdt) if self.cfg.mass > 0 else None
        self._tree = fb.finalize()
        self._debug = None
        if positions is None:
            from .init import initial_configuration
            positions, engine_direction = initial_configuration(scene)
        self.set_state(positions, engine_direction)
        if self.cfg.reversals:
            self._init_reversals()

    # ------------------------------------------------------------------ state
    def set_state(self, positions, engine_direction, step: int = 0) -> None:
        pos = np.asarray(positions, dtype=np.float64).reshape(self.cfg.n_cells, self.cfg.N, 2)
        L = np.array([self.cfg.Lx, self.cfg.Ly])
        self.x.from_numpy(np.mod(pos, L).reshape(-1, 2).astype(np.float64 if self.pdt == ti.f64 else np.float32))
        self.ke.from_numpy(np.where(np.asarray(engine_direction) >= 0, 1, -1).astype(np.int32))
        self.step_count = step
        self.snapshot_speed()
        self.rebuild_neighbours()

    def positions(self) -> np.ndarray:
        """(n_cells, N, 2) float64, chains unwrapped, particle 0 in the box."""
        return unwrap_chains(self.x.to_numpy().astype(np.float64).reshape(self.cfg.n_cells, self.cfg.N, 2), (self.cfg.Lx, self.cfg.Ly))

    @property
    def time(self) -> float:
        return self.step_count * self.cfg.dt

    def engine_direction(self) -> np.ndarray:
        return self.ke.to_numpy().astype(np.int8)

    def get_checkpoint(self) -> dict:
        st = {"x": self.x.to_numpy(), "x_snap": self.x_snap.to_numpy(), "ke": self.ke.to_numpy(),
              "step": np.array(self.step_count), "snap_step": np.array(getattr(self, "_snap_step", 0))}
        for name in ("rev_clock", "rev_period", "rev_count", "slime", "v"):
            f = getattr(self, name)
            if f is not None:
                st[name] = f.to_numpy()
        return st

    def load_checkpoint(self, st: dict) -> None:
        self.x.from_numpy(st["x"])
        self.ke.from_numpy(st["ke"])
        self.step_count = int(st["step"])
        for name in ("rev_clock", "rev_period", "rev_count", "slime", "v"):
            f = getattr(self, name)
            if f is not None:
                f.from_numpy(st[name])
        self.x_snap.from_numpy(st["x_snap"])
        self._snap_step = int(st["snap_step"])
        self.rebuild_neighbours()

    # ------------------------------------------------------------------ reversals: docs/model.md term 7
    @ti.func
    def _draw_period(self, c, count):
        u1 = uniform_ti(ti.u32(self.cfg.seed), ti.u32(STREAM_REVERSAL), ti.u32(c), ti.u32(2 * count))
        u2 = uniform_ti(ti.u32(self.cfg.seed), ti.u32(STREAM_REVERSAL), ti.u32(c), ti.u32(2 * count + 1))
        z = ti.sqrt(-2.0 * ti.log(u1)) * ti.cos(2.0 * math.pi * u2)
        p = self.cfg.period_mean_steps + self.cfg.period_sd_steps * z
        return ti.cast(ti.max(p, self.cfg.period_min_steps), ti.i32)

    @ti.kernel
    def _init_reversals(self):
        """Periods ~ Normal(T_R, sd) truncated below; initial phases uniform (docs/model.md term 7)."""
        ti.loop_config(serialize=self.serial)
        for c in range(self.cfg.n_cells):
            p = self._draw_period(c, 0)
            u = uniform_ti(ti.u32(self.cfg.seed), ti.u32(STREAM_REVERSAL + 100), ti.u32(c), ti.u32(0))
            self.rev_period[c] = p
            self.rev_clock[c] = ti.cast(u * p, ti.i32)
            self.rev_count[c] = 0

    # ------------------------------------------------------------------ neighbour list
    @ti.func
    def _seg_ends(self, s):
        c = s // (self.cfg.N - 1)
        p = c * self.cfg.N + s % (self.cfg.N - 1)
        return p, p + 1

    @ti.func
    def _seg_mid(self, s):
        a, b = self._seg_ends(s)
        d = _min_image(self.x[b] - self.x[a], self.cfg.Lx, self.cfg.Ly)
        m = self.x[a] + 0.5 * d
        return ti.Vector([m[0] - self.cfg.Lx * ti.floor(m[0] / self.cfg.Lx), m[1] - self.cfg.Ly * ti.floor(m[1] / self.cfg.Ly)])

    @ti.kernel
    def _build_neighbours(self):
        nbx, nby = ti.static(self.nbx, self.nby)
        r2 = ti.static(self.cfg.list_radius ** 2)
        ti.loop_config(serialize=self.serial)
        for i in range(nbx * nby):
            self.bin_count[i] = 0
        ti.loop_config(serialize=self.serial)
        for s in range(self.n_s):
            m = self._seg_mid(s)
            bx = ti.min(ti.cast(m[0] / self.cfg.Lx * nbx, ti.i32), nbx - 1)
            by = ti.min(ti.cast(m[1] / self.cfg.Ly * nby, ti.i32), nby - 1)
            b = bx * nby + by
            self.seg_bin[s] = b
            ti.atomic_add(self.bin_count[b], 1)
        ti.loop_config(serialize=True)
        for i in range(nbx * nby + 1):
            if i == 0:
                self.bin_start[0] = 0
            else:
                self.bin_start[i] = self.bin_start[i - 1] + self.bin_count[i - 1]
        ti.loop_config(serialize=self.serial)
        for i in range(nbx * nby):
            self.bin_cursor[i] = self.bin_start[i]
        ti.loop_config(serialize=self.serial)
        for s in range(self.n_s):
            k = ti.atomic_add(self.bin_cursor[self.seg_bin[s]], 1)
            self.bin_items[k] = s
        ti.loop_config(serialize=self.serial)
        for s in range(self.n_s):
            cs = s // (self.cfg.N - 1)
            ks = s % (self.cfg.N - 1)
            ms = self._seg_mid(s)
            b = self.seg_bin[s]
            bx0 = b // nby
            by0 = b % nby
            n = 0
            for ox in ti.static(range(-1, 2) if nbx >= 3 else range(nbx)):
                bx = ox
                if ti.static(nbx >= 3):
                    bx = (bx0 + ox + nbx) % nbx
                for oy in ti.static(range(-1, 2) if nby >= 3 else range(nby)):
                    by = oy
                    if ti.static(nby >= 3):
                        by = (by0 + oy + nby) % nby
                    bb = bx * nby + by
                    for q in range(self.bin_start[bb], self.bin_start[bb + 1]):
                        t = self.bin_items[q]
                        ct = t // (self.cfg.N - 1)
                        kt = t % (self.cfg.N - 1)
                        if t != s and (ct != cs or abs(kt - ks) >= 2):
                            d = _min_image(self._seg_mid(t) - ms, self.cfg.Lx, self.cfg.Ly)
                            if d.dot(d) < r2:
                                if n < self.cfg.max_nbrs:
                                    self.nbr[s, n] = t
                                else:
                                    self.flags[0] = 1
                                n += 1
            n = ti.min(n, self.cfg.max_nbrs)
            self.nbr_n[s] = n
            # insertion sort: the list, and so every force sum, is independent of thread scheduling
            for i in range(1, n):
                v = self.nbr[s, i]
                j = i - 1
                while j >= 0 and self.nbr[s, j] > v:
                    self.nbr[s, j + 1] = self.nbr[s, j]
                    j -= 1
                self.nbr[s, j + 1] = v
        ti.loop_config(serialize=self.serial)
        for p in range(self.n_p):
            self.x_ref[p] = self.x[p]
        self.flags[1] = 0

    def rebuild_neighbours(self) -> None:
        self.flags[0] = 0
        self._build_neighbours()
        self.rebuilds += 1
        if self.flags[0]:
            raise NeighbourOverflow(
                f"more than {self.cfg.max_nbrs} segments within the neighbour radius of one segment: cells are packed "
                f"beyond area fraction 1 or blew up; set run.max_neighbours higher or use a smaller time step")

    # ------------------------------------------------------------------ contacts: docs/model.md term 4
    # The contact law (docs/model.md, "Contacts"). Each cell is sampled along its axis every l0 / 2: its particles
    # (nodes) and its segment midpoints. Every sample point is pressed out of every other cell's chain:
    #     E = sum over samples p and other chains B of w_p k_c / 2 (W - D(p, B))^2   for D < W,
    # D the distance from p to the polyline B (its nearest segment). w_p = 1/4, so two parallel cells overlapping by
    # W - d feel k_c (W - d) per l0 of overlap length (both cells' samples count); the two poles carry w = 1/2, so a
    # pole pressing on another cell's side feels at least half the paper's point contact k_c (W - d) (more where the
    # other cell's samples lie within reach of the pole, up to about the full contact).
    # Why samples against polylines and not segment pairs: a segment-pair law counts a contact at a shared node twice
    # (S1 Text defect A) and gives a washboard when a cell slides along a straight neighbour (defect B), and any rule
    # that hands node-clamped contacts from one segment to its neighbour loses them (side-by-side cells kept 1 of 9
    # contacts at a tilt of 0.003 deg). A point's distance to a straight polyline does not change when it slides
    # along it (no tangential force), it is one number however many segments meet at the nearest point (a node
    # contact counts once), and the energy is continuous in every coordinate. In 2D two segments that do not cross
    # are closest at an end of one of them, so node samples see every contact; the midpoints halve the sampling
    # error, which with nodes alone made the force on two side-by-side cells swing by 17 % with their stagger
    # (measured: tests/test_contacts.py sweeps tilt and stagger; now within 10 %).
    # "Nearest segment" is decided locally: p against segment t counts when t is strictly nearer than t - 1 and at
    # least as near as t + 1 (among the segments p may touch). Ties (p nearest to the node shared by t and t + 1) go
    # to t. Every distance of one sample is computed in that sample's frame by one function, so the force on the
    # sample (gathered by its own segment) and the reaction (gathered by t) come from identical numbers.
    CONTACT_WEIGHT = 0.25
    POLE_WEIGHT = 0.5

    @ti.func
    def _sample(self, s, j):
        """Sample j of segment s (0: first particle, 1: midpoint, 2: second particle): (position in position
        precision, index along the cell in half-segments, contact weight)."""
        N = ti.static(self.cfg.N)
        a, b = self._seg_ends(s)
        x = self.x[a]
        if j == 1:
            x = x + 0.5 * _min_image(self.x[b] - x, self.cfg.Lx, self.cfg.Ly)
        elif j == 2:
            x = self.x[b]
        h = 2 * (s % (N - 1)) + j
        w = ti.cast(self.CONTACT_WEIGHT, self.fdt)          # a Taichi variable: a Python float would not branch
        if h == 0 or h == 2 * (N - 1):
            w = ti.cast(self.POLE_WEIGHT, self.fdt)
        return x, h, w

    @ti.func
    def _sample_eligible(self, c, h, t):
        """Sample h (half-segments along cell c) may touch segment t: another cell's segment, or one of its own cell's
        segments at least 1.5 segments away along the cell (so a bend between neighbours is the bending spring's
        business, while a folded cell, a hairpin, still pushes itself apart)."""
        N = ti.static(self.cfg.N)
        ok = True
        if c == t // (N - 1):
            kt = t % (N - 1)
            ok = h - (2 * kt + 2) >= 3 or 2 * kt - h >= 3
        return ok

    @ti.func
    def _point_seg(self, xp, t):
        """Point xp against segment t in xp's frame (force precision): (u on t, d, closest point of t - xp)."""
        a, b = self._seg_ends(t)
        e0 = ti.cast(_min_image(self.x[a] - xp, self.cfg.Lx, self.cfg.Ly), self.fdt)
        e = ti.cast(_min_image(self.x[b] - self.x[a], self.cfg.Lx, self.cfg.Ly), self.fdt)
        ee = e.dot(e)
        u = ti.cast(0.0, self.fdt)
        if ee > 1e-12:
            u = ti.math.clamp(-e0.dot(e) / ee, 0.0, 1.0)
        c = e0 + u * e
        return u, c.norm(), c

    @ti.func
    def _sample_contact(self, s, j, t):
        """Contact of sample j of segment s with segment t (docs/model.md term 4, rule above): (accepted, u on t, force
        on the sample, its unit direction n, the sample's weight w). The reaction on t is -force, shared (1 - u, u)
        by t's particles."""
        N = ti.static(self.cfg.N)
        ok = False
        u = ti.cast(0.0, self.fdt)
        f = ti.Vector([0.0, 0.0], dt=self.fdt)
        n = ti.Vector([0.0, 0.0], dt=self.fdt)
        c = s // (N - 1)
        xp, h, w = self._sample(s, j)
        if self._sample_eligible(c, h, t):
            u, dist, cp = self._point_seg(xp, t)
            if dist < self.cfg.W:
                ok = True
                kt = t % (N - 1)
                if kt > 0 and self._sample_eligible(c, h, t - 1):
                    _, dprev, _ = self._point_seg(xp, t - 1)
                    if dprev <= dist:
                        ok = False
                if ok and kt < N - 2 and self._sample_eligible(c, h, t + 1):
                    _, dnext, _ = self._point_seg(xp, t + 1)
                    if dnext < dist:
                        ok = False
                if ok:
                    if dist > 1e-9:
                        n = -cp / dist
                    else:
                        # the sample lies on the segment: push it across t, the side fixed by the indices
                        a, b = self._seg_ends(t)
                        e = ti.cast(_min_image(self.x[b] - self.x[a], self.cfg.Lx, self.cfg.Ly), self.fdt)
                        ln = e.norm()
                        n = ti.Vector([1.0, 0.0], dt=self.fdt)
                        if ln > 1e-12:
                            n = _perp(e / ln)
                        if s < t:
                            n = -n
                    f = w * self.cfg.k_c * (self.cfg.W - dist) * n
        return ok, u, f, n, w

    @ti.func
    def _within_reach(self, s, t):
        """Segments s and t can be in contact: their midpoints are closer than half their lengths plus W. Most list
        partners (about 33 per segment at area fraction 1) are not, and are skipped before any sample is tested;
        skipping them changes no sum, since they contribute nothing."""
        # in a fixed order (the same numbers whichever segment asks) and with a margin far above rounding, so a
        # contact is never skipped from one side only
        a, b = self._seg_ends(ti.min(s, t))
        c_, d_ = self._seg_ends(ti.max(s, t))
        es = ti.cast(_min_image(self.x[b] - self.x[a], self.cfg.Lx, self.cfg.Ly), self.fdt)
        et = ti.cast(_min_image(self.x[d_] - self.x[c_], self.cfg.Lx, self.cfg.Ly), self.fdt)
        m = ti.cast(_min_image(self.x[c_] - self.x[a], self.cfg.Lx, self.cfg.Ly), self.fdt) + 0.5 * (et - es)
        reach = 0.5 * (es.norm() + et.norm()) + 1.001 * self.cfg.W
        return m.dot(m) < reach * reach

    @ti.func
    def _sample_energy(self, s, j, t):
        """Contact energy of sample j of segment s with segment t (0 if not in contact), pN·µm, f64."""
        ok, u, f, n, w = self._sample_contact(s, j, t)
        e = ti.cast(0.0, ti.f64)
        if ok:
            fn = ti.cast(f.norm(), ti.f64)
            e = 0.5 * fn * fn / (w * self.cfg.k_c)          # w k_c (W - d)^2 / 2 with |f| = w k_c (W - d)
        return e

    @ti.func
    def _guiding_pair(self, follower_seg, leader_seg):
        """Short-range guiding pull on the follower's head (docs/model.md term 5). Returns (force on the head particle,
        gap g) with the force zero outside 0 < g < d_g. Reading 'segments': closest points of the head and tail
        segments; 'particles': head particle to tail particle."""
        cj = follower_seg // (self.cfg.N - 1)
        cl = leader_seg // (self.cfg.N - 1)
        hj = cj * self.cfg.N + (0 if self.ke[cj] > 0 else self.cfg.N - 1)          # follower head particle
        tl = cl * self.cfg.N + (self.cfg.N - 1 if self.ke[cl] > 0 else 0)          # leader tail particle
        xh = self.x[hj]
        sep = ti.Vector([0.0, 0.0], dt=self.fdt)
        if ti.static(self.cfg.guide_particles):
            sep = ti.cast(_min_image(self.x[tl] - xh, self.cfg.Lx, self.cfg.Ly), self.fdt)
        else:
            a, b = self._seg_ends(follower_seg)
            c_, d_ = self._seg_ends(leader_seg)
            pa = ti.cast(_min_image(self.x[a] - xh, self.cfg.Lx, self.cfg.Ly), self.fdt)
            pb = ti.cast(_min_image(self.x[b] - xh, self.cfg.Lx, self.cfg.Ly), self.fdt)
            pc = ti.cast(_min_image(self.x[c_] - xh, self.cfg.Lx, self.cfg.Ly), self.fdt)
            pd = pc + ti.cast(_min_image(self.x[d_] - self.x[c_], self.cfg.Lx, self.cfg.Ly), self.fdt)
            _, _, c1, c2 = closest_points(pa, pb, pc, pd)
            sep = c2 - c1
        d = sep.norm()
        g = d - self.cfg.W
        f = ti.Vector([0.0, 0.0], dt=self.fdt)
        if g > 0.0 and g < self.cfg.d_g:
            f = ti.min(self.cfg.k_g * g, self.cfg.f_max_g) * sep / d
        return f, g

    @ti.func
    def _head_seg(self, c):
        return c * (self.cfg.N - 1) + (0 if self.ke[c] > 0 else self.cfg.N - 2)

    @ti.func
    def _tail_seg(self, c):
        return c * (self.cfg.N - 1) + (self.cfg.N - 2 if self.ke[c] > 0 else 0)

    @ti.func
    def _contact_hook(self, s, i, t, P, Q, gn):
        """Called by _pair_forces for the i-th contact segment s gathers with segment t: lever arms P on s and Q on t
        (the sample's position, 0, 1/2 or 1, on its own segment), gn the unit separation from t's side to s's side
        times sqrt(w), so that the contact's stiffness is k_c gn gn^T. The implicit integrator
        (implicit.py) records contacts here for its Jacobian. Nothing in the explicit step."""
        pass

    @ti.func
    def _contact_count_hook(self, s, n_contacts):
        pass

    @ti.func
    def _pair_forces(self):
        """Per segment: gather contact forces onto its two particles (the forces on its own samples, and the
        reactions of other cells' samples pressing on it, docs/model.md term 4); the head segment gathers its cell's
        guiding pull, the tail segment the adhesion reaction and the interaction flag (for reversal suppression)."""
        N = ti.static(self.cfg.N)
        ti.loop_config(serialize=self.serial)
        for s in range(self.n_s):
            fa = ti.Vector([0.0, 0.0], dt=self.fdt)
            fb = ti.Vector([0.0, 0.0], dt=self.fdt)
            nc = 0
            s_last = s % (N - 1) == N - 2
            for q in range(self.nbr_n[s]):
                t = self.nbr[s, q]
                if not self._within_reach(s, t):
                    continue
                t_last = t % (N - 1) == N - 2
                # side 0: this segment's own samples pressed by t (its second particle belongs to the next segment,
                # except at the cell's end); side 1: t's samples pressing on this segment (the reaction, shared by
                # the lever rule). The sides are a runtime loop and the three samples unrolled: the contact code is
                # compiled three times, not six (the step took 15 s to compile fully unrolled, 5 s before the sample
                # law), and within a side the other segment's loads are shared by the three samples.
                for side in range(2):
                    p_seg, o_seg, p_last = s, t, s_last
                    if side == 1:
                        p_seg, o_seg, p_last = t, s, t_last
                    for j in ti.static(range(3)):
                        if ti.static(j < 2) or p_last:
                            ok, u, f, n, w = self._sample_contact(p_seg, j, o_seg)
                            if ok:
                                P = 0.5 * j                # the sample's lever arm on its own segment
                                if side == 0:
                                    fa += (1.0 - P) * f
                                    fb += P * f
                                    self._contact_hook(s, nc, t, P, u, ti.sqrt(w) * n)
                                else:
                                    fa -= (1.0 - u) * f
                                    fb -= u * f
                                    self._contact_hook(s, nc, t, u, P, -ti.sqrt(w) * n)
                                nc += 1
            self._contact_count_hook(s, nc)
            self.fa[s] = fa
            self.fb_[s] = fb
            if ti.static(self.cfg.head_tail):
                c = s // (self.cfg.N - 1)
                is_head = s == self._head_seg(c)
                is_tail = s == self._tail_seg(c)
                if is_head or is_tail:
                    gh = ti.Vector([0.0, 0.0], dt=self.fdt)
                    gt = ti.Vector([0.0, 0.0], dt=self.fdt)
                    inter = 0
                    # the cell's own tail segment is not in its head segment's list when they are adjacent (N=3)
                    for q in range(self.nbr_n[s]):
                        t = self.nbr[s, q]
                        ct = t // (self.cfg.N - 1)
                        if ti.static(not self.cfg.guide_self):
                            if ct == c:
                                continue
                        if is_head and t == self._tail_seg(ct):
                            f, g = self._guiding_pair(s, t)
                            gh += f
                            if g < self.cfg.d_g:
                                inter = 1
                        if is_tail and t == self._head_seg(ct):
                            f, g = self._guiding_pair(t, s)
                            gt -= f
                            if g < self.cfg.d_g:
                                inter = 1
                    if ti.static(self.cfg.guiding != "none"):
                        if is_head:
                            self.g_head[c] = gh
                    if ti.static(self.cfg.guiding == "adhesion"):
                        if is_tail:
                            self.g_tail[c] = gt
                    if ti.static(self.cfg.suppression):
                        # head and tail segments of one cell both write: combine without a race by bit
                        ti.atomic_or(self.interacting[c], inter * (1 if is_head else 2))

    # ------------------------------------------------------------------ cell forces: docs/model.md terms 1-3, 5, 6
    @ti.func
    def _cell_forces(self, c):
        """Forces on the N particles of cell c, relative positions (mixed precision: f64 origin, self.fdt offsets).
        Returns (X: N x 2 offsets from particle 0, F_total, T: tangents, F_int (springs+bending), F_eng)."""
        N = ti.static(self.cfg.N)
        base = c * N
        x0 = self.x[base]
        X = ti.Matrix.zero(self.fdt, N, 2)
        for k in ti.static(range(1, N)):
            d = ti.cast(_min_image(self.x[base + k] - self.x[base + k - 1], self.cfg.Lx, self.cfg.Ly), self.fdt)
            X[k, 0] = X[k - 1, 0] + d[0]
            X[k, 1] = X[k - 1, 1] + d[1]
        Fi = ti.Matrix.zero(self.fdt, N, 2)
        U = ti.Matrix.zero(self.fdt, N - 1, 2)    # unit segment vectors k -> k+1
        Ln = ti.Vector.zero(self.fdt, N - 1)
        for k in ti.static(range(N - 1)):
            l = ti.Vector([X[k + 1, 0] - X[k, 0], X[k + 1, 1] - X[k, 1]])
            ln = l.norm()
            Ln[k] = ln
            u = l / ln
            U[k, 0] = u[0]
            U[k, 1] = u[1]
            fs = self.cfg.k_s * (ln - self.cfg.l0) * u              # term 1: pulls k toward k+1 when stretched
            Fi[k, 0] += fs[0]
            Fi[k, 1] += fs[1]
            Fi[k + 1, 0] -= fs[0]
            Fi[k + 1, 1] -= fs[1]
        for k in ti.static(range(N - 2)):                 # term 2: E = k_a theta^2 / 2 at joint k+1
            u1 = ti.Vector([U[k, 0], U[k, 1]])
            u2 = ti.Vector([U[k + 1, 0], U[k + 1, 1]])
            th = ti.atan2(u1[0] * u2[1] - u1[1] * u2[0], u1.dot(u2))
            fA = -self.cfg.k_a * th * _perp(u1) / Ln[k]        # d theta / d x_k = perp(l1) / |l1|^2
            fC = -self.cfg.k_a * th * _perp(u2) / Ln[k + 1]    # d theta / d x_k+2 = perp(l2) / |l2|^2
            Fi[k, 0] += fA[0]
            Fi[k, 1] += fA[1]
            Fi[k + 2, 0] += fC[0]
            Fi[k + 2, 1] += fC[1]
            Fi[k + 1, 0] -= fA[0] + fC[0]
            Fi[k + 1, 1] -= fA[1] + fC[1]
        ke = ti.cast(self.ke[c], self.fdt)
        T = ti.Matrix.zero(self.fdt, N, 2)                     # forward unit tangents (toward the head when ke = +1 ...)
        for k in ti.static(range(N)):
            v = ti.Vector([0.0, 0.0], dt=self.fdt)
            if ti.static(k == 0):
                v = -ti.Vector([U[0, 0], U[0, 1]])
            elif ti.static(k == N - 1):
                v = -ti.Vector([U[N - 2, 0], U[N - 2, 1]])
            else:
                v = -(ti.Vector([U[k - 1, 0], U[k - 1, 1]]) + ti.Vector([U[k, 0], U[k, 1]]))
                v = v / ti.max(v.norm(), 1e-12)
            T[k, 0] = ke * v[0]
            T[k, 1] = ke * v[1]
        F = ti.Matrix.zero(self.fdt, N, 2)
        for k in ti.static(range(N)):
            f = ti.Vector([Fi[k, 0], Fi[k, 1]]) + self.cfg.f_engine * ti.Vector([T[k, 0], T[k, 1]])   # term 3
            if ti.static(k > 0):
                f += self.fb_[c * (N - 1) + k - 1]
            if ti.static(k < N - 1):
                f += self.fa[c * (N - 1) + k]
            F[k, 0] = f[0]
            F[k, 1] = f[1]
        head = 0 if self.ke[c] > 0 else N - 1
        tail = N - 1 - head
        th_ = ti.Vector([T[head, 0], T[head, 1]])
        nh = _perp(th_)
        if ti.static(self.cfg.guiding != "none"):              # term 5
            g = self.g_head[c]
            if ti.static(self.cfg.guiding == "passive"):
                g = g.dot(nh) * nh
            F[head, 0] += g[0]
            F[head, 1] += g[1]
            if ti.static(self.cfg.guiding == "adhesion"):
                gt = self.g_tail[c]
                F[tail, 0] += gt[0]
                F[tail, 1] += gt[1]
        if ti.static(self.cfg.slime):                          # term 6: steer the head along the trail
            xh = self.x[base + head]
            ix = ti.cast(ti.floor(xh[0] / self.cfg.slime_dx), ti.i32) % self.sgx
            iy = ti.cast(ti.floor(xh[1] / self.cfg.slime_dx), ti.i32) % self.sgy
            sv = ti.cast(self.slime[ix, iy], self.fdt)
            if sv.dot(sv) > 0.0:
                sg = 1.0 if th_.dot(sv) >= 0.0 else -1.0
                fsl = sg * self.cfg.f_slime * sv
                fsl = fsl.dot(nh) * nh
                F[head, 0] += fsl[0]
                F[head, 1] += fsl[1]
        return x0, X, F, T, Fi

    # ------------------------------------------------------------------ the step
    @ti.kernel
    def _step(self, dt: ti.f64) -> ti.i32:
        """One explicit step (docs/model.md "Equation of motion"): forces at x_n, then the semi-implicit Euler step of
        m dv/dt = F - zeta v with the drag implicit, v_n+1 = (m v_n + dt F) / (m + dt zeta) per axis (t, n);
        x_n+1 = x_n + dt v_n+1. With m = 0 this is the overdamped step v = F_t / zeta_t + F_n / zeta_n."""
        N = ti.static(self.cfg.N)
        if ti.static(self.cfg.suppression):
            ti.loop_config(serialize=self.serial)
            for c in range(self.cfg.n_cells):
                self.interacting[c] = 0
        self._pair_forces()
        ti.loop_config(serialize=self.serial)
        for c in range(self.cfg.n_cells):
            x0, X, F, T, Fi = self._cell_forces(c)
            moved = 0
            for k in ti.static(range(N)):
                t = ti.Vector([T[k, 0], T[k, 1]])
                n = _perp(t)
                f = ti.Vector([F[k, 0], F[k, 1]])
                ft = f.dot(t)
                fn = f.dot(n)
                v = ti.Vector([0.0, 0.0], dt=self.fdt)
                if ti.static(self.cfg.mass > 0):
                    vo = self.v[c * N + k]
                    v = (self.cfg.mass * vo.dot(t) + dt * ft) / (self.cfg.mass + dt * self.cfg.zeta_t) * t + \
                        (self.cfg.mass * vo.dot(n) + dt * fn) / (self.cfg.mass + dt * self.cfg.zeta_n) * n
                    self.v[c * N + k] = v
                else:
                    v = ft / self.cfg.zeta_t * t + fn / self.cfg.zeta_n * n
                xn = x0 + ti.cast(ti.Vector([X[k, 0], X[k, 1]]) + v * dt, self.pdt)
                moved |= self._store_position(c * N + k, xn)
            self._finish_cell(c, moved)
        if ti.static(self.cfg.slime):
            ti.loop_config(serialize=self.serial)
            for c in range(self.cfg.n_cells):
                self._slime_write(c)
                if ti.static(self.cfg.reversals):
                    self._reversal_clock(c)
        return self.flags[1]

    @ti.func
    def _store_position(self, p, xn):
        """Wrap and store particle p's new position; 1 if it has moved past half the skin since the list build."""
        xn[0] -= self.cfg.Lx * ti.floor(xn[0] / self.cfg.Lx)
        xn[1] -= self.cfg.Ly * ti.floor(xn[1] / self.cfg.Ly)
        self.x[p] = xn
        moved = 0
        dd = _min_image(xn - self.x_ref[p], self.cfg.Lx, self.cfg.Ly)
        if dd.dot(dd) > (0.5 * self.cfg.skin) ** 2:
            moved = 1
        return moved

    @ti.func
    def _finish_cell(self, c, moved):
        """After a cell's update: neighbour-list flag, slime claim (the reversal follows the slime write) or the
        reversal clock. Shared by the explicit and the implicit step."""
        if moved:
            self.flags[1] = 1
        if ti.static(self.cfg.slime):
            self._slime_claim(c)
        else:
            if ti.static(self.cfg.reversals):
                self._reversal_clock(c)

    @ti.func
    def _reversal_clock(self, c):
        """Advance the cell's reversal clock; reverse (k_e -> -k_e) when it reaches the period, unless suppressed
        by a head-to-tail interaction this step, in which case the clock restarts (docs/model.md term 7)."""
        self.rev_clock[c] += 1
        if self.rev_clock[c] >= self.rev_period[c]:
            self.rev_clock[c] = 0
            skip = False
            if ti.static(self.cfg.suppression):
                skip = self.interacting[c] != 0
            if not skip:
                self.ke[c] = -self.ke[c]
                self.rev_count[c] += 1
                self.rev_period[c] = self._draw_period(c, self.rev_count[c])

    # ------------------------------------------------------------------ slime deposition: docs/model.md term 6
    @ti.func
    def _rear(self, c):
        """Rear particle index, its element, and its forward unit tangent (new positions)."""
        N = ti.static(self.cfg.N)
        tail = c * N + (N - 1 if self.ke[c] > 0 else 0)
        nxt = c * N + (N - 2 if self.ke[c] > 0 else 1)
        xr = self.x[tail]
        t = ti.cast(_min_image(self.x[nxt] - xr, self.cfg.Lx, self.cfg.Ly), ti.f32)
        t = t / ti.max(t.norm(), 1e-12)
        ix = ti.cast(ti.floor(xr[0] / self.cfg.slime_dx), ti.i32) % self.sgx
        iy = ti.cast(ti.floor(xr[1] / self.cfg.slime_dx), ti.i32) % self.sgy
        return ix, iy, t

    @ti.func
    def _slime_claim(self, c):
        ix, iy, _ = self._rear(c)
        ti.atomic_max(self.slime_claim[ix, iy], c + 1)

    @ti.func
    def _slime_write(self, c):
        # the highest-numbered cell over an element wins: a fixed rule, independent of thread order
        ix, iy, t = self._rear(c)
        if self.slime_claim[ix, iy] == c + 1:
            self.slime[ix, iy] = t
            self.slime_claim[ix, iy] = 0

    # ------------------------------------------------------------------ driving
    def run(self, n_steps: int, dt: float | None = None) -> None:
        """Advance n_steps steps of dt seconds (the scene's step by default).
        The neighbour list stays valid because every step checks every particle's real displacement since the list
        was built, and the list is rebuilt as soon as one has moved half the skin: then, at every force evaluation,
        no two particles have closed in by more than the skin since the build, whatever their speed (a guided head
        swings at up to F_max / zeta_n ~ 32 v_b; an interval chosen for an assumed top speed is no guarantee).
        The check costs one comparison per particle inside the step kernel, which returns the flag."""
        dt = self.cfg.dt if dt is None else dt
        for _ in range(n_steps):
            self.step_count += 1
            if self._step(dt):
                self.rebuild_neighbours()

    # ------------------------------------------------------------------ measurements
    @ti.kernel
    def _copy_snap(self):
        ti.loop_config(serialize=self.serial)
        for p in range(self.n_p):
            self.x_snap[p] = self.x[p]

    def snapshot_speed(self) -> None:
        """Start a speed window: the displayed speed is |x(t) - x(t - window)| / window (docs/model.md)."""
        self._copy_snap()
        self._snap_step = self.step_count

    def particle_speed(self) -> np.ndarray:
        """(n_cells, N) µm/min averaged since the last snapshot_speed (instantaneous if none since)."""
        L = np.array([self.cfg.Lx, self.cfg.Ly])
        steps = self.step_count - getattr(self, "_snap_step", self.step_count)
        if steps <= 0:
            return np.zeros((self.cfg.n_cells, self.cfg.N), np.float32)
        d = self.x.to_numpy().astype(np.float64) - self.x_snap.to_numpy().astype(np.float64)
        d -= L * np.round(d / L)
        sp = np.sqrt((d * d).sum(-1)) / (steps * self.cfg.dt) * 60.0
        return sp.reshape(self.cfg.n_cells, self.cfg.N).astype(np.float32)

    @ti.kernel
    def _strain_kernel(self):
        """Strain energy per segment (docs/model.md "What is measured"): the contact energy w k_c (W - d)^2 / 2 of each
        sample contact, half to the segment pressed and half to the sample's own segment (a particle's half shared
        by the two segments meeting there). The segment energies sum to the contact energy whose gradient is the
        contact force; docs/model.md says how this differs from the paper's all-pairs sum."""
        N = ti.static(self.cfg.N)
        ti.loop_config(serialize=self.serial)
        for s in range(self.n_s):
            e = ti.cast(0.0, ti.f64)
            ks = s % (N - 1)
            for q in range(self.nbr_n[s]):
                t = self.nbr[s, q]
                if not self._within_reach(s, t):
                    continue
                t_last = t % (N - 1) == N - 2
                for k in range(6):                               # as in _pair_forces: own samples, then t's
                    j = k % 3
                    if k < 3:
                        share = 0.5                              # the midpoint's half is all this segment's
                        if j != 1:
                            share = 0.25                         # a particle's half, shared with the neighbour
                            if (j == 0 and ks == 0) or (j == 2 and ks == N - 2):
                                share = 0.5                      # a pole has one segment
                        e += share * self._sample_energy(s, j, t)
                    elif j < 2 or t_last:
                        e += 0.5 * self._sample_energy(t, j, s)
            self.strain_seg[s] = e

    def segment_strain(self) -> np.ndarray:
        """(n_cells, N-1) strain energy in J (pN·µm = 1e-18 J). Only in scenes that ask for strain."""
        if self.strain_seg is None:
            raise RuntimeError("strain energy is not computed in this scene (set output.strain = true)")
        self._strain_kernel()
        return self.strain_seg.to_numpy().reshape(self.cfg.n_cells, self.cfg.N - 1) * 1e-18

    def frame(self) -> Frame:
        return Frame(time_s=self.time, step=self.step_count, box=(self.cfg.Lx, self.cfg.Ly), width_um=self.cfg.W,
                     positions=self.positions(), engine_direction=self.engine_direction(),
                     particle_speed=self.particle_speed(),
                     segment_strain=self.segment_strain() if self.cfg.strain else None,
                     meta={"scene": self.scene.name})

    # ------------------------------------------------------------------ introspection for tests
    def _ensure_debug(self):
        if self._debug is None:
            fb = ti.FieldsBuilder()
            f_int = ti.Vector.field(2, dtype=ti.f64)
            f_tot = ti.Vector.field(2, dtype=ti.f64)
            tan = ti.Vector.field(2, dtype=ti.f64)
            fb.dense(ti.i, self.n_p).place(f_int, f_tot, tan)
            self._debug = (f_int, f_tot, tan, fb.finalize())
        return self._debug

    @ti.kernel
    def _forces_kernel(self, f_int: ti.template(), f_tot: ti.template(), tan: ti.template()):
        if ti.static(self.cfg.suppression):
            ti.loop_config(serialize=self.serial)
            for c in range(self.cfg.n_cells):
                self.interacting[c] = 0
        self._pair_forces()
        ti.loop_config(serialize=self.serial)
        for c in range(self.cfg.n_cells):
            x0, X, F, T, Fi = self._cell_forces(c)
            for k in ti.static(range(self.cfg.N)):
                p = c * self.cfg.N + k
                f_int[p] = ti.cast(ti.Vector([Fi[k, 0], Fi[k, 1]]), ti.f64)
                f_tot[p] = ti.cast(ti.Vector([F[k, 0], F[k, 1]]), ti.f64)
                tan[p] = ti.cast(ti.Vector([T[k, 0], T[k, 1]]), ti.f64)

    def forces(self) -> dict:
        """Forces at the current state without stepping: 'internal' (springs + bending), 'contact' (per particle),
        'total' (everything the step uses), 'tangent'. Arrays (n_cells, N, 2), pN."""
        f_int, f_tot, tan, _ = self._ensure_debug()
        self._forces_kernel(f_int, f_tot, tan)
        sh = (self.cfg.n_cells, self.cfg.N, 2)
        fa = self.fa.to_numpy().astype(np.float64).reshape(self.cfg.n_cells, self.cfg.N - 1, 2)
        fb = self.fb_.to_numpy().astype(np.float64).reshape(self.cfg.n_cells, self.cfg.N - 1, 2)
        contact = np.zeros(sh)
        contact[:, :-1] += fa
        contact[:, 1:] += fb
        return {"internal": f_int.to_numpy().reshape(sh), "total": f_tot.to_numpy().reshape(sh),
                "contact": contact, "tangent": tan.to_numpy().reshape(sh)}

    def allocated_fields(self) -> dict:
        """Name -> bytes of every field this Simulation allocated (effects a scene does not use are absent)."""
        out = {}
        for name, f in vars(self).items():
            if isinstance(f, (ti.Field, ti.MatrixField)):
                n = int(np.prod(f.shape))
                per = (f.n * f.m if isinstance(f, ti.MatrixField) else 1) * (8 if f.dtype in (ti.f64, ti.i64) else 4)
                out[name] = n * per
        return out

    def close(self) -> None:
        if self._debug is not None:
            self._debug[3].destroy()
            self._debug = None
        if self._tree is not None:
            self._tree.destroy()
            self._tree = None


def make_simulation(scene, **kw) -> "Simulation":
    """The Simulation class for the scene's integrator."""
    if scene.integrator == "imex":
        from .implicit import ImplicitSimulation
        return ImplicitSimulation(scene, **kw)
    return Simulation(scene, **kw)
