"""The stiff-capable step (scene run.integrator = "imex"): linearly implicit Euler on springs, bending and contacts.

Equation (MODEL.md "Equation of motion", overdamped): Z(x) v = F(x), Z the anisotropic drag. The explicit step takes
v = Z^-1 F(x_n) and is stable only while dt stays below ~2 zeta / (stiffest rate): a few ms at the paper's k_s, k_c
and very rigid k_a. This step takes one Newton step of backward Euler instead:

    (Z_n + dt K_n) v = F(x_n),        x_n+1 = x_n + dt v,

with Z_n the drag at the start of the step (tangents of x_n) and K_n the positive semidefinite (Gauss-Newton) part of
the stiffness -dF/dx of the conservative stiff terms:
  - linear springs: k_s [u u^T + max(0, 1 - l0/l) (I - u u^T)] per segment (the compressive geometric part, which
    is negative, is dropped);
  - angular springs: k_a g g^T per joint, g = d theta / dx over the joint's three particles (the theta d2theta term
    is dropped);
  - contacts: k_c J^T n n^T J per accepted contact, J the lever-rule map from the four end particles to the
    separation of the closest points (lever arms P, Q held fixed; the tangential geometric term is dropped).
The engine, guiding and slime forces stay explicit (they are slow: the fastest, guiding, has rate k_g / (N zeta_t)
~ 0.5 /s). Properties, each tested in tests/test_implicit.py:
  - fixed points are those of the explicit step (v = 0 exactly where F(x_n) = 0);
  - a rigid translation is in K's null space, so a free straight cell moves at exactly v_b at any step;
  - bodies that push each other move together at the right speed: contacts are coupled in the solve, not added as
    one-sided drag (the `diagonal` mode below shows that error).

Solve. Per cell, Z + dt (K_springs + K_bending + the cell's own share of each contact) is a banded SPD matrix of size
2N (half-bandwidth 5); it is assembled and Cholesky-factorised in one thread per cell. Contacts couple cells (and
non-adjacent segments of one cell); the global system is solved by preconditioned conjugate gradients with that
per-cell factor as a block-Jacobi preconditioner, warm-started from the previous step's velocities, until
r.M^-1 r <= tol^2 F.M^-1 F (Chronopoulos-Gear form: one global reduction per iteration, two parallel loops).
Everything is gathered (each segment stores its own contacts; each cell gathers its rows), and reductions sum
per-block partials in a fixed order, so runs are identical on 1 and 2 threads.

Contact modes (constructor argument, for the accuracy study):
  coupled   (default) the above;
  diagonal  each cell solves with its own share of the contact stiffness only, as if the other body were fixed:
            no CG, but bodies pushing each other feel a spurious extra drag dt k_c (measured in the study);
  explicit  contacts stay explicit (IMEX): only springs and bending are implicit.
"""

import math

import numpy as np
import taichi as ti

from .scene import SceneError
from .sim import Simulation, _min_image, _perp

CONTACT_MODES = ("coupled", "diagonal", "explicit")
DEFAULT_TOL = 1e-3
DEFAULT_MAX_ITER = 40


