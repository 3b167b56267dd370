"""Term 4, contacts (docs/model.md "Contacts"): every sample point of a cell pushed out of every other cell's chain.

The law. Each cell is sampled along its axis every l0 / 2: its particles (nodes) and its segment midpoints. Every
sample point p is pressed out of every other cell's chain B:
    E = sum over samples p and other chains B of w_p k_c / 2 (W - D(p, B))^2   for D < W,
D the distance from p to the polyline B (its nearest segment). w_p = 1/4, so two parallel cells overlapping by W - d
feel k_c (W - d) per l0 of overlap length (both cells' samples count); the two poles carry w = 1/2, so a pole
pressing on another cell's side feels at least half the paper's point contact k_c (W - d).
Why samples against polylines and not segment pairs: a segment-pair law counts a contact at a shared node twice
and gives a washboard when a cell slides along a straight neighbour, and any rule that hands node-clamped contacts
from one segment to its neighbour loses them (side-by-side cells kept 1 of 9 contacts at a tilt of 0.003 deg). A
point's distance to a straight polyline does not change when it slides along it (no tangential force), it is one
number however many segments meet at the nearest point (a node contact counts once), and the energy is continuous.
With nodes alone the force on two side-by-side cells swung by 17 % with their stagger; the midpoints bring it within
10 % (measured: tests/test_contacts.py sweeps tilt and stagger).
"Nearest segment" is decided locally: p against segment t counts when t is strictly nearer than t - 1 and at least
as near as t + 1. Every distance of one sample is computed in that sample's frame by one function, so the force on
the sample (gathered by its own segment) and the reaction (gathered by t) come from identical numbers.

Determinism: a contact is evaluated from both sides and each segment gathers its own forces, over a sorted
neighbour list, so sums do not depend on thread scheduling. Here too: the energy (`sample_energy`, and the numpy
reference taichimyxo.geometry.contact_energy), the per-cell force (`add_cell_forces`) and, for the linearly implicit
step, the contact stiffness (`add_stiffness`, `add_coupling`) from the contacts each segment records.
"""

import taichi as ti

from ..geometry import contact_energy as energy  # noqa: F401  (the numpy reference energy, re-exported)
from ..state import perp


