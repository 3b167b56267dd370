"""The neighbour lists, built together from one cell grid, and the skin check that says when to rebuild them.

  contact list  for each segment, the segments whose closest points (minimum image) are within W + skin: every pair
                that can touch before the next rebuild. Sorted; for a partner t < s, `rev` holds where s sits in t's
                row, so a contact pair is evaluated once (by its lower segment) and gathered by both (terms/contacts).
  guiding list  only when head-to-tail guiding or reversal suppression is on: for each cell end (row 2c for the end
                segment at particle 0, 2c + 1 at particle N - 1), the other cells' end segments within
                W + d_g + skin. Head and tail swap on a reversal; both ends are listed, so the list stays valid.

Why true segment distance, not midpoint distance: a list by midpoints (radius 1.25 l0 + W + d_g + skin = 1.85 µm
for the default cell) held about 33 partners per segment at area fraction 1, while fewer than half can touch; every
step walked them all, twice. Validity: the list is rebuilt as soon as any particle has moved half the skin since the
build (`store` returns the flag inside the step), so no two points of two segments have closed in by a full skin,
whatever the speed; a pair farther apart than W + skin at the build cannot touch before the next one.

Determinism: the build counts into bins with atomics, but each row is sorted afterwards, so the lists and every sum
over them are independent of thread scheduling.

Per arch (taichimyxo/runtime/launch.py): every loop of the build is parallel over segments or bins, except the bins'
prefix sum, which runs in one thread on the CPU and as a two-level blocked scan on a GPU (`_scan_bins`); both give the
same bin_start, so the lists are the same on either shape.
"""

import taichi as ti

from ..runtime.kernel_call import direct
from ..runtime.launch import scan_block
from .state import SEGMENT_LENGTH_TOL, State, closest_points

# the grid holds segments up to 1.5 l0, the bound frames check too: a longer one (a blown-up chain) could escape
# the 3 x 3 bins searched, so the build stops the run with the invariant's message
LENGTH_BOUND = 1.0 + SEGMENT_LENGTH_TOL

# NeighbourList.flags, set in kernels and read on the host
FLAG_CONTACT_OVERFLOW = 0     # more listed segments than a row holds
FLAG_MOVED = 1                # a particle moved past half the skin: rebuild before the next force evaluation
FLAG_GUIDE_OVERFLOW = 2       # more cell ends than a guiding row holds
FLAG_LONG_SEGMENT = 3         # a segment longer than LENGTH_BOUND l0 at a build


class NeighbourOverflow(RuntimeError):
    pass


def grid_radius(l0: float, cutoff: float) -> float:
    """Two segments no longer than l_max = 1.5 l0 whose closest points are within `cutoff` have midpoints within
    l_max + cutoff: the grid's bins are at least that wide, so a 3 x 3 block of bins holds every candidate."""
    return LENGTH_BOUND * l0 + cutoff