@ti.data_oriented
class ImplicitSimulation(Simulation):
    MAX_CONTACTS = 8          # stored contacts per segment; more are kept in the force but not in the Jacobian

    def __init__(self, scene, positions=None, engine_direction=None, contacts: str = "coupled",
                 tol: float = DEFAULT_TOL, max_iter: int = DEFAULT_MAX_ITER, iters_per_launch: int = 4):
        if scene.raw["run"]["mass_pg"] > 0:
            raise SceneError("run.integrator = 'imex' is overdamped only; set run.mass_pg = 0")
        if contacts not in CONTACT_MODES:
            raise ValueError(f"contacts={contacts!r}: one of {CONTACT_MODES}")
        self.contacts = contacts
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.iters_per_launch = int(iters_per_launch)
        self._imex_tree = None
        super().__init__(scene, positions=positions, engine_direction=engine_direction)
        cfg = self.cfg
        N = cfg.N
        self.n2 = 2 * N
        self.BW = min(6, self.n2)                 # lower band incl. the diagonal: bending couples k and k+2
        C, P, S = cfg.n_cells, self.n_p, self.n_s
        self.nblk = 1 if self.serial else min(C, 64)
        self.bs = (C + self.nblk - 1) // self.nblk
        fb = ti.FieldsBuilder()

        def vec(n):
            f = ti.Vector.field(2, dtype=self.fdt)
            fb.dense(ti.i, n).place(f)
            return f

        self.Lf = ti.field(self.fdt)              # per cell: lower band of the Cholesky factor, last slot 1/diag
        fb.dense(ti.ijk, (C, self.n2, self.BW + 1)).place(self.Lf)
        self.vel = vec(P)                         # solution (velocity), kept as the next step's first guess
        self.coupled = contacts == "coupled"
        if contacts != "explicit":
            self.ct_n = ti.field(ti.i32)
            fb.dense(ti.i, S).place(self.ct_n)
            self.ct_t = ti.field(ti.i32)
            self.ct_w = ti.Vector.field(4, dtype=self.fdt)    # (P on s, Q on t, n_x, n_y), n from t to s
            fb.dense(ti.ij, (S, self.MAX_CONTACTS)).place(self.ct_t, self.ct_w)
        if self.coupled:
            self.cg_r, self.cg_u, self.cg_w, self.cg_p, self.cg_s = (vec(P) for _ in range(5))
            self.part = ti.field(ti.f64)
            fb.dense(ti.ij, (self.nblk, 3)).place(self.part)
        self.cgs = ti.field(ti.f64)               # 0 gamma, 1 delta, 2 gamma_b, 3 alpha, 4 beta
        self.cgi = ti.field(ti.i32)               # 0 state (0 iterating, 1 converged, 2 step done), 1 iterations
        fb.dense(ti.i, 8).place(self.cgs, self.cgi)   # this step, 2 total iterations, 3 steps, 4 contact overflows
        self._imex_tree = fb.finalize()
        self.vel.fill(0)

    # ------------------------------------------------------------------ state
    def set_state(self, positions, engine_direction, step: int = 0) -> None:
        super().set_state(positions, engine_direction, step)
        if self._imex_tree is not None:
            self.vel.fill(0)

    def load_checkpoint(self, st: dict) -> None:
        super().load_checkpoint(st)
        self.vel.fill(0)

    def close(self) -> None:
        super().close()
        if self._imex_tree is not None:
            self._imex_tree.destroy()
            self._imex_tree = None

    def solver_stats(self) -> dict:
        """CG iterations per step since the last reset, and contacts beyond the per-segment store."""
        steps = int(self.cgi[3])
        return {"steps": steps, "cg_iterations": int(self.cgi[2]),
                "cg_per_step": (int(self.cgi[2]) / steps) if steps else 0.0, "contact_overflow": int(self.cgi[4])}

    def reset_stats(self) -> None:
        for i in (2, 3, 4):
            self.cgi[i] = 0

    # ------------------------------------------------------------------ contacts recorded by _pair_forces
    @ti.func
    def _contact_hook(self, s, i, t, P, dist, n):
        if ti.static(self.contacts != "explicit"):
            if i < self.MAX_CONTACTS:
                a, b = self._seg_ends(s)
                c_, d_ = self._seg_ends(t)
                xa = self.x[a]
                pb = ti.cast(_min_image(self.x[b] - xa, self.cfg.Lx, self.cfg.Ly), self.fdt)
                pc = ti.cast(_min_image(self.x[c_] - xa, self.cfg.Lx, self.cfg.Ly), self.fdt)
                pd = pc + ti.cast(_min_image(self.x[d_] - self.x[c_], self.cfg.Lx, self.cfg.Ly), self.fdt)
                c2 = P * pb - dist * n              # closest point on t (the separation is dist * n)
                e = pd - pc
                ee = e.dot(e)
                Q = ti.cast(0.0, self.fdt)
                if ee > 1e-12:
                    Q = ti.math.clamp((c2 - pc).dot(e) / ee, 0.0, 1.0)
                self.ct_t[s, i] = t
                self.ct_w[s, i] = ti.Vector([P, Q, n[0], n[1]], dt=self.fdt)
            else:
                ti.atomic_add(self.cgi[4], 1)

    @ti.func
    def _contact_count_hook(self, s, n_contacts):
        if ti.static(self.contacts != "explicit"):
            self.ct_n[s] = ti.min(n_contacts, self.MAX_CONTACTS)

    # ------------------------------------------------------------------ per-cell banded matrix
    @ti.func
    def _addb(self, Mb: ti.template(), pi: ti.template(), pj: ti.template(), B):
        """Add the 2x2 block B at particle rows pi >= pj to the lower band Mb[i, i - j]."""
        for a in ti.static(range(2)):
            for b in ti.static(range(2)):
                if ti.static(2 * pi + a >= 2 * pj + b):
                    Mb[2 * pi + a, 2 * pi + a - 2 * pj - b] += B[a, b]

    @ti.func
    def _factor(self, c, X, T, dt):
        """Assemble Z + dt K for cell c (drag, springs, bending, own share of contacts) and factorise into Lf[c]."""
        N = ti.static(self.cfg.N)
        n2 = ti.static(self.n2)
        BW = ti.static(self.BW)
        Mb = ti.Matrix.zero(self.fdt, n2, BW)
        I2 = ti.Matrix.identity(self.fdt, 2)
        for k in ti.static(range(N)):
            t = ti.Vector([T[k, 0], T[k, 1]])
            self._addb(Mb, k, k, self.cfg.zeta_n * I2 + (self.cfg.zeta_t - self.cfg.zeta_n) * t.outer_product(t))
        U = ti.Matrix.zero(self.fdt, N - 1, 2)
        Ln = ti.Vector.zero(self.fdt, N - 1)
        for k in ti.static(range(N - 1)):
            l = ti.Vector([X[k + 1, 0] - X[k, 0], X[k + 1, 1] - X[k, 1]])
            ln = l.norm()
            u = l / ln
            Ln[k] = ln
            U[k, 0] = u[0]
            U[k, 1] = u[1]
            g = ti.max(0.0, 1.0 - self.cfg.l0 / ln)
            Ks = dt * self.cfg.k_s * ((1.0 - g) * u.outer_product(u) + g * I2)
            self._addb(Mb, k, k, Ks)
            self._addb(Mb, k + 1, k + 1, Ks)
            self._addb(Mb, k + 1, k, -Ks)
        for j in ti.static(range(N - 2)):
            gA = _perp(ti.Vector([U[j, 0], U[j, 1]])) / Ln[j]
            gC = _perp(ti.Vector([U[j + 1, 0], U[j + 1, 1]])) / Ln[j + 1]
            gB = -(gA + gC)
            G = [gA, gB, gC]
            ka = dt * self.cfg.k_a
            for p in ti.static(range(3)):
                for q in ti.static(range(p + 1)):
                    self._addb(Mb, j + p, j + q, ka * G[p].outer_product(G[q]))
        if ti.static(self.contacts != "explicit"):
            kc = dt * self.cfg.k_c
            for k in ti.static(range(N - 1)):
                s = c * (N - 1) + k
                for q in range(self.ct_n[s]):
                    w4 = self.ct_w[s, q]
                    P = w4[0]
                    nv = ti.Vector([w4[2], w4[3]])
                    nn = kc * nv.outer_product(nv)
                    self._addb(Mb, k, k, (1.0 - P) * (1.0 - P) * nn)
                    self._addb(Mb, k + 1, k + 1, P * P * nn)
                    self._addb(Mb, k + 1, k, (1.0 - P) * P * nn)
        # banded Cholesky, L[i, j] stored at Lf[c, i, i - j]; slot BW holds 1 / L[i, i]
        L = ti.Matrix.zero(self.fdt, n2, BW + 1)
        for i in ti.static(range(n2)):
            for j in ti.static(range(max(0, i - BW + 1), i + 1)):
                acc = Mb[i, i - j]
                for k in ti.static(range(max(0, i - BW + 1), j)):
                    acc -= L[i, i - k] * L[j, j - k]
                if ti.static(i == j):
                    d = ti.sqrt(ti.max(acc, 1e-30))
                    L[i, 0] = d
                    L[i, BW] = 1.0 / d
                else:
                    L[i, i - j] = acc * L[j, BW]
        for i in ti.static(range(n2)):
            for j in ti.static(range(BW + 1)):
                self.Lf[c, i, j] = L[i, j]

    @ti.func
    def _load_factor(self, c):
        L = ti.Matrix.zero(self.fdt, self.n2, self.BW + 1)
        for i in ti.static(range(self.n2)):
            for j in ti.static(range(self.BW + 1)):
                L[i, j] = self.Lf[c, i, j]
        return L

    @ti.func
    def _solve(self, L, r):
        """z = M^-1 r with M = L L^T (banded)."""
        n2 = ti.static(self.n2)
        BW = ti.static(self.BW)
        y = ti.Vector.zero(self.fdt, n2)
        for i in ti.static(range(n2)):
            acc = r[i]
            for k in ti.static(range(max(0, i - BW + 1), i)):
                acc -= L[i, i - k] * y[k]
            y[i] = acc * L[i, BW]
        z = ti.Vector.zero(self.fdt, n2)
        for ii in ti.static(range(n2)):
            i = ti.static(n2 - 1 - ii)
            acc = y[i]
            for k in ti.static(range(i + 1, min(n2, i + BW))):
                acc -= L[k, k - i] * z[k]
            z[i] = acc * L[i, BW]
        return z

    @ti.func
    def _mul(self, L, y):
        """M y = L (L^T y)."""
        n2 = ti.static(self.n2)
        BW = ti.static(self.BW)
        t = ti.Vector.zero(self.fdt, n2)
        for i in ti.static(range(n2)):
            for k in ti.static(range(i, min(n2, i + BW))):
                t[i] += L[k, k - i] * y[k]
        out = ti.Vector.zero(self.fdt, n2)
        for i in ti.static(range(n2)):
            for k in ti.static(range(max(0, i - BW + 1), i + 1)):
                out[i] += L[i, i - k] * t[k]
        return out

    @ti.func
    def _get(self, f: ti.template(), c):
        v = ti.Vector.zero(self.fdt, self.n2)
        for k in ti.static(range(self.cfg.N)):
            e = f[c * self.cfg.N + k]
            v[2 * k] = e[0]
            v[2 * k + 1] = e[1]
        return v

    @ti.func
    def _put(self, f: ti.template(), c, v):
        for k in ti.static(range(self.cfg.N)):
            f[c * self.cfg.N + k] = ti.Vector([v[2 * k], v[2 * k + 1]])

    @ti.func
    def _offdiag(self, c, y: ti.template(), dt):
        """Rows of cell c of dt K_contact y minus the cell's own share (which is in M): for each contact of each of
        the cell's segments, -dt k_c J_s^T n (n . J_t y_t). Gathered from the segment's stored contacts."""
        N = ti.static(self.cfg.N)
        out = ti.Vector.zero(self.fdt, self.n2)
        kc = dt * self.cfg.k_c
        for k in ti.static(range(N - 1)):
            s = c * (N - 1) + k
            oa = ti.Vector([0.0, 0.0], dt=self.fdt)
            ob = ti.Vector([0.0, 0.0], dt=self.fdt)
            for q in range(self.ct_n[s]):
                t = self.ct_t[s, q]
                w4 = self.ct_w[s, q]
                P = w4[0]
                Q = w4[1]
                nv = ti.Vector([w4[2], w4[3]])
                pc, pd = self._seg_ends(t)
                wt = nv.dot((1.0 - Q) * y[pc] + Q * y[pd])
                oa += (1.0 - P) * wt * nv
                ob += P * wt * nv
            out[2 * k] -= kc * oa[0]
            out[2 * k + 1] -= kc * oa[1]
            out[2 * k + 2] -= kc * ob[0]
            out[2 * k + 3] -= kc * ob[1]
        return out

    # ------------------------------------------------------------------ end of step (shared by the modes)
    @ti.func
    def _advance_cell(self, c, V, dt, check_skin):
        """x_n+1 = x_n + dt v for cell c (V: its 2N velocity components), wrap, skin flag, slime claim, clock."""
        N = ti.static(self.cfg.N)
        half_skin2 = ti.static((0.5 * self.cfg.skin) ** 2)
        moved = 0
        for k in ti.static(range(N)):
            p = c * N + k
            xn = self.x[p] + ti.cast(ti.Vector([V[2 * k], V[2 * k + 1]]) * dt, self.pdt)
            xn[0] -= self.cfg.Lx * ti.floor(xn[0] / self.cfg.Lx)
            xn[1] -= self.cfg.Ly * ti.floor(xn[1] / self.cfg.Ly)
            self.x[p] = xn
            if check_skin:
                dd = _min_image(xn - self.x_ref[p], self.cfg.Lx, self.cfg.Ly)
                if dd.dot(dd) > half_skin2:
                    moved = 1
        if moved:
            self.flags[1] = 1
        if ti.static(self.cfg.slime):
            self._slime_claim(c)
        else:
            if ti.static(self.cfg.reversals):
                self._reversal_clock(c)

    @ti.func
    def _slime_pass(self):
        if ti.static(self.cfg.slime):
            ti.loop_config(serialize=self.serial)
            for c in range(self.cfg.n_cells):
                if self.cgi[0] == 1:
                    self._slime_write(c)
                    if ti.static(self.cfg.reversals):
                        self._reversal_clock(c)

    # ------------------------------------------------------------------ kernels
    @ti.kernel
    def _imex_begin(self, dt: ti.f64, check_skin: ti.i32):
        """Forces at x_n (MODEL.md terms 1-6), per-cell assembly and factorisation. Without coupled contacts the
        per-cell solve is the whole step; with them, the CG start: r = F - A v_prev, u = M^-1 r, w = A u."""
        C = ti.static(self.cfg.n_cells)
        bs = ti.static(self.bs)
        dtf = ti.cast(dt, self.fdt)
        if ti.static(self.cfg.suppression):
            ti.loop_config(serialize=self.serial)
            for c in range(C):
                self.interacting[c] = 0
        self._pair_forces()
        if ti.static(not self.coupled):
            ti.loop_config(serialize=self.serial)
            for c in range(C):
                x0, X, F, T, Fi = self._cell_forces(c)
                self._factor(c, X, T, dtf)
                fv = ti.Vector.zero(self.fdt, self.n2)
                for k in ti.static(range(self.cfg.N)):
                    fv[2 * k] = F[k, 0]
                    fv[2 * k + 1] = F[k, 1]
                V = self._solve(self._load_factor(c), fv)
                self._put(self.vel, c, V)
                self._advance_cell(c, V, dt, check_skin)
            if ti.static(self.cfg.slime):
                ti.loop_config(serialize=self.serial)
                for c in range(C):
                    self._slime_write(c)
                    if ti.static(self.cfg.reversals):
                        self._reversal_clock(c)
            ti.loop_config(serialize=True)
            for _ in range(1):
                self.cgi[3] += 1
        else:
            ti.loop_config(serialize=self.serial)
            for b in range(self.nblk):
                g = ti.cast(0.0, ti.f64)
                gb = ti.cast(0.0, ti.f64)
                for c in range(b * bs, ti.min((b + 1) * bs, C)):
                    x0, X, F, T, Fi = self._cell_forces(c)
                    self._factor(c, X, T, dtf)
                    L = self._load_factor(c)
                    fv = ti.Vector.zero(self.fdt, self.n2)
                    for k in ti.static(range(self.cfg.N)):
                        fv[2 * k] = F[k, 0]
                        fv[2 * k + 1] = F[k, 1]
                    v0 = self._get(self.vel, c)
                    r = fv - self._mul(L, v0) - self._offdiag(c, self.vel, dtf)
                    u = self._solve(L, r)
                    self._put(self.cg_r, c, r)
                    self._put(self.cg_u, c, u)
                    z = ti.Vector.zero(self.fdt, self.n2)
                    self._put(self.cg_p, c, z)
                    self._put(self.cg_s, c, z)
                    g += ti.cast(r.dot(u), ti.f64)
                    gb += ti.cast(fv.dot(self._solve(L, fv)), ti.f64)
                self.part[b, 0] = g
                self.part[b, 2] = gb
            self._apply_A(dtf, False)
            ti.loop_config(serialize=True)
            for _ in range(1):
                gam = ti.cast(0.0, ti.f64)
                dlt = ti.cast(0.0, ti.f64)
                gb = ti.cast(0.0, ti.f64)
                for b in range(self.nblk):
                    gam += self.part[b, 0]
                    dlt += self.part[b, 1]
                    gb += self.part[b, 2]
                self.cgs[0] = gam
                self.cgs[1] = dlt
                self.cgs[2] = gb
                self.cgs[4] = 0.0
                self.cgi[1] = 0
                self.cgi[3] += 1
                self.cgi[0] = 0
                if gam <= self.tol * self.tol * gb or dlt <= 0.0:
                    self.cgi[0] = 1
                else:
                    self.cgs[3] = gam / dlt

    @ti.func
    def _apply_A(self, dtf, gated: ti.template()):
        """w = A u (gathering neighbours' u), per-block partials of u.w; gated: only while CG is iterating."""
        C = ti.static(self.cfg.n_cells)
        bs = ti.static(self.bs)
        ti.loop_config(serialize=self.serial)
        for b in range(self.nblk):
            d = ti.cast(0.0, ti.f64)
            if not gated or self.cgi[0] == 0:
                for c in range(b * bs, ti.min((b + 1) * bs, C)):
                    u = self._get(self.cg_u, c)
                    w = self._mul(self._load_factor(c), u) + self._offdiag(c, self.cg_u, dtf)
                    self._put(self.cg_w, c, w)
                    d += ti.cast(u.dot(w), ti.f64)
            self.part[b, 1] = d

    @ti.kernel
    def _imex_iterate(self, dt: ti.f64, check_skin: ti.i32):
        """`iters_per_launch` CG iterations (skipped once converged), then the position update if converged."""
        C = ti.static(self.cfg.n_cells)
        bs = ti.static(self.bs)
        dtf = ti.cast(dt, self.fdt)
        for _it in ti.static(range(self.iters_per_launch)):
            ti.loop_config(serialize=self.serial)
            for b in range(self.nblk):
                g = ti.cast(0.0, ti.f64)
                if self.cgi[0] == 0:
                    al = ti.cast(self.cgs[3], self.fdt)
                    be = ti.cast(self.cgs[4], self.fdt)
                    for c in range(b * bs, ti.min((b + 1) * bs, C)):
                        p = self._get(self.cg_u, c) + be * self._get(self.cg_p, c)
                        s = self._get(self.cg_w, c) + be * self._get(self.cg_s, c)
                        self._put(self.cg_p, c, p)
                        self._put(self.cg_s, c, s)
                        self._put(self.vel, c, self._get(self.vel, c) + al * p)
                        r = self._get(self.cg_r, c) - al * s
                        u = self._solve(self._load_factor(c), r)
                        self._put(self.cg_r, c, r)
                        self._put(self.cg_u, c, u)
                        g += ti.cast(r.dot(u), ti.f64)
                self.part[b, 0] = g
            self._apply_A(dtf, True)
            ti.loop_config(serialize=True)
            for _ in range(1):
                if self.cgi[0] == 0:
                    gam = ti.cast(0.0, ti.f64)
                    dlt = ti.cast(0.0, ti.f64)
                    for b in range(self.nblk):
                        gam += self.part[b, 0]
                        dlt += self.part[b, 1]
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
        self._finish(dt, check_skin)

    @ti.func
    def _finish(self, dt, check_skin):
        ti.loop_config(serialize=self.serial)
        for c in range(self.cfg.n_cells):
            if self.cgi[0] == 1:
                self._advance_cell(c, self._get(self.vel, c), dt, check_skin)
        self._slime_pass()
        ti.loop_config(serialize=True)
        for _ in range(1):
            if self.cgi[0] == 1:
                self.cgi[0] = 2

    @ti.kernel
    def _imex_finish(self, dt: ti.f64, check_skin: ti.i32):
        ti.loop_config(serialize=True)
        for _ in range(1):
            self.cgi[0] = 1
        self._finish(dt, check_skin)

    def _step(self, dt, check_skin):
        """One linearly implicit step (module docstring). Replaces the explicit kernel; run() drives it."""
        self._imex_begin(dt, check_skin)
        if not self.coupled:
            return
        for _ in range(math.ceil(self.max_iter / self.iters_per_launch) + 1):
            self._imex_iterate(dt, check_skin)
            if self.cgi[0] == 2:
                return
        self._imex_finish(dt, check_skin)
