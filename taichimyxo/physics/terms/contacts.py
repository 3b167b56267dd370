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
as near as t + 1. Every distance of one sample is computed in that sample's frame (positions relative to its own
segment's first particle, each point computed once from its own position: `chain_points`), so the comparisons of
t with t - 1 and t + 1 see identical numbers whichever pair asks, and a node contact counts exactly once.

Cost and determinism. The contact list (neighbours.py) holds pairs of segments within W + skin by true distance;
each pair (s, t > s) is evaluated once, by s, after a closest-points test of the two segments (no sample is nearer
than that), and both sides' results go into s's row of `pair_f`; each segment then gathers its pairs' results in
list order (its own rows for t > s, t's row at `rev` for t < s). No atomics, sorted lists: sums do not depend on
thread scheduling (1 and 2 threads bit-identical). The implicit step needs each segment's own record of its contacts
for the Jacobian, so with `record` each segment gathers from both sides (`gather_segment`). Here too: the energy
(`sample_energy`, and the numpy reference taichimyxo.physics.geometry.contact_energy), the per-cell force
(`add_cell_forces`) and the contact stiffness (`add_stiffness`, `add_coupling`).
"""

import taichi as ti

from ..geometry import contact_energy as energy  # noqa: F401  (the numpy reference energy, re-exported)
from ..state import closest_points, perp
from .base import Term


@ti.data_oriented
class Contacts(Term):
    name = "contacts"
    CONTACT_WEIGHT = 0.25
    POLE_WEIGHT = 0.5
    MAX_CONTACTS = 16     # recorded contacts per segment (implicit step); more stay in the force, not in K

    def __init__(self, scene, state, neighbours, builder, record: bool = False):
        self.state, self.nl = state, neighbours
        self.N, self.W, self.k_c = scene.N, scene.width, scene.k_c
        S = state.n_s
        self.record = record
        if not record:
            # each pair once: the lower segment s of a listed pair (s, t) evaluates both sides into its slot of s's
            # row, (forces on s's two particles, forces on t's two); both segments gather them in list order
            self.pair_f = ti.Vector.field(8, dtype=state.fdt)
            builder.dense(ti.ij, (S, neighbours.max_nbrs)).place(self.pair_f)
            self.fa = self.fb = self.ct_n = self.ct_t = self.ct_w = self.overflow = None
        else:
            # the implicit step records each segment's view of its contacts, so each segment gathers its own
            self.pair_f = None
            self.fa = state.vec(builder, S, state.fdt)    # contact force on a segment's first particle
            self.fb = state.vec(builder, S, state.fdt)    # ... and on its second particle
            # each segment's view of its contacts, for the Jacobian: (P on s, Q on t, n_x, n_y), n from t to s
            self.ct_n = state.scalar(builder, S, ti.i32)
            self.ct_t = ti.field(ti.i32)
            self.ct_w = ti.Vector.field(4, dtype=state.fdt)
            builder.dense(ti.ij, (S, self.MAX_CONTACTS)).place(self.ct_t, self.ct_w)
            self.overflow = state.scalar(builder, 1, ti.i32)

    # ------------------------------------------------------------------ the law, in a pair's local frame
    @ti.func
    def chain_points(self, t, o):
        """Segment t and its chain neighbours relative to o, in force precision: (A, B) its particles, Ap the one before
        A (A at the cell's first end), Bn the one after B (B at the last). Each point directly from its own position
        and o, so a particle shared by t and t + 1 has the same numbers whichever segment asks and a sample nearest to
        a node counts once (offsets chained from A lost a quarter of the force of two cells side by side at 3e-5 rad
        in mixed precision)."""
        xp, xa, xb, xn = self.chain_positions(t)
        return self.rel(xa, o), self.rel(xb, o), self.rel(xp, o), self.rel(xn, o)

    @ti.func
    def chain_positions(self, t):
        """Positions of segment t's chain points (Ap, A, B, Bn of chain_points)."""
        st = self.state
        a, b = st.seg_ends(t)
        kt = t % ti.static(self.N - 1)
        pa, pb = a, b
        if kt > 0:
            pa = a - 1
        if kt < ti.static(self.N - 2):
            pb = b + 1
        return st.x[pa], st.x[a], st.x[b], st.x[pb]

    @ti.func
    def rel(self, y, o):
        """y relative to o (minimum image), in force precision: the one formula every chain point is computed by."""
        return ti.cast(self.state.mi(y - o), self.state.fdt)

    @ti.func
    def apart(self, h, k):
        """Sample h (half-segments along its cell) may touch its own cell's segment k: at least 1.5 segments away
        along the cell (so a bend between neighbours is the bending spring's business, while a folded cell, a
        hairpin, still pushes itself apart). Another cell's segments are always eligible."""
        return h - (2 * k + 2) >= 3 or 2 * k - h >= 3

    @ti.func
    def point_seg(self, xp, A, B):
        """Point xp against the segment A-B: (u on it, distance, closest point - xp)."""
        e0 = A - xp
        e = B - A
        ee = e.dot(e)
        u = ee * 0.0                                   # typed like the inputs
        if ee > 1e-12:
            u = ti.math.clamp(-e0.dot(e) / ee, 0.0, 1.0)
        cp = e0 + u * e
        return u, cp.norm(), cp

    @ti.func
    def contact(self, s, j, P0, P1, t, A, B, Ap, Bn):
        """Sample j (0: first particle, 1: midpoint, 2: second particle) of segment s, whose particles are P0, P1,
        against segment t = A-B (chain neighbours Ap, Bn), all in one frame: (accepted, u on t, force on the sample,
        its unit direction n, the sample's weight w). The reaction on t is -force, shared (1 - u, u) by t's
        particles. The rule: the sample is within W of t, t is strictly nearer than t - 1 and at least as near as
        t + 1 (so a sample nearest to a node of t's chain counts once)."""
        st = self.state
        N = ti.static(self.N)
        ok = False
        u = ti.cast(0.0, st.fdt)
        f = ti.Vector([0.0, 0.0], dt=st.fdt)
        n = ti.Vector([0.0, 0.0], dt=st.fdt)
        c = s // (N - 1)
        h = 2 * (s % (N - 1)) + j
        kt = t % (N - 1)
        # t, t - 1 and t + 1 are one cell's segments (t - 1 tested only when kt > 0, t + 1 when kt < N - 2)
        same = c == t // (N - 1)
        ok_t = (not same) or self.apart(h, kt)
        ok_prev = (not same) or self.apart(h, kt - 1)
        ok_next = (not same) or self.apart(h, kt + 1)
        w = ti.cast(self.CONTACT_WEIGHT, st.fdt)          # a Taichi variable: a Python float would not branch
        if h == 0 or h == 2 * (N - 1):
            w = ti.cast(self.POLE_WEIGHT, st.fdt)
        xp = P0
        if j == 1:
            xp = 0.5 * (P0 + P1)
        elif j == 2:
            xp = P1
        if ok_t:
            u, dist, cp = self.point_seg(xp, A, B)
            if dist < self.W:
                ok = True
                if kt > 0 and ok_prev:
                    _, dprev, _ = self.point_seg(xp, Ap, A)
                    if dprev <= dist:
                        ok = False
                if ok and kt < N - 2 and ok_next:
                    _, dnext, _ = self.point_seg(xp, B, Bn)
                    if dnext < dist:
                        ok = False
                if ok:
                    if dist > 1e-9:
                        n = -cp / dist
                    else:
                        # the sample lies on the segment: push it across t, the side fixed by the indices
                        e = B - A
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
        """Segments s and t can be in contact: their midpoints are closer than half their lengths plus W. The list
        holds pairs within W + skin; this cheap test skips those not within W now before any sample is tested
        (skipping changes no sum: they contribute nothing)."""
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
    def side(self, p_seg, o_seg, Pp: ti.template(), Po: ti.template(), rec: ti.template(), s_rec, nc):
        """The samples of segment p_seg (chain points Pp) pressed out of segment o_seg (Po): (forces on p_seg's first
        and second particle, reactions on o_seg's, the contact count nc advanced). rec: 0 records nothing, 1 records
        for s_rec = p_seg, 2 for s_rec = o_seg (the implicit step's Jacobian)."""
        st = self.state
        N = ti.static(self.N)
        pa = ti.Vector([0.0, 0.0], dt=st.fdt)
        pb = ti.Vector([0.0, 0.0], dt=st.fdt)
        oa = ti.Vector([0.0, 0.0], dt=st.fdt)
        ob = ti.Vector([0.0, 0.0], dt=st.fdt)
        # the second particle is sampled by the next segment, but at the cell's last end by this one. A dynamic loop:
        # unrolled, the three inlined samples (x 2 sides) tripled the step kernel's compile time
        n_samples = 3 if p_seg % (N - 1) == N - 2 else 2
        for j in range(n_samples):
            ok, u, f, n, w = self.contact(p_seg, j, Pp[0], Pp[1], o_seg, Po[0], Po[1], Po[2], Po[3])
            if ok:
                P = ti.cast(0.5 * j, st.fdt)  # the sample's lever arm on its own segment
                pa += (1.0 - P) * f
                pb += P * f
                oa -= (1.0 - u) * f
                ob -= u * f
                if ti.static(rec == 1):
                    self._record(s_rec, nc, o_seg, P, u, ti.sqrt(w) * n)
                if ti.static(rec == 2):
                    self._record(s_rec, nc, p_seg, u, P, -ti.sqrt(w) * n)
                nc += 1
        return pa, pb, oa, ob, nc

    @ti.func
    def sample_frame(self, p_seg, o_seg):
        """Chain points of p_seg (whose samples are tested) and of o_seg, relative to p_seg's first particle."""
        o = self.state.x[self.state.seg_ends(p_seg)[0]]
        Ap, Bp, App, Bnp = self.chain_points(p_seg, o)
        Ao, Bo, Apo, Bno = self.chain_points(o_seg, o)
        return [Ap, Bp, App, Bnp], [Ao, Bo, Apo, Bno]

    @ti.func
    def sample_energy(self, s, j, t):
        """Contact energy of sample j of segment s with segment t (0 if not in contact), pN·µm, f64."""
        Ps, Pt = self.sample_frame(s, t)
        ok, u, f, n, w = self.contact(s, j, Ps[0], Ps[1], t, Pt[0], Pt[1], Pt[2], Pt[3])
        e = ti.cast(0.0, ti.f64)
        if ok:
            fn = ti.cast(f.norm(), ti.f64)
            e = 0.5 * fn * fn / (w * self.k_c)          # w k_c (W - d)^2 / 2 with |f| = w k_c (W - d)
        return e

    # ------------------------------------------------------------------ forces
    @ti.func
    def pair_pass(self, s):
        """Segment s's share of the pair loop: with recorded contacts (implicit step), gather its own; otherwise
        evaluate each listed pair (s, t > s) once, both sides, into s's row."""
        if ti.static(self.record):
            self.gather_segment(s)
        else:
            st = self.state
            nl = self.nl
            n = nl.nbr_n[s]
            if n > 0:                        # most segments of a sparse state have no partner: load nothing for them
                # positions loaded and points mapped once per pair, not once per side (docs/performance.md)
                xs_p, xs_a, xs_b, xs_n = self.chain_positions(s)
                zero = ti.Vector([0.0, 0.0], dt=st.fdt)
                Bs = self.rel(xs_b, xs_a)
                for q in range(n):
                    t = nl.nbr[s, q]
                    if t > s:
                        v = ti.Vector.zero(st.fdt, 8)
                        xt_p, xt_a, xt_b, xt_n = self.chain_positions(t)
                        # the segments' distance first (seg_distance's numbers: t's ends chained, a far pair cannot pass
                        # by mapping them to different images); no sample is nearer. No margin: a sample within W only
                        # by rounding (~1e-7 µm, < 1e-3 pN) goes with its whole pair: a margin would evaluate every
                        # pair of a lattice at exactly W (S11's start) in full for no force.
                        At = self.rel(xt_a, xs_a)
                        Bt = self.rel(xt_b, xt_a)                 # t's second point in t's own frame
                        _, _, c1, c2 = closest_points(zero, Bs, At, At + Bt)
                        if (c2 - c1).norm() < self.W:
                            # each sample's distances in its own frame (chain_points' numbers exactly)
                            Ts = [At, self.rel(xt_b, xs_a), self.rel(xt_p, xs_a), self.rel(xt_n, xs_a)]
                            St = [self.rel(xs_a, xt_a), self.rel(xs_b, xt_a), self.rel(xs_p, xt_a),
                                  self.rel(xs_n, xt_a)]
                            # the sides inlined: a dynamic loop would select every point at run time (slower)
                            sa, sb, ta, tb, _n = self.side(s, t, [zero, Bs], Ts, 0, s, 0)
                            pa, pb, oa, ob, _m = self.side(t, s, [zero, Bt], St, 0, s, 0)
                            v = ti.Vector([sa[0] + oa[0], sa[1] + oa[1], sb[0] + ob[0], sb[1] + ob[1],
                                           ta[0] + pa[0], ta[1] + pa[1], tb[0] + pb[0], tb[1] + pb[1]])
                        self.pair_f[s, q] = v

    @ti.func
    def segment_forces(self, s):
        """Contact forces on segment s's two particles (after the pair loop): its pairs' results, in list order."""
        st = self.state
        fa = ti.Vector([0.0, 0.0], dt=st.fdt)
        fb = ti.Vector([0.0, 0.0], dt=st.fdt)
        if ti.static(self.record):
            fa = self.fa[s]
            fb = self.fb[s]
        else:
            nl = self.nl
            for q in range(nl.nbr_n[s]):
                t = nl.nbr[s, q]
                if t > s:
                    v = self.pair_f[s, q]
                    fa += ti.Vector([v[0], v[1]])
                    fb += ti.Vector([v[2], v[3]])
                else:
                    v = self.pair_f[t, nl.rev[s, q]]
                    fa += ti.Vector([v[4], v[5]])
                    fb += ti.Vector([v[6], v[7]])
        return fa, fb

    @ti.func
    def gather_segment(self, s):
        """Implicit step: segment s gathers its contacts from both sides (its own samples pressed by t, and t's
        samples pressing on it) and records each for the Jacobian."""
        st = self.state
        nl = self.nl
        fa = ti.Vector([0.0, 0.0], dt=st.fdt)
        fb = ti.Vector([0.0, 0.0], dt=st.fdt)
        nc = 0
        for q in range(nl.nbr_n[s]):
            t = nl.nbr[s, q]
            if self.within_reach(s, t):
                Ps, Pt = self.sample_frame(s, t)
                sa, sb, _a, _b, nc = self.side(s, t, Ps, Pt, 1, s, nc)
                Pt2, Ps2 = self.sample_frame(t, s)
                _c, _d, sa2, sb2, nc = self.side(t, s, Pt2, Ps2, 2, s, nc)
                fa += sa + sa2
                fb += sb + sb2
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
        for k in range(N - 1):                  # dynamic (F indexed at run time): unrolled it cost ~3 s of compile
            fa, fb = self.segment_forces(c * (N - 1) + k)
            F[k, 0] += fa[0]
            F[k, 1] += fa[1]
            F[k + 1, 0] += fb[0]
            F[k + 1, 1] += fb[1]
        return F

    @ti.kernel
    def _segment_forces_to(self, out_a: ti.template(), out_b: ti.template()):
        ti.loop_config(**self.state.loops.items)
        for s in range(self.state.n_s):
            fa, fb = self.segment_forces(s)
            out_a[s] = ti.cast(fa, ti.f64)
            out_b[s] = ti.cast(fb, ti.f64)

    def per_particle(self):
        """(n_cells, N, 2) float64 contact force on each particle, pN (host side, after a force evaluation; output
        fields made on first use, a measurement and not part of a run's memory)."""
        import numpy as np
        st = self.state
        if getattr(self, "_out", None) is None:
            builder = ti.FieldsBuilder()
            out = [ti.Vector.field(2, dtype=ti.f64) for _ in range(2)]
            builder.dense(ti.i, st.n_s).place(*out)
            self._out = (*out, builder.finalize())
        self._segment_forces_to(self._out[0], self._out[1])
        sh = (st.n_cells, st.N - 1, 2)
        res = np.zeros((st.n_cells, st.N, 2))
        res[:, :-1] += self._out[0].to_numpy().reshape(sh)
        res[:, 1:] += self._out[1].to_numpy().reshape(sh)
        return res

    def close(self) -> None:
        if getattr(self, "_out", None) is not None:
            self._out[2].destroy()
            self._out = None

    # ------------------------------------------------------------------ stiffness, for the linearly implicit step
    @ti.func
    def add_stiffness(self, band: ti.template(), c, xrel: ti.template(), dt):
        """Cell c's own share of dt k_c J^T gn gn^T J per recorded contact (lever arms, recorded with the forces,
        held fixed, so xrel is unused; the tangential geometric term is dropped)."""
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
