"""The stiff-capable step (scene run.integrator = "imex"): linearly implicit Euler on springs, bending and
contacts.

Equation (docs/model.md "Equation of motion", overdamped): Z(x) v = F(x), Z the anisotropic drag. The explicit step
takes v = Z^-1 F(x_n) and is stable only while dt stays below ~2 zeta / (stiffest rate): a few ms at the paper's k_s,
k_c and very rigid k_a. This step takes one Newton step of backward Euler instead:

    (Z_n + dt K_n) v = F(x_n),        x_n+1 = x_n + dt v,

with Z_n the drag at the start of the step (tangents of x_n) and K_n the positive semidefinite (Gauss-Newton) part of
the stiffness -dF/dx of the conservative stiff terms:
  - linear springs: k_s [u u^T + max(0, 1 - l0/l) (I - u u^T)] per segment (the compressive geometric part, which
    is negative, is dropped);
  - angular springs: k_a g g^T per joint, g = d theta / dx over the joint's three particles (the theta d2theta term
    is dropped);
  - contacts: w k_c J^T n n^T J per sample contact (w the sample's weight, terms/contacts.py), J the map from
    the sample point and the two ends of the segment it presses to their separation (lever arms held fixed; the
    tangential geometric term is dropped). Each segment stores its view of a contact as lever arms (P on itself,
    Q on the other segment, the sample's own being 0, 1/2 or 1) and n scaled by sqrt(w).
The engine, guiding and slime forces stay explicit (they are slow: the fastest, guiding, has rate k_g / (N zeta_t)
~ 0.5 /s). Properties, each tested in tests/test_implicit.py:
  - fixed points are those of the explicit step (v = 0 exactly where F(x_n) = 0);
  - a rigid translation is in K's null space, so a free straight cell moves at exactly v_b at any step;
  - bodies that push each other move together at the right speed: contacts are coupled in the solve, not added as
    one-sided drag (the `diagonal` mode below shows that error).

Solve. Per cell, Z + dt (K_springs + K_bending + the cell's own share of each contact) is a banded SPD matrix of size
2N (half-bandwidth 5); it is assembled and Cholesky-factorised in one thread per cell. Contacts couple cells (and
non-adjacent segments of one cell). A cell with no contact is solved exactly by its own factor; the cells with
contacts are solved together by preconditioned conjugate gradients with the per-cell factors as a block-Jacobi
preconditioner, warm-started from the previous step's velocities, until r.M^-1 r <= tol^2 F.M^-1 F over those cells
(Chronopoulos-Gear form: one global reduction per iteration, two parallel loops; the contact matrix is applied
matrix-free from the contacts each segment recorded while its forces were computed, terms/contacts.py).
Each term's stiffness block lives with the term (Springs/Bending/Contacts.add_stiffness); this module holds the
drag, the solver and the step; banded.py the per-cell matrices.
Everything is gathered (each segment stores its own contacts; each cell gathers its rows), and reductions sum
per-block partials in a fixed order, so runs are identical on 1 and 2 threads. Blocks per arch
(taichimyxo/runtime/launch.py): on the CPU at most 64 blocks of cells (one below 3000 segments), on a GPU one partial
per cell, summed in groups of
~sqrt(cells) in parallel and the group sums in one thread (`_group_sums`, `_reduce`), still in a fixed order.

Contact modes (constructor argument, for the accuracy study):
  coupled   (default) the above;
  diagonal  each cell solves with its own share of the contact stiffness only, as if the other body were fixed:
            no CG, but bodies pushing each other feel a spurious extra drag dt k_c (measured in the study);
  explicit  contacts stay explicit (IMEX): only springs and bending are implicit.

Accuracy and cost against the explicit step: benchmarks/results/ACCURACY.md (benchmarks/accuracy.py).
In short: stable far beyond the explicit limit, but a linearised step lets overlaps lag by about v dt, so where
cells press into each other (dense clusters, aggregate cores) the step must stay small against F / (k_c v).
"""
import math

