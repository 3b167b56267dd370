"""Term 5, short-range head-to-tail guiding (docs/model.md "Force terms"), and the head-to-tail interaction that
suppresses reversals (term 7).

A follower's head within d_g of a leader's tail (gap g = distance - W, 0 < g < d_g) is pulled toward it with
min(k_g g, F_max). Kinds: passive (only the component normal to the head's direction: the head turns, the engine
is not helped), active (the whole pull on the head), adhesion (active, and the reaction on the leader's tail).
Distance: 'segments' (closest points of the head and tail segments) or 'particles' (head particle to tail
particle). The unit exists when guiding is on or reversals are suppressed; its fields are allocated per use:
g_head (any guiding), g_tail (adhesion), interacting (suppression).
"""

import taichi as ti

from ..state import closest_points, perp  # noqa: F401  (closest_points: tested here)
from .base import Term


@ti.data_oriented
class HeadToTail(Term):
    name = "head_to_tail"

    def __init__(self, scene, state, neighbours, builder):
        self.state, self.nl = state, neighbours
        self.kind = scene.guiding                         # none | passive | active | adhesion
        self.suppression = scene.suppression
        self.N, self.W = scene.N, scene.width
        self.k_g, self.f_max, self.d_g = scene.k_g, scene.guiding_f_max, scene.guiding_range
        self.particles = scene.guiding_by_particles
        self.guide_self = scene.guiding_self
        self.pull_shared = scene.guiding_pull_shared              # docs/model.md "Head-to-tail guiding"
        self.reaction_shared = scene.adhesion_reaction_shared
        self.head_only = scene.suppression_head_only
        C = state.n_cells
        self.g_head = state.vec(builder, C, state.fdt) if self.kind != "none" else None
        self.g_tail = state.vec(builder, C, state.fdt) if self.kind == "adhesion" else None
        # per cell, one flag per end (head and tail segments write their own: no atomics, no clearing pass)
        self.interacting = state.vec(builder, C, ti.i32) if self.suppression else None
        # 1 + the cell whose tail this cell's head follows (nearest, gap below d_g), 0: none; read by the event log
        self.leader = state.scalar(builder, C, ti.i32)

    def hooks(self) -> set:
        # with suppression alone the head-to-tail pass only flags interactions: no force on the cell
        return super().hooks() - ({"add_cell_forces"} if self.kind == "none" else set())

    @ti.func
    def pair(self, follower_seg, leader_seg):
        """Pull on the follower's head particle toward the leader's tail, and the gap g (force zero outside
        0 < g < d_g)."""
        st = self.state
        N = ti.static(self.N)
        cj = follower_seg // (N - 1)
        cl = leader_seg // (N - 1)
        hj = cj * N + (0 if st.ke[cj] > 0 else N - 1)          # follower head particle
        tl = cl * N + (N - 1 if st.ke[cl] > 0 else 0)          # leader tail particle
        xh = st.x[hj]
        sep = ti.Vector([0.0, 0.0], dt=st.fdt)
        if ti.static(self.particles):
            sep = ti.cast(st.mi(st.x[tl] - xh), st.fdt)
        else:
            a, b = st.seg_ends(follower_seg)
            c_, d_ = st.seg_ends(leader_seg)
            pa = ti.cast(st.mi(st.x[a] - xh), st.fdt)
            pb = ti.cast(st.mi(st.x[b] - xh), st.fdt)
            pc = ti.cast(st.mi(st.x[c_] - xh), st.fdt)
            pd = pc + ti.cast(st.mi(st.x[d_] - st.x[c_]), st.fdt)
            _, _, c1, c2 = closest_points(pa, pb, pc, pd)
            sep = c2 - c1
        d = sep.norm()
        g = d - self.W
        f = ti.Vector([0.0, 0.0], dt=st.fdt)
        if g > 0.0 and g < self.d_g:
            f = ti.min(self.k_g * g, self.f_max) * sep / d
        return f, g

    @ti.func
    def pair_pass(self, s):
        """The head segment gathers its cell's guiding pull, the tail segment the adhesion reaction, each over its
        cell end's guiding list (neighbours.py); both write their end's interaction flag (reversal suppression)."""
        st = self.state
        nl = self.nl
        N = ti.static(self.N)
        c = s // (N - 1)
        is_head = s == st.head_seg(c)
        is_tail = s == st.tail_seg(c)
        if is_head or is_tail:
            end = 0 if s % (N - 1) == 0 else 1
            row = 2 * c + end
            gh = ti.Vector([0.0, 0.0], dt=st.fdt)
            gt = ti.Vector([0.0, 0.0], dt=st.fdt)
            inter = 0
            lead = 0
            best = ti.cast(self.d_g, st.fdt)
            # the cell's own tail segment is not listed for its head segment when they are adjacent (N=3)
            for q in range(nl.guide_n[row]):
                t = nl.guide[row, q]
                ct = t // (N - 1)
                if ti.static(not self.guide_self):
                    if ct == c:
                        continue
                if is_head and t == st.tail_seg(ct):
                    f, g = self.pair(s, t)
                    gh += f
                    if g < self.d_g:
                        inter = 1
                    if g < best or (g == best and lead > 0 and ct + 1 < lead):
                        best = g
                        lead = ct + 1
                if is_tail and t == st.head_seg(ct):
                    f, g = self.pair(t, s)
                    gt -= f
                    if g < self.d_g:
                        inter = 1
            if is_head:
                self.leader[c] = lead
            if ti.static(self.kind != "none"):
                if is_head:
                    self.g_head[c] = gh
            if ti.static(self.kind == "adhesion"):
                if is_tail:
                    self.g_tail[c] = gt
            if ti.static(self.suppression):
                self.interacting[c][end] = inter

    @ti.func
    def interacts(self, c):
        """Cell c's head or tail is in a head-to-tail interaction (gap below d_g, overlap included); with
        reversals.suppression_contacts = "head", only its head (the follower's end)."""
        v = self.interacting[c]
        out = v[0] != 0 or v[1] != 0
        if ti.static(self.head_only):
            out = v[0 if self.state.ke[c] > 0 else 1] != 0      # the head segment's end (State.head_seg)
        return out

    @ti.func
    def push_end(self, F, p, g, shared: ti.template()):
        """g on end particle p, or half on p and half on the other particle of its end segment."""
        N = ti.static(self.N)
        w = 0.5 if ti.static(shared) else 1.0
        F[p, 0] += w * g[0]
        F[p, 1] += w * g[1]
        if ti.static(shared):
            q = 1 if p == 0 else N - 2
            F[q, 0] += w * g[0]
            F[q, 1] += w * g[1]
        return F

    @ti.func
    def add_cell_forces(self, c, T, F):
        """The gathered pull on cell c's head (passive: its component normal to the head's direction) and, with
        adhesion, the reaction on its tail: each on the end particle, or shared by the end segment's two particles
        (guiding.pull_on, guiding.reaction_on)."""
        if ti.static(self.kind != "none"):
            st = self.state
            N = ti.static(self.N)
            head = 0 if st.ke[c] > 0 else N - 1
            tail = N - 1 - head
            g = self.g_head[c]
            if ti.static(self.kind == "passive"):
                nh = perp(ti.Vector([T[head, 0], T[head, 1]]))
                g = g.dot(nh) * nh
            F = self.push_end(F, head, g, ti.static(self.pull_shared))
            if ti.static(self.kind == "adhesion"):
                F = self.push_end(F, tail, self.g_tail[c], ti.static(self.reaction_shared))
        return F