@ti.data_oriented
class NeighbourList:
    def __init__(self, state: State, builder: ti.FieldsBuilder, W: float, skin: float, capacity: int,
                 guiding_range: float | None = None, guiding_capacity: int = 0):
        self.state = st = state
        self.W, self.skin, self.max_nbrs = W, skin, capacity
        self.contact_cutoff = W + skin
        self.guide_lists = guiding_range is not None
        self.guiding_cutoff = W + guiding_range + skin if self.guide_lists else 0.0
        self.max_guides = guiding_capacity
        self.l_max = LENGTH_BOUND * st.layout.l0
        self.radius = grid_radius(st.layout.l0, max(self.contact_cutoff, self.guiding_cutoff))
        self.nbx = max(1, int(st.Lx // self.radius))
        self.nby = max(1, int(st.Ly // self.radius))
        nb = self.nbx * self.nby
        S = st.n_s
        self.x_ref = st.vec(builder, st.n_p, st.pdt)            # positions at the last build
        self.nbr = ti.field(ti.i32)                         # contact partners, sorted
        self.rev = ti.field(ti.i32)                         # for a partner t < s: the slot of s in t's row
        builder.dense(ti.ij, (S, capacity)).place(self.nbr, self.rev)
        self.nbr_n = st.scalar(builder, S, ti.i32)
        if self.guide_lists:
            self.guide = ti.field(ti.i32)                   # per cell end: other cells' end segments, sorted
            builder.dense(ti.ij, (2 * st.n_cells, guiding_capacity)).place(self.guide)
            self.guide_n = st.scalar(builder, 2 * st.n_cells, ti.i32)
        else:
            self.guide = self.guide_n = None
        self.bin_count = st.scalar(builder, nb, ti.i32)
        self.bin_start = st.scalar(builder, nb + 1, ti.i32)
        self.bin_cursor = st.scalar(builder, nb, ti.i32)
        self.bin_items = st.scalar(builder, S, ti.i32)
        # beside each binned segment, in bin order: its midpoint and half length (force precision), so a candidate
        # beyond reach is rejected from one contiguous load before its distance is computed
        self.bin_geo = ti.Vector.field(3, dtype=st.fdt)
        builder.dense(ti.i, S).place(self.bin_geo)
        self.seg_bin = st.scalar(builder, S, ti.i32)
        if st.loops.gpu:                                    # the blocked scan's block totals (launch.py)
            self.scan_block = scan_block(nb)
            self.n_scan_blocks = (nb + self.scan_block - 1) // self.scan_block
            self.bin_block = st.scalar(builder, self.n_scan_blocks, ti.i32)
        self.flags = st.scalar(builder, 4, ti.i32)       # indexed by the FLAG_ names above
        self.rebuilds = 0
        self._launch_build = direct(self._build)          # a build's kernel call without Taichi's Python work

    @ti.func
    def seg_distance(self, s, t):
        """Distance between segments s and t (closest points, minimum image; t's second end chained from its first,
        in force precision) for a pair the grid offers, or, when their midpoints are farther apart than the grid's
        radius (l_max + the widest cutoff), the lower bound |m_s - m_t| - l_max without the closest-points test
        (either way >= a cutoff exactly when the distance is). The build calls it only for candidates that pass the
        reach test on the binned midpoints (`_reach_geometry`), which rejects most of the 3 x 3 bins' candidates
        from one contiguous load (benchmarks/results/dense_step.md)."""
        st = self.state
        a, b = st.seg_ends(s)
        c_, d_ = st.seg_ends(t)
        pb = ti.cast(st.mi(st.x[b] - st.x[a]), st.fdt)
        pc = ti.cast(st.mi(st.x[c_] - st.x[a]), st.fdt)
        pd = pc + ti.cast(st.mi(st.x[d_] - st.x[c_]), st.fdt)
        m = 0.5 * (pc + pd - pb)                       # t's midpoint relative to s's
        r = ti.static(self.radius * 1.001)              # a margin far above rounding
        d = ti.cast(0.0, st.fdt)
        if m.dot(m) > r * r:
            d = m.norm() - ti.static(self.l_max)
        else:
            _, _, c1, c2 = closest_points(pb * 0.0, pb, pc, pd)
            d = (c2 - c1).norm()
        return d

    @ti.func
    def _reach_geometry(self, s):
        """Segment s's midpoint (wrapped) and half length, in force precision: (m_x, m_y, h)."""
        st = self.state
        a, b = st.seg_ends(s)
        m = ti.cast(st.seg_mid(s), st.fdt)
        h = 0.5 * ti.cast(st.mi(st.x[b] - st.x[a]), st.fdt).norm()
        return ti.Vector([m[0], m[1], h])

    @ti.func
    def _sort_row(self, f: ti.template(), r, n):
        """Insertion sort of row r (n entries): the list, and so every force sum, is independent of scheduling."""
        for i in range(1, n):
            v = f[r, i]
            j = i - 1
            while j >= 0 and f[r, j] > v:
                f[r, j + 1] = f[r, j]
                j -= 1
            f[r, j + 1] = v

    @ti.kernel
    def _build(self) -> ti.i32:
        """The lists, and what went wrong: bit 0 a contact row overflowed, bit 1 a guiding row, bit 2 a segment was
        longer than l_max (one value read back, no flag read or written from Python)."""
        st = self.state
        N = ti.static(st.N)
        nbx, nby = ti.static(self.nbx, self.nby)
        cut_c = ti.static(self.contact_cutoff * 1.001)       # a margin far above rounding
        cut_g = ti.static(self.guiding_cutoff * 1.001)
        l_max = ti.static(self.l_max)
        self.flags[FLAG_CONTACT_OVERFLOW] = 0
        self.flags[FLAG_GUIDE_OVERFLOW] = 0
        self.flags[FLAG_LONG_SEGMENT] = 0
        ti.loop_config(**st.loops.items)
        for i in range(nbx * nby):
            self.bin_count[i] = 0
        ti.loop_config(**st.loops.items)
        for s in range(st.n_s):
            m = st.seg_mid(s)
            a, b = st.seg_ends(s)
            e = st.mi(st.x[b] - st.x[a])
            if e.dot(e) > l_max * l_max:
                self.flags[FLAG_LONG_SEGMENT] = 1
            bx = ti.min(ti.cast(m[0] / st.Lx * nbx, ti.i32), nbx - 1)
            by = ti.min(ti.cast(m[1] / st.Ly * nby, ti.i32), nby - 1)
            bn = bx * nby + by
            self.seg_bin[s] = bn
            ti.atomic_add(self.bin_count[bn], 1)
        if ti.static(st.loops.gpu):
            self._scan_bins()
        else:
            ti.loop_config(**st.loops.one_thread)
            for i in range(nbx * nby + 1):
                if i == 0:
                    self.bin_start[0] = 0
                else:
                    self.bin_start[i] = self.bin_start[i - 1] + self.bin_count[i - 1]
            ti.loop_config(**st.loops.items)
            for i in range(nbx * nby):
                self.bin_cursor[i] = self.bin_start[i]
        ti.loop_config(**st.loops.items)
        for s in range(st.n_s):
            k = ti.atomic_add(self.bin_cursor[self.seg_bin[s]], 1)
            self.bin_items[k] = s
            self.bin_geo[k] = self._reach_geometry(s)
        ti.loop_config(**st.loops.items)
        for i in range(st.n_s):
            s = st.segment_of(i)                    # the threads' shares spread over the cells (launch.py)
            cs = s // (N - 1)
            ks = s % (N - 1)
            s_end = ks == 0 or ks == N - 2
            row_g = 2 * cs + (0 if ks == 0 else 1)
            b0 = self.seg_bin[s]
            bx0 = b0 // nby
            by0 = b0 % nby
            n = 0
            ng = 0
            g_s = self._reach_geometry(s)
            # t can be within the cutoff only if its midpoint is within both half lengths plus the cutoff of s's
            # (triangle inequality); the margin is far above rounding, so the lists are those of the exact test alone
            reach_s = g_s[2] + cut_c + 1e-3
            if ti.static(self.guide_lists):
                if s_end:
                    reach_s = g_s[2] + ti.max(cut_c, cut_g) + 1e-3
            # the 3 x 3 bins around (fewer on a grid narrower than 3), as a dynamic loop: unrolled, the nine inlined
            # copies of the distance test made this kernel's compile (~7 s) longer than all of a test's run
            rx = ti.static(3 if nbx >= 3 else nbx)
            ry = ti.static(3 if nby >= 3 else nby)
            for o in range(rx * ry):
                bx = o // ry
                by = o % ry
                if ti.static(nbx >= 3):
                    bx = (bx0 + bx - 1 + nbx) % nbx
                if ti.static(nby >= 3):
                    by = (by0 + by - 1 + nby) % nby
                bb = bx * nby + by
                for q in range(self.bin_start[bb], self.bin_start[bb + 1]):
                    g_t = self.bin_geo[q]
                    dm = st.mi(ti.Vector([g_t[0] - g_s[0], g_t[1] - g_s[1]]))
                    reach = reach_s + g_t[2]
                    if dm.dot(dm) >= reach * reach:
                        continue
                    t = self.bin_items[q]
                    ct = t // (N - 1)
                    kt = t % (N - 1)
                    # a cell's own neighbouring segments are the springs' and the bending's business
                    if t != s and (ct != cs or abs(kt - ks) >= 2):
                        d = self.seg_distance(s, t)
                        if d < cut_c:
                            if n < self.max_nbrs:
                                self.nbr[s, n] = t
                            else:
                                self.flags[FLAG_CONTACT_OVERFLOW] = 1
                            n += 1
                        if ti.static(self.guide_lists):
                            if s_end and (kt == 0 or kt == N - 2) and d < cut_g:
                                if ng < self.max_guides:
                                    self.guide[row_g, ng] = t
                                else:
                                    self.flags[FLAG_GUIDE_OVERFLOW] = 1
                                ng += 1
            n = ti.min(n, self.max_nbrs)
            self.nbr_n[s] = n
            self._sort_row(self.nbr, s, n)
            if ti.static(self.guide_lists):
                if s_end:
                    ng = ti.min(ng, self.max_guides)
                    self.guide_n[row_g] = ng
                    self._sort_row(self.guide, row_g, ng)
        ti.loop_config(**st.loops.items)
        for s in range(st.n_s):
            for q in range(self.nbr_n[s]):
                t = self.nbr[s, q]
                self.rev[s, q] = -1
                if t < s:
                    for q2 in range(self.nbr_n[t]):
                        if self.nbr[t, q2] == s:
                            self.rev[s, q] = q2
        ti.loop_config(**st.loops.items)
        for p in range(st.n_p):
            self.x_ref[p] = st.x[p]
        self.flags[FLAG_MOVED] = 0
        return (self.flags[FLAG_CONTACT_OVERFLOW] + 2 * self.flags[FLAG_GUIDE_OVERFLOW]
                + 4 * self.flags[FLAG_LONG_SEGMENT])

    @ti.func
    def _scan_bins(self):
        """bin_start (exclusive prefix sum of bin_count) and bin_cursor, the gpu shape's two-level blocked scan:
        each block's total in parallel, the totals' scan in one thread, each block's own scan in parallel."""
        st = self.state
        nb = ti.static(self.nbx * self.nby)
        G = ti.static(self.scan_block)
        ti.loop_config(**st.loops.items)
        for k in range(self.n_scan_blocks):
            acc = 0
            for i in range(k * G, ti.min((k + 1) * G, nb)):
                acc += self.bin_count[i]
            self.bin_block[k] = acc
        ti.loop_config(**st.loops.one_thread)
        for _ in range(1):
            acc = 0
            for k in range(self.n_scan_blocks):
                c = self.bin_block[k]
                self.bin_block[k] = acc
                acc += c
            self.bin_start[nb] = acc
        ti.loop_config(**st.loops.items)
        for k in range(self.n_scan_blocks):
            acc = self.bin_block[k]
            for i in range(k * G, ti.min((k + 1) * G, nb)):
                self.bin_start[i] = acc
                self.bin_cursor[i] = acc
                acc += self.bin_count[i]

    def rebuild(self) -> None:
        broken = self._launch_build()
        self.rebuilds += 1
        if broken & 3:
            contacts = broken & 1
            which = ("segments within W + skin of one segment", self.max_nbrs) if contacts else \
                ("cell ends within W + d_g + skin of one cell end", self.max_guides)
            raise NeighbourOverflow(
                f"more than {which[1]} {which[0]}: cells are packed beyond area fraction 1 or blew up; set "
                f"run.max_neighbours higher or use a smaller time step")
        if broken & 4:
            raise NeighbourOverflow(
                f"segment lengths above {LENGTH_BOUND:g} l0 outside 1 +- {SEGMENT_LENGTH_TOL} l0 at a neighbour-list "
                f"build: the chain blew up; use a smaller time step")

    @ti.func
    def store(self, p, xn):
        """Wrap and store particle p's new position; 1 if it has moved past half the skin since the build (the lists
        stay valid while no two particles have closed in by more than the skin)."""
        st = self.state
        xn = st.wrap(xn)
        st.x[p] = xn
        moved = 0
        dd = st.mi(xn - self.x_ref[p])
        if dd.dot(dd) > (0.5 * self.skin) ** 2:
            moved = 1
        return moved

    @ti.func
    def flag_moved(self, moved):
        if moved:
            self.flags[FLAG_MOVED] = 1