import taichi as ti

from ...runtime.kernel_call import direct
from ...runtime.launch import scan_block
from ..neighbours import FLAG_MOVED
from .banded import BandedCells

CONTACT_MODES = ("coupled", "diagonal", "explicit")
DEFAULT_TOL = 1e-3
DEFAULT_MAX_ITER = 40


class ImexError(ValueError):
    pass


@ti.data_oriented
class Imex:
    name = "imex"

    def __init__(self, scene, state, model, neighbours, builder, contacts: str = "coupled", tol: float = DEFAULT_TOL,
                 max_iter: int = DEFAULT_MAX_ITER, iters_per_launch: int = 2):
        if scene.mass > 0:
            raise ImexError("run.integrator = 'imex' is overdamped only; set run.mass_pg = 0")
        if contacts not in CONTACT_MODES:
            raise ImexError(f"contacts={contacts!r}: one of {CONTACT_MODES}")
        self.state, self.model, self.nl = state, model, neighbours
        self.contacts = contacts
        self.tol, self.max_iter, self.iters_per_launch = float(tol), int(max_iter), int(iters_per_launch)
        self.N, self.n2 = scene.N, 2 * scene.N
        self.zeta_t, self.zeta_n = scene.zeta_t, scene.zeta_n
        C, P = state.n_cells, state.n_p
        self.nblk = state.loops.cell_blocks(C)  # partial sums per block of cells (launch.py: CPU <= 64, GPU one a cell)
        self.bs = (C + self.nblk - 1) // self.nblk
        self.band = BandedCells(C, scene.N, state.fdt, builder)
        # explicit contacts: terms that couple cells (contacts) stay out of the matrix
        self.stiff_terms = [u for u in model.stiff_terms
                            if contacts != "explicit" or u not in model.coupling_terms]

        def dof(n):
            return state.scalar(builder, n, state.fdt)

        self.vel = dof(2 * P)                     # solution (velocity), kept as the next step's first guess
        self.rhs = dof(2 * P)                     # F(x_n)
        self.tan = state.vec(builder, P, state.fdt)    # tangents and chain offsets of x_n, for the assembly
        self.xrel = state.vec(builder, P, state.fdt)
        self.coupled = contacts == "coupled"
        # the step's kernel calls without Taichi's Python work (kernel_call.py)
        self._launch_begin, self._launch_iterate, self._launch_finish = (
            direct(self._imex_begin), direct(self._imex_iterate), direct(self._imex_finish))
        if self.coupled:
            self.cg_r, self.cg_u, self.cg_w, self.cg_p, self.cg_s = (dof(2 * P) for _ in range(5))
            self.vprev = dof(2 * P)               # last step's velocities: the first guess
            self.active = state.scalar(builder, C, ti.i32)     # cell takes part in the CG (it has contacts)
            self.part = ti.field(ti.f64)
            builder.dense(ti.ij, (self.nblk, 3)).place(self.part)
            if state.loops.gpu:                   # the two-level reduction: sums of groups of ~sqrt(nblk) partials
                self.grp = scan_block(self.nblk)
                self.ngrp = (self.nblk + self.grp - 1) // self.grp
                self.part2 = ti.field(ti.f64)
                builder.dense(ti.ij, (self.ngrp, 3)).place(self.part2)
        self.cgs = ti.field(ti.f64)               # 0 gamma, 1 delta, 2 gamma_b, 3 alpha, 4 beta
        self.cgi = ti.field(ti.i32)               # 0 state (0 iterating, 1 converged, 2 step done), 1 iterations
        builder.dense(ti.i, 8).place(self.cgs, self.cgi)   # this step, 2 total iterations, 3 steps

    def reset(self, restored: bool = False) -> None:
        """Forget the previous step's velocities (the state was replaced, or restored from a checkpoint, which does
        not keep them)."""
        self.vel.fill(0)
        if self.coupled:
            self.vprev.fill(0)

    def checkpoint_fields(self) -> dict:
        return {}

    def stats(self) -> dict:
        """CG iterations per step since the last reset, and contacts beyond the per-segment store."""
        steps = int(self.cgi[3])
        over = self.model.contacts.overflow
        return {"steps": steps, "cg_iterations": int(self.cgi[2]),
                "cg_per_step": (int(self.cgi[2]) / steps) if steps else 0.0,
                "contact_overflow": int(over[0]) if over is not None else 0}

    def reset_stats(self) -> None:
        for i in (2, 3):
            self.cgi[i] = 0
        if self.model.contacts.overflow is not None:
            self.model.contacts.overflow[0] = 0

    # ------------------------------------------------------------------ per cell
    @ti.func
    def _factor(self, c, dt):
        """Assemble Z + dt K for cell c (drag; each stiff term's block: springs, bending and the cell's own share of
        contacts, unless contacts stay explicit) from tan / xrel, and factorise it."""
        band = self.band
        I2 = ti.Matrix.identity(self.state.fdt, 2)
        band.clear(c)
        for k in range(self.N):
            t = self.tan[c * self.N + k]
            band.add_diag(c, k, self.zeta_n * I2 + (self.zeta_t - self.zeta_n) * t.outer_product(t))
        for u in ti.static(self.stiff_terms):
            u.add_stiffness(band, c, self.xrel, dt)
        band.factor(c)

    @ti.func
    def _apply(self, c, y: ti.template(), out: ti.template(), dt):
        """out = A y on cell c's rows: the cell's own block M y plus the coupling to other cells (contacts)."""
        self.band.multiply(c, y, out)
        for u in ti.static(self.model.coupling_terms):
            u.add_coupling(c, y, out, dt)

    @ti.func
    def _load_cell(self, c):
        """Forces at x_n (all terms) into rhs, tangents and chain offsets into tan / xrel."""
        N = ti.static(self.N)
        x0, X, F, T, Fi = self.model.cell_forces(c)
        for k in ti.static(range(N)):
            p = c * N + k
            f = ti.Vector([F[k, 0], F[k, 1]])
            t = ti.Vector([T[k, 0], T[k, 1]])
            self.rhs[2 * p] = f[0]
            self.rhs[2 * p + 1] = f[1]
            self.tan[p] = t
            self.xrel[p] = ti.Vector([X[k, 0], X[k, 1]])

    @ti.func
    def _advance_cell(self, c, dt):
        """x_n+1 = x_n + dt v for cell c, then what follows a move (as the explicit step)."""
        st = self.state
        N = ti.static(self.N)
        moved = 0
        for k in range(N):
            p = c * N + k
            v = ti.Vector([self.vel[2 * p], self.vel[2 * p + 1]])
            moved |= self.nl.store(p, st.x[p] + ti.cast(v * dt, st.pdt))
        self.model.after_move(c, moved, dt)

    @ti.func
    def _last_loop(self, gated: ti.template(), dt):
        m = self.model
        if ti.static(m.has_last_loop):
            ti.loop_config(**self.state.loops.items)
            for c in range(self.state.n_cells):
                if not gated or self.cgi[0] == 1:
                    m.last_loop(c, dt)

    # ------------------------------------------------------------------ kernels
    @ti.kernel
    def _imex_begin(self, dt: ti.f64) -> ti.i32:
        """Forces, per-cell assembly and factorisation. Without coupled contacts the per-cell solve is the whole
        step; with them, the CG start: r = F - A v_prev, u = M^-1 r, w = A u (v_prev: last step's velocities)."""
        C = ti.static(self.state.n_cells)
        bs = ti.static(self.bs)
        dtf = ti.cast(dt, self.state.fdt)
        self.model.pairs()
        if ti.static(not self.coupled):
            ti.loop_config(**self.state.loops.items)
            for c in range(C):
                self._load_cell(c)
                self._factor(c, dtf)
                self.band.solve(c, self.rhs, self.vel)
                self._advance_cell(c, dt)
            self._last_loop(False, dt)
            ti.loop_config(**self.state.loops.one_thread)
            for _ in range(1):
                self.cgi[3] += 1
        else:
            ti.loop_config(**self.state.loops.items)
            for b in range(self.nblk):
                g = ti.cast(0.0, ti.f64)
                gb = ti.cast(0.0, ti.f64)
                for c in range(b * bs, ti.min((b + 1) * bs, C)):
                    self._load_cell(c)
                    self._factor(c, dtf)
                    base = c * self.n2
                    nc = 0
                    for k in range(self.N - 1):
                        nc += self.model.contacts.ct_n[c * (self.N - 1) + k]
                    if nc == 0:
                        # no contacts: the cell's block is the whole system for it; solve directly, leave the CG
                        self.active[c] = 0
                        self.band.solve(c, self.rhs, self.vel)
                        for i in range(self.n2):
                            self.cg_u[base + i] = 0.0
                    else:
                        self.active[c] = 1
                        self._apply(c, self.vprev, self.cg_r, dtf)
                        for i in range(self.n2):
                            self.cg_r[base + i] = self.rhs[base + i] - self.cg_r[base + i]
                            self.vel[base + i] = self.vprev[base + i]
                            self.cg_p[base + i] = 0.0
                            self.cg_s[base + i] = 0.0
                        self.band.solve(c, self.cg_r, self.cg_u)
                        g += self.band.dot(c, self.cg_r, self.cg_u)
                        self.band.solve(c, self.rhs, self.cg_w)          # w as scratch: F . M^-1 F
                        gb += self.band.dot(c, self.rhs, self.cg_w)
                self.part[b, 0] = g
                self.part[b, 2] = gb
            self._apply_A(dtf, False)
            self._group_sums()
            ti.loop_config(**self.state.loops.one_thread)
            for _ in range(1):
                gam, dlt, gb = self._reduce()
                self.cgs[0] = gam
                self.cgs[1] = dlt
                self.cgs[2] = gb
                self.cgs[4] = 0.0
                self.cgi[1] = 0
                self.cgi[3] += 1
                self.cgi[0] = 0
                if gam <= self.tol * self.tol * self.cgs[2] or dlt <= 0.0:
                    self.cgi[0] = 1
                else:
                    self.cgs[3] = gam / dlt
        return self._code()

    @ti.func
    def _reduce(self):
        """Sums of the per-block partials (gamma, delta, gamma_b), in block order: the same on any thread count (gpu
        shape: of the group sums, each in block order)."""
        gam = ti.cast(0.0, ti.f64)
        dlt = ti.cast(0.0, ti.f64)
        gb = ti.cast(0.0, ti.f64)
        if ti.static(self.state.loops.gpu):
            for g in range(self.ngrp):
                gam += self.part2[g, 0]
                dlt += self.part2[g, 1]
                gb += self.part2[g, 2]
        else:
            for b in range(self.nblk):
                gam += self.part[b, 0]
                dlt += self.part[b, 1]
                gb += self.part[b, 2]
        return gam, dlt, gb

    @ti.func
    def _group_sums(self):
        """gpu shape: the reduction's first level, in parallel: part2[g] = the partials of group g, in block order."""
        if ti.static(self.state.loops.gpu):
            G = ti.static(self.grp)
            ti.loop_config(**self.state.loops.items)
            for g in range(self.ngrp):
                for k in ti.static(range(3)):
                    acc = ti.cast(0.0, ti.f64)
                    for b in range(g * G, ti.min((g + 1) * G, self.nblk)):
                        acc += self.part[b, k]
                    self.part2[g, k] = acc

    @ti.func
    def _apply_A(self, dtf, gated: ti.template()):
        """w = A u (gathering neighbours' u), per-block partials of u.w; gated: only while CG is iterating."""
        C = ti.static(self.state.n_cells)
        bs = ti.static(self.bs)
        ti.loop_config(**self.state.loops.items)
        for b in range(self.nblk):
            d = ti.cast(0.0, ti.f64)
            if not gated or self.cgi[0] == 0:
                for c in range(b * bs, ti.min((b + 1) * bs, C)):
                    if self.active[c]:
                        self._apply(c, self.cg_u, self.cg_w, dtf)
                        d += self.band.dot(c, self.cg_u, self.cg_w)
            self.part[b, 1] = d

    @ti.kernel
    def _imex_iterate(self, dt: ti.f64) -> ti.i32:
        """`iters_per_launch` CG iterations (skipped once converged), then the position update if converged."""
        C = ti.static(self.state.n_cells)
        bs = ti.static(self.bs)
        dtf = ti.cast(dt, self.state.fdt)
        for _it in ti.static(range(self.iters_per_launch)):
            ti.loop_config(**self.state.loops.items)
            for b in range(self.nblk):
                g = ti.cast(0.0, ti.f64)
                if self.cgi[0] == 0:
                    al = ti.cast(self.cgs[3], self.state.fdt)
                    be = ti.cast(self.cgs[4], self.state.fdt)
                    for c in range(b * bs, ti.min((b + 1) * bs, C)):
                        if not self.active[c]:
                            continue
                        base = c * self.n2
                        for i in range(self.n2):
                            p = self.cg_u[base + i] + be * self.cg_p[base + i]
                            s = self.cg_w[base + i] + be * self.cg_s[base + i]
                            self.cg_p[base + i] = p
                            self.cg_s[base + i] = s
                            self.vel[base + i] = self.vel[base + i] + al * p
                            self.cg_r[base + i] = self.cg_r[base + i] - al * s
                        self.band.solve(c, self.cg_r, self.cg_u)
                        g += self.band.dot(c, self.cg_r, self.cg_u)
                self.part[b, 0] = g
            self._apply_A(dtf, True)
            self._group_sums()
            ti.loop_config(**self.state.loops.one_thread)
            for _ in range(1):
                if self.cgi[0] == 0:
                    gam, dlt, gb_unused = self._reduce()
                    self.cgi[1] += 1
                    self.cgi[2] += 1
                    if gam <= self.tol * self.tol * self.cgs[2] or self.cgi[1] >= self.max_iter:
                        self.cgi[0] = 1
                    else:
                        be = gam / self.cgs[0]
                        den = dlt - be * gam / self.cgs[3]
                        if den <= 0.0:
                            self.cgi[0] = 1
                        else:
                            self.cgs[4] = be
                            self.cgs[3] = gam / den
                            self.cgs[0] = gam
        self._finish(dt)
        return self._code()

    @ti.func
    def _finish(self, dt):
        ti.loop_config(**self.state.loops.items)
        for c in range(self.state.n_cells):
            if self.cgi[0] == 1:
                self._advance_cell(c, dt)
                base = c * self.n2
                for i in range(self.n2):
                    self.vprev[base + i] = self.vel[base + i]
        self._last_loop(True, dt)
        ti.loop_config(**self.state.loops.one_thread)
        for _ in range(1):
            if self.cgi[0] == 1:
                self.cgi[0] = 2

    @ti.kernel
    def _imex_finish(self, dt: ti.f64) -> ti.i32:
        ti.loop_config(**self.state.loops.one_thread)
        for _ in range(1):
            self.cgi[0] = 1
        self._finish(dt)
        return self._code()

    @ti.func
    def _code(self):
        """What a step's kernel returns: 2 x the CG state (2: converged and moved) + the neighbour-list flag."""
        return 2 * self.cgi[0] + self.nl.flags[FLAG_MOVED]

    def step(self, dt: float) -> int:
        """One linearly implicit step (module docstring). Returns its step code (integrators/__init__.py): with no
        step controller, the neighbour-list flag alone (a particle moved past half the skin)."""
        code = self._launch_begin(dt)
        if self.coupled:
            for _ in range(math.ceil(self.max_iter / self.iters_per_launch) + 1):
                code = self._launch_iterate(dt)
                if code >> 1 == 2:
                    break
            else:
                code = self._launch_finish(dt)
        return code & 1
