"""The stiff-capable step (scene run.integrator = "imex"): linearly implicit Euler on springs, bending and contacts.

Equation (docs/model.md "Equation of motion", overdamped): Z(x) v = F(x), Z the anisotropic drag. The explicit step takes
v = Z^-1 F(x_n) and is stable only while dt stays below ~2 zeta / (stiffest rate): a few ms at the paper's k_s, k_c
and very rigid k_a. This step takes one Newton step of backward Euler instead:

    (Z_n + dt K_n) v = F(x_n),        x_n+1 = x_n + dt v,

with Z_n the drag at the start of the step (tangents of x_n) and K_n the positive semidefinite (Gauss-Newton) part of
the stiffness -dF/dx of the conservative stiff terms:
  - linear springs: k_s [u u^T + max(0, 1 - l0/l) (I - u u^T)] per segment (the compressive geometric part, which
    is negative, is dropped);
  - angular springs: k_a g g^T per joint, g = d theta / dx over the joint's three particles (the theta d2theta term
    is dropped);
  - contacts: w k_c J^T n n^T J per sample contact (w the sample's weight, sim.py "contact law"), J the map from
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
matrix-free from the contacts each segment recorded while its forces were computed, through a hook in
Simulation._pair_forces).
Everything is gathered (each segment stores its own contacts; each cell gathers its rows), and reductions sum
per-block partials in a fixed order, so runs are identical on 1 and 2 threads.

Contact modes (constructor argument, for the accuracy study):
  coupled   (default) the above;
  diagonal  each cell solves with its own share of the contact stiffness only, as if the other body were fixed:
            no CG, but bodies pushing each other feel a spurious extra drag dt k_c (measured in the study);
  explicit  contacts stay explicit (IMEX): only springs and bending are implicit.

Accuracy and cost against the explicit step: benchmarks/results/ACCURACY.md (python -m taichimyxo bench accuracy).
In short: stable far beyond the explicit limit, but a linearised step lets overlaps lag by about v dt, so where
cells press into each other (dense clusters, aggregate cores) the step must stay small against F / (k_c v).
"""

import math

import taichi as ti

from .scene import SceneError
from .sim import Simulation, _perp

CONTACT_MODES = ("coupled", "diagonal", "explicit")
DEFAULT_TOL = 1e-3
DEFAULT_MAX_ITER = 40