@ti.data_oriented
class Contacts:
    name = "contacts"
    CONTACT_WEIGHT = 0.25
    POLE_WEIGHT = 0.5
    MAX_CONTACTS = 16     # recorded contacts per segment (implicit step); more stay in the force, not in K

    def __init__(self, scene, state, neighbours, fb, record: bool = False):
        self.state, self.nl = state, neighbours
        self.N, self.W, self.k_c = scene.N, scene.width, scene.k_c
        S = state.n_s
        self.fa = state.vec(fb, S, state.fdt)        # contact force on a segment's first particle
        self.fb = state.vec(fb, S, state.fdt)        # ... and on its second particle
        self.record = record
        if record:
            # each segment's view of its contacts, for the Jacobian: (P on s, Q on t, n_x, n_y), n from t to s
            self.ct_n = state.scalar(fb, S, ti.i32)
            self.ct_t = ti.field(ti.i32)
            self.ct_w = ti.Vector.field(4, dtype=state.fdt)
            fb.dense(ti.ij, (S, self.MAX_CONTACTS)).place(self.ct_t, self.ct_w)
            self.overflow = state.scalar(fb, 1, ti.i32)
        else:
            self.ct_n = self.ct_t = self.ct_w = self.overflow = None

    # ------------------------------------------------------------------ the law
    @ti.func
    def sample(self, s, j):
        """Sample j of segment s (0: first particle, 1: midpoint, 2: second particle): (position in position
        precision, index along the cell in half-segments, contact weight)."""
        st = self.state
        N = ti.static(self.N)
        a, b = st.seg_ends(s)
        x = st.x[a]
        if j == 1:
            x = x + 0.5 * st.mi(st.x[b] - x)
        elif j == 2:
            x = st.x[b]
        h = 2 * (s % (N - 1)) + j
        w = ti.cast(self.CONTACT_WEIGHT, st.fdt)          # a Taichi variable: a Python float would not branch
        if h == 0 or h == 2 * (N - 1):
            w = ti.cast(self.POLE_WEIGHT, st.fdt)
        return x, h, w

    @ti.func
    def sample_eligible(self, c, h, t):
        """Sample h (half-segments along cell c) may touch segment t: another cell's segment, or one of its own cell's
        segments at least 1.5 segments away along the cell (so a bend between neighbours is the bending spring's
        business, while a folded cell, a hairpin, still pushes itself apart)."""
        N = ti.static(self.N)
        ok = True
        if c == t // (N - 1):
            kt = t % (N - 1)
            ok = h - (2 * kt + 2) >= 3 or 2 * kt - h >= 3
        return ok

    @ti.func
    def point_seg(self, xp, t):
        """Point xp against segment t in xp's frame (force precision): (u on t, d, closest point of t - xp)."""
        st = self.state
        a, b = st.seg_ends(t)
        e0 = ti.cast(st.mi(st.x[a] - xp), st.fdt)
        e = ti.cast(st.mi(st.x[b] - st.x[a]), st.fdt)
        ee = e.dot(e)
        u = ti.cast(0.0, st.fdt)
        if ee > 1e-12:
            u = ti.math.clamp(-e0.dot(e) / ee, 0.0, 1.0)
        c = e0 + u * e
        return u, c.norm(), c

    @ti.func
    def sample_contact(self, s, j, t):
        """Contact of sample j of segment s with segment t (the rule above): (accepted, u on t, force on the sample,
        its unit direction n, the sample's weight w). The reaction on t is -force, shared (1 - u, u) by t's
        particles."""
        st = self.state
        N = ti.static(self.N)
        ok = False
        u = ti.cast(0.0, st.fdt)
        f = ti.Vector([0.0, 0.0], dt=st.fdt)
        n = ti.Vector([0.0, 0.0], dt=st.fdt)
        c = s // (N - 1)
        xp, h, w = self.sample(s, j)
        if self.sample_eligible(c, h, t):
            u, dist, cp = self.point_seg(xp, t)
            if dist < self.W:
                ok = True
                kt = t % (N - 1)
                if kt > 0 and self.sample_eligible(c, h, t - 1):
                    _, dprev, _ = self.point_seg(xp, t - 1)
                    if dprev <= dist:
                        ok = False
                if ok and kt < N - 2 and self.sample_eligible(c, h, t + 1):
                    _, dnext, _ = self.point_seg(xp, t + 1)
                    if dnext < dist:
                        ok = False
                if ok:
                    if dist > 1e-9:
                        n = -cp / dist
                    else:
                        # the sample lies on the segment: push it across t, the side fixed by the indices
                        a, b = st.seg_ends(t)
                        e = ti.cast(st.mi(st.x[b] - st.x[a]), st.fdt)
                        ln = e.norm()
                        n = ti.Vector([1.0, 0.0], dt=st.fdt)
                        if ln > 1e-12:
                            n = perp(e / ln)
                        if s < t:
                            n = -n
                    f = w * self.k_c * (self.W - dist) * n
        return ok, u, f, n, w

    @ti.func
    def within_reach(self, s, t):
        """Segments s and t can be in contact: their midpoints are closer than half their lengths plus W. Most list
        partners (about 33 per segment at area fraction 1) are not, and are skipped before any sample is tested;
        skipping them changes no sum, since they contribute nothing."""
        # in a fixed order (the same numbers whichever segment asks) and with a margin far above rounding, so a
        # contact is never skipped from one side only
        st = self.state
        a, b = st.seg_ends(ti.min(s, t))
        c_, d_ = st.seg_ends(ti.max(s, t))
        es = ti.cast(st.mi(st.x[b] - st.x[a]), st.fdt)
        et = ti.cast(st.mi(st.x[d_] - st.x[c_]), st.fdt)
        m = ti.cast(st.mi(st.x[c_] - st.x[a]), st.fdt) + 0.5 * (et - es)
        reach = 0.5 * (es.norm() + et.norm()) + 1.001 * self.W
        return m.dot(m) < reach * reach

    @ti.func
    def sample_energy(self, s, j, t):
        """Contact energy of sample j of segment s with segment t (0 if not in contact), pN·µm, f64."""
        ok, u, f, n, w = self.sample_contact(s, j, t)
        e = ti.cast(0.0, ti.f64)
        if ok:
            fn = ti.cast(f.norm(), ti.f64)
            e = 0.5 * fn * fn / (w * self.k_c)          # w k_c (W - d)^2 / 2 with |f| = w k_c (W - d)
        return e

    # ------------------------------------------------------------------ forces
    @ti.func
    def gather_segment(self, s):
        """Contact forces onto segment s's two particles: the forces on its own samples, and the reactions of other
        cells' samples pressing on it (shared by the lever rule)."""
        st = self.state
        nl = self.nl
        N = ti.static(self.N)
        fa = ti.Vector([0.0, 0.0], dt=st.fdt)
        fb = ti.Vector([0.0, 0.0], dt=st.fdt)
        nc = 0
        s_last = s % (N - 1) == N - 2
        for q in range(nl.nbr_n[s]):
            t = nl.nbr[s, q]
            if not self.within_reach(s, t):
                continue
            t_last = t % (N - 1) == N - 2
            # side 0: this segment's own samples pressed by t (its second particle belongs to the next segment,
            # except at the cell's end); side 1: t's samples pressing on this segment. The sides are a runtime loop
            # and the three samples unrolled: the contact code is compiled three times, not six (the step took 15 s
            # to compile fully unrolled, 5 s before the sample law), and within a side the other segment's loads
            # are shared by the three samples.
            for side in range(2):
                p_seg, o_seg, p_last = s, t, s_last
                if side == 1:
                    p_seg, o_seg, p_last = t, s, t_last
                for j in ti.static(range(3)):
                    if ti.static(j < 2) or p_last:
                        ok, u, f, n, w = self.sample_contact(p_seg, j, o_seg)
                        if ok:
                            P = 0.5 * j                # the sample's lever arm on its own segment
                            if side == 0:
                                fa += (1.0 - P) * f
                                fb += P * f
                                self._record(s, nc, t, P, u, ti.sqrt(w) * n)
                            else:
                                fa -= (1.0 - u) * f
                                fb -= u * f
                                self._record(s, nc, t, u, P, -ti.sqrt(w) * n)
                            nc += 1
        if ti.static(self.record):
            self.ct_n[s] = ti.min(nc, self.MAX_CONTACTS)
        self.fa[s] = fa
        self.fb[s] = fb

    @ti.func
    def _record(self, s, i, t, P, Q, gn):
        """The i-th contact segment s gathers with t, for the implicit step's Jacobian: lever arms P on s and Q on t,
        gn the unit separation from t's side to s's side times sqrt(w) (the contact's stiffness is k_c gn gn^T)."""
        if ti.static(self.record):
            if i < self.MAX_CONTACTS:
                self.ct_t[s, i] = t
                self.ct_w[s, i] = ti.Vector([P, Q, gn[0], gn[1]], dt=self.state.fdt)
            else:
                ti.atomic_add(self.overflow[0], 1)

    @ti.func
    def add_cell_forces(self, c, T, F):
        """F (N x 2) of cell c += the contact forces its segments gathered."""
        N = ti.static(self.N)
        for k in ti.static(range(N)):
            f = ti.Vector([F[k, 0], F[k, 1]])
            if ti.static(k > 0):
                f += self.fb[c * (N - 1) + k - 1]
            if ti.static(k < N - 1):
                f += self.fa[c * (N - 1) + k]
            F[k, 0] = f[0]
            F[k, 1] = f[1]
        return F

    def per_particle(self):
        """(n_cells, N, 2) float64 contact force on each particle, pN (host side, after a force evaluation)."""
        import numpy as np
        st = self.state
        sh = (st.n_cells, st.N - 1, 2)
        out = np.zeros((st.n_cells, st.N, 2))
        out[:, :-1] += self.fa.to_numpy().astype(np.float64).reshape(sh)
        out[:, 1:] += self.fb.to_numpy().astype(np.float64).reshape(sh)
        return out

    # ------------------------------------------------------------------ stiffness, for the linearly implicit step
    @ti.func
    def add_stiffness(self, band: ti.template(), c, dt):
        """Cell c's own share of dt k_c J^T gn gn^T J for each recorded contact (lever arms held fixed; the
        tangential geometric term is dropped)."""
        N = ti.static(self.N)
        kc = dt * self.k_c
        for k in range(N - 1):
            s = c * (N - 1) + k
            for q in range(self.ct_n[s]):
                w4 = self.ct_w[s, q]
                P = w4[0]
                nv = ti.Vector([w4[2], w4[3]])
                nn = kc * nv.outer_product(nv)
                band.add_diag(c, k, (1.0 - P) * (1.0 - P) * nn)
                band.add_diag(c, k + 1, P * P * nn)
                band.add_lower(c, k + 1, k, (1.0 - P) * P * nn)

    @ti.func
    def add_coupling(self, c, y: ti.template(), out: ti.template(), dt):
        """out -= the contact coupling of cell c's segments to the segments they touch: dt k_c J_s^T n (n . J_t y_t)
        per recorded contact (y and out over degrees of freedom, 2 p + axis)."""
        st = self.state
        N = ti.static(self.N)
        kc = dt * self.k_c
        base = c * 2 * N
        for k in range(N - 1):
            s = c * (N - 1) + k
            oa = ti.Vector([0.0, 0.0], dt=st.fdt)
            ob = ti.Vector([0.0, 0.0], dt=st.fdt)
            for q in range(self.ct_n[s]):
                t = self.ct_t[s, q]
                w4 = self.ct_w[s, q]
                P = w4[0]
                Q = w4[1]
                nv = ti.Vector([w4[2], w4[3]])
                pc, pd = st.seg_ends(t)
                wt = nv[0] * ((1.0 - Q) * y[2 * pc] + Q * y[2 * pd]) + \
                    nv[1] * ((1.0 - Q) * y[2 * pc + 1] + Q * y[2 * pd + 1])
                oa += (1.0 - P) * wt * nv
                ob += P * wt * nv
            i = base + 2 * k
            out[i] = out[i] - kc * oa[0]
            out[i + 1] = out[i + 1] - kc * oa[1]
            out[i + 2] = out[i + 2] - kc * ob[0]
            out[i + 3] = out[i + 3] - kc * ob[1]