@ti.data_oriented
class ImplicitSimulation(Simulation):
    MAX_CONTACTS = 16         # stored node contacts per segment; more are kept in the force but not in the Jacobian

    def __init__(self, scene, positions=None, engine_direction=None, contacts: str = "coupled",
                 tol: float = DEFAULT_TOL, max_iter: int = DEFAULT_MAX_ITER, iters_per_launch: int = 2):
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

        def dof(n):
            f = ti.field(dtype=self.fdt)
            fb.dense(ti.i, n).place(f)
            return f

        self.Lf = ti.field(self.fdt)              # per dof: lower band of the cell's Cholesky factor, then 1/diag
        fb.dense(ti.ij, (2 * P, self.BW + 1)).place(self.Lf)
        self.vel = dof(2 * P)                     # solution (velocity), kept as the next step's first guess
        self.rhs = dof(2 * P)                     # F(x_n)
        self.tmp = dof(2 * P)
        self.tan = vec(P)                         # tangents and chain offsets of x_n, for the assembly
        self.xrel = vec(P)
        self.coupled = contacts == "coupled"
        if contacts != "explicit":
            self.ct_n = ti.field(ti.i32)
            fb.dense(ti.i, S).place(self.ct_n)
            self.ct_t = ti.field(ti.i32)
            self.ct_w = ti.Vector.field(4, dtype=self.fdt)    # (P on s, Q on t, n_x, n_y), n from t to s
            fb.dense(ti.ij, (S, self.MAX_CONTACTS)).place(self.ct_t, self.ct_w)
        if self.coupled:
            self.cg_r, self.cg_u, self.cg_w, self.cg_p, self.cg_s = (dof(2 * P) for _ in range(5))
            self.vprev = dof(2 * P)               # last step's velocities: the first guess
            self.active = ti.field(ti.i32)        # cell takes part in the CG (it has contacts)
            fb.dense(ti.i, C).place(self.active)
            self.part = ti.field(ti.f64)
            fb.dense(ti.ij, (self.nblk, 3)).place(self.part)
        self.cgs = ti.field(ti.f64)               # 0 gamma, 1 delta, 2 gamma_b, 3 alpha, 4 beta
        self.cgi = ti.field(ti.i32)               # 0 state (0 iterating, 1 converged, 2 step done), 1 iterations
        fb.dense(ti.i, 8).place(self.cgs, self.cgi)   # this step, 2 total iterations, 3 steps, 4 contact overflows
        self._imex_tree = fb.finalize()
        self._zero_guess()

    def _zero_guess(self):
        self.vel.fill(0)
        if self.coupled:
            self.vprev.fill(0)

    # ------------------------------------------------------------------ state
    def set_state(self, positions, engine_direction, step: int = 0) -> None:
        super().set_state(positions, engine_direction, step)
        if self._imex_tree is not None:
            self._zero_guess()

    def load_checkpoint(self, st: dict) -> None:
        super().load_checkpoint(st)
        self._zero_guess()

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
    def _contact_hook(self, s, i, t, P, Q, gn):
        if ti.static(self.contacts != "explicit"):
            if i < self.MAX_CONTACTS:
                self.ct_t[s, i] = t
                self.ct_w[s, i] = ti.Vector([P, Q, gn[0], gn[1]], dt=self.fdt)
            else:
                ti.atomic_add(self.cgi[4], 1)

    @ti.func
    def _contact_count_hook(self, s, n_contacts):
        if ti.static(self.contacts != "explicit"):
            self.ct_n[s] = ti.min(n_contacts, self.MAX_CONTACTS)

    # ------------------------------------------------------------------ per-cell banded matrix
    # Vectors are scalar fields over degrees of freedom: dof 2 p + a is axis a of particle p, so cell c owns dofs
    # c n2 ... c n2 + n2 - 1. Loops over dofs are dynamic (not unrolled): with the band held in registers and every
    # solve unrolled, Taichi took five minutes to compile; these loops are short and cache-resident. Only the
    # factorisation, which appears once in the program, is unrolled.
    @ti.func
    def _addb(self, base, pi, pj, B):
        """Add the 2x2 block B at particle rows pi > pj to the lower band (Lf[base + i, i - j])."""
        for a in ti.static(range(2)):
            for b in ti.static(range(2)):
                i = 2 * pi + a
                j = i - 2 * pj - b
                self.Lf[base + i, j] = self.Lf[base + i, j] + B[a, b]

    @ti.func
    def _addd(self, base, pi, B):
        """Add the symmetric 2x2 block B on the diagonal of particle pi."""
        # plain read-modify-write: `field[i] += x` compiles to an atomic add, several times slower
        i = base + 2 * pi
        self.Lf[i, 0] = self.Lf[i, 0] + B[0, 0]
        self.Lf[i + 1, 0] = self.Lf[i + 1, 0] + B[1, 1]
        self.Lf[i + 1, 1] = self.Lf[i + 1, 1] + B[1, 0]

    @ti.func
    def _factor(self, c, dt):
        """Assemble Z + dt K for cell c (drag, springs, bending, own share of contacts) from tan / xrel and
        Cholesky-factorise it in place in Lf (lower band, L[i, j] at Lf[base + i, i - j], 1 / L[i, i] in the last
        slot)."""
        N = ti.static(self.cfg.N)
        n2 = ti.static(self.n2)
        BW = ti.static(self.BW)
        base = c * n2
        pb = c * N
        I2 = ti.Matrix.identity(self.fdt, 2)
        for i in range(n2):
            for j in ti.static(range(BW + 1)):
                self.Lf[base + i, j] = 0.0
        for k in range(N):
            t = self.tan[pb + k]
            self._addd(base, k, self.cfg.zeta_n * I2 + (self.cfg.zeta_t - self.cfg.zeta_n) * t.outer_product(t))
        for k in range(N - 1):
            l = self.xrel[pb + k + 1] - self.xrel[pb + k]
            ln = l.norm()
            u = l / ln
            g = ti.max(0.0, 1.0 - self.cfg.l0 / ln)
            Ks = dt * self.cfg.k_s * ((1.0 - g) * u.outer_product(u) + g * I2)
            self._addd(base, k, Ks)
            self._addd(base, k + 1, Ks)
            self._addb(base, k + 1, k, -Ks)
        ka = dt * self.cfg.k_a
        for j in range(N - 2):
            l1 = self.xrel[pb + j + 1] - self.xrel[pb + j]
            l2 = self.xrel[pb + j + 2] - self.xrel[pb + j + 1]
            gA = _perp(l1) / l1.dot(l1)           # d theta / d x_j = perp(l1) / |l1|^2
            gC = _perp(l2) / l2.dot(l2)
            gB = -(gA + gC)
            self._addd(base, j, ka * gA.outer_product(gA))
            self._addd(base, j + 1, ka * gB.outer_product(gB))
            self._addd(base, j + 2, ka * gC.outer_product(gC))
            self._addb(base, j + 1, j, ka * gB.outer_product(gA))
            self._addb(base, j + 2, j, ka * gC.outer_product(gA))
            self._addb(base, j + 2, j + 1, ka * gC.outer_product(gB))
        if ti.static(self.contacts != "explicit"):
            kc = dt * self.cfg.k_c
            for k in range(N - 1):
                s = c * (N - 1) + k
                for q in range(self.ct_n[s]):
                    w4 = self.ct_w[s, q]
                    P = w4[0]
                    nv = ti.Vector([w4[2], w4[3]])
                    nn = kc * nv.outer_product(nv)
                    self._addd(base, k, (1.0 - P) * (1.0 - P) * nn)
                    self._addd(base, k + 1, P * P * nn)
                    self._addb(base, k + 1, k, (1.0 - P) * P * nn)
        # band Cholesky, unrolled at compile time (one copy in the program): ~15 % faster steps than dynamic loops
        for i in ti.static(range(n2)):
            for j in ti.static(range(max(0, i - BW + 1), i + 1)):
                acc = self.Lf[base + i, i - j]
                for k in ti.static(range(max(0, i - BW + 1), j)):
                    acc -= self.Lf[base + i, i - k] * self.Lf[base + j, j - k]
                if ti.static(i == j):
                    d = ti.sqrt(ti.max(acc, 1e-30))
                    self.Lf[base + i, 0] = d
                    self.Lf[base + i, BW] = 1.0 / d
                else:
                    self.Lf[base + i, i - j] = acc * self.Lf[base + j, BW]

    @ti.func
    def _solve(self, c, src: ti.template(), dst: ti.template()):
        """dst = M^-1 src on cell c's dofs (M = L L^T banded); src may be dst."""
        n2 = ti.static(self.n2)
        BW = ti.static(self.BW)
        base = c * n2
        for i in range(n2):
            acc = src[base + i]
            for k in range(ti.max(0, i - BW + 1), i):
                acc -= self.Lf[base + i, i - k] * dst[base + k]
            dst[base + i] = acc * self.Lf[base + i, BW]
        for ii in range(n2):
            i = n2 - 1 - ii
            acc = dst[base + i]
            for k in range(i + 1, ti.min(n2, i + BW)):
                acc -= self.Lf[base + k, k - i] * dst[base + k]
            dst[base + i] = acc * self.Lf[base + i, BW]

    @ti.func
    def _apply(self, c, y: ti.template(), out: ti.template(), dt):
        """out = A y on cell c's rows: M y (= L L^T y, the cell's own block) plus the contact coupling to other
        segments, -dt k_c J_s^T n (n . J_t y_t) for each stored contact (s, t) of the cell's segments."""
        N = ti.static(self.cfg.N)
        n2 = ti.static(self.n2)
        BW = ti.static(self.BW)
        base = c * n2
        for i in range(n2):
            acc = ti.cast(0.0, self.fdt)
            for k in range(i, ti.min(n2, i + BW)):
                acc += self.Lf[base + k, k - i] * y[base + k]
            self.tmp[base + i] = acc
        for i in range(n2):
            acc = ti.cast(0.0, self.fdt)
            for k in range(ti.max(0, i - BW + 1), i + 1):
                acc += self.Lf[base + i, i - k] * self.tmp[base + k]
            out[base + i] = acc
        kc = dt * self.cfg.k_c
        for k in range(N - 1):
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
                wt = nv[0] * ((1.0 - Q) * y[2 * pc] + Q * y[2 * pd]) + \
                    nv[1] * ((1.0 - Q) * y[2 * pc + 1] + Q * y[2 * pd + 1])
                oa += (1.0 - P) * wt * nv
                ob += P * wt * nv
            i = base + 2 * k
            out[i] = out[i] - kc * oa[0]
            out[i + 1] = out[i + 1] - kc * oa[1]
            out[i + 2] = out[i + 2] - kc * ob[0]
            out[i + 3] = out[i + 3] - kc * ob[1]

    @ti.func
    def _dot(self, c, a: ti.template(), b: ti.template()):
        base = c * self.n2
        acc = ti.cast(0.0, ti.f64)
        for i in range(self.n2):
            acc += ti.cast(a[base + i] * b[base + i], ti.f64)
        return acc

    @ti.func
    def _load_cell(self, c):
        """Forces at x_n (docs/model.md terms 1-6) into rhs, tangents and chain offsets into tan / xrel."""
        N = ti.static(self.cfg.N)
        x0, X, F, T, Fi = self._cell_forces(c)
        for k in ti.static(range(N)):
            p = c * N + k
            f = ti.Vector([F[k, 0], F[k, 1]])
            t = ti.Vector([T[k, 0], T[k, 1]])
            self.rhs[2 * p] = f[0]
            self.rhs[2 * p + 1] = f[1]
            self.tan[p] = t
            self.xrel[p] = ti.Vector([X[k, 0], X[k, 1]])

    # ------------------------------------------------------------------ end of step (shared by the modes)
    @ti.func
    def _advance_cell(self, c, dt):
        """x_n+1 = x_n + dt v for cell c, wrap, skin flag, slime claim, reversal clock (as the explicit step)."""
        N = ti.static(self.cfg.N)
        moved = 0
        for k in range(N):
            p = c * N + k
            v = ti.Vector([self.vel[2 * p], self.vel[2 * p + 1]])
            moved |= self._store_position(p, self.x[p] + ti.cast(v * dt, self.pdt))
        self._finish_cell(c, moved)

    @ti.func
    def _slime_pass(self, gated: ti.template()):
        if ti.static(self.cfg.slime):
            ti.loop_config(serialize=self.serial)
            for c in range(self.cfg.n_cells):
                if not gated or self.cgi[0] == 1:
                    self._slime_write(c)
                    if ti.static(self.cfg.reversals):
                        self._reversal_clock(c)

    # ------------------------------------------------------------------ kernels
    @ti.kernel
    def _imex_begin(self, dt: ti.f64):
        """Forces, per-cell assembly and factorisation. Without coupled contacts the per-cell solve is the whole
        step; with them, the CG start: r = F - A v_prev, u = M^-1 r, w = A u (v_prev: last step's velocities)."""
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
                self._load_cell(c)
                self._factor(c, dtf)
                self._solve(c, self.rhs, self.vel)
                self._advance_cell(c, dt)
            self._slime_pass(False)
            ti.loop_config(serialize=True)
            for _ in range(1):
                self.cgi[3] += 1
        else:
            ti.loop_config(serialize=self.serial)
            for b in range(self.nblk):
                g = ti.cast(0.0, ti.f64)
                gb = ti.cast(0.0, ti.f64)
                for c in range(b * bs, ti.min((b + 1) * bs, C)):
                    self._load_cell(c)
                    self._factor(c, dtf)
                    base = c * self.n2
                    nc = 0
                    for k in range(self.cfg.N - 1):
                        nc += self.ct_n[c * (self.cfg.N - 1) + k]
                    if nc == 0:
                        # no contacts: the cell's block is the whole system for it; solve directly, leave the CG
                        self.active[c] = 0
                        self._solve(c, self.rhs, self.vel)
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
                        self._solve(c, self.cg_r, self.cg_u)
                        g += self._dot(c, self.cg_r, self.cg_u)
                        self._solve(c, self.rhs, self.cg_w)          # w as scratch: F . M^-1 F
                        gb += self._dot(c, self.rhs, self.cg_w)
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
                if gam <= self.tol * self.tol * self.cgs[2] or dlt <= 0.0:
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
                    if self.active[c]:
                        self._apply(c, self.cg_u, self.cg_w, dtf)
                        d += self._dot(c, self.cg_u, self.cg_w)
            self.part[b, 1] = d

    @ti.kernel
    def _imex_iterate(self, dt: ti.f64):
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
                        self._solve(c, self.cg_r, self.cg_u)
                        g += self._dot(c, self.cg_r, self.cg_u)
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
        self._finish(dt)

    @ti.func
    def _finish(self, dt):
        ti.loop_config(serialize=self.serial)
        for c in range(self.cfg.n_cells):
            if self.cgi[0] == 1:
                self._advance_cell(c, dt)
                base = c * self.n2
                for i in range(self.n2):
                    self.vprev[base + i] = self.vel[base + i]
        self._slime_pass(True)
        ti.loop_config(serialize=True)
        for _ in range(1):
            if self.cgi[0] == 1:
                self.cgi[0] = 2

    @ti.kernel
    def _imex_finish(self, dt: ti.f64):
        ti.loop_config(serialize=True)
        for _ in range(1):
            self.cgi[0] = 1
        self._finish(dt)

    def _step(self, dt):
        """One linearly implicit step (module docstring). Replaces the explicit kernel; run() drives it. Returns the
        neighbour-list flag (a particle moved past half the skin), as the explicit kernel does."""
        self._imex_begin(dt)
        if self.coupled:
            for _ in range(math.ceil(self.max_iter / self.iters_per_launch) + 1):
                self._imex_iterate(dt)
                if self.cgi[0] == 2:
                    break
            else:
                self._imex_finish(dt)
        return self.flags[1]
