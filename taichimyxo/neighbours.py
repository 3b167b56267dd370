"""The neighbour list: for each segment, the segments whose midpoints are within the list radius, built from a cell
grid and sorted, and the skin check that says when to rebuild it.

Determinism: the build counts into bins with atomics, but each segment's list is sorted afterwards, so the list and
every force summed over it are independent of thread scheduling.
"""

import taichi as ti

from .state import State


class NeighbourOverflow(RuntimeError):
    pass


def list_radius(l0: float, W: float, d_g: float, skin: float) -> float:
    """Two segments no longer than l_max = 1.25 l0 whose closest points are within W + d_g have midpoints within
    l_max + W + d_g; the skin covers motion between rebuilds."""
    return 1.25 * l0 + W + d_g + skin


@ti.data_oriented
class NeighbourList:
    def __init__(self, state: State, fb: ti.FieldsBuilder, radius: float, capacity: int, skin: float):
        self.state = st = state
        self.radius, self.max_nbrs, self.skin = radius, capacity, skin
        self.nbx = max(1, int(st.Lx // radius))
        self.nby = max(1, int(st.Ly // radius))
        nb = self.nbx * self.nby
        S = st.n_s
        self.x_ref = st.vec(fb, st.n_p, st.pdt)            # positions at the last build
        self.nbr = ti.field(ti.i32)
        fb.dense(ti.ij, (S, capacity)).place(self.nbr)
        self.nbr_n = st.scalar(fb, S, ti.i32)
        self.bin_count = st.scalar(fb, nb, ti.i32)
        self.bin_start = st.scalar(fb, nb + 1, ti.i32)
        self.bin_cursor = st.scalar(fb, nb, ti.i32)
        self.bin_items = st.scalar(fb, S, ti.i32)
        self.seg_bin = st.scalar(fb, S, ti.i32)
        self.flags = st.scalar(fb, 4, ti.i32)               # 0: overflow, 1: a particle moved past half the skin
        self.rebuilds = 0

    @ti.kernel
    def _build(self):
        st = self.state
        N = ti.static(st.N)
        nbx, nby = ti.static(self.nbx, self.nby)
        r2 = ti.static(self.radius ** 2)
        ti.loop_config(serialize=st.serial)
        for i in range(nbx * nby):
            self.bin_count[i] = 0
        ti.loop_config(serialize=st.serial)
        for s in range(st.n_s):
            m = st.seg_mid(s)
            bx = ti.min(ti.cast(m[0] / st.Lx * nbx, ti.i32), nbx - 1)
            by = ti.min(ti.cast(m[1] / st.Ly * nby, ti.i32), nby - 1)
            b = bx * nby + by
            self.seg_bin[s] = b
            ti.atomic_add(self.bin_count[b], 1)
        ti.loop_config(serialize=True)
        for i in range(nbx * nby + 1):
            if i == 0:
                self.bin_start[0] = 0
            else:
                self.bin_start[i] = self.bin_start[i - 1] + self.bin_count[i - 1]
        ti.loop_config(serialize=st.serial)
        for i in range(nbx * nby):
            self.bin_cursor[i] = self.bin_start[i]
        ti.loop_config(serialize=st.serial)
        for s in range(st.n_s):
            k = ti.atomic_add(self.bin_cursor[self.seg_bin[s]], 1)
            self.bin_items[k] = s
        ti.loop_config(serialize=st.serial)
        for s in range(st.n_s):
            cs = s // (N - 1)
            ks = s % (N - 1)
            ms = st.seg_mid(s)
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
                        ct = t // (N - 1)
                        kt = t % (N - 1)
                        if t != s and (ct != cs or abs(kt - ks) >= 2):
                            d = st.mi(st.seg_mid(t) - ms)
                            if d.dot(d) < r2:
                                if n < self.max_nbrs:
                                    self.nbr[s, n] = t
                                else:
                                    self.flags[0] = 1
                                n += 1
            n = ti.min(n, self.max_nbrs)
            self.nbr_n[s] = n
            # insertion sort: the list, and so every force sum, is independent of thread scheduling
            for i in range(1, n):
                v = self.nbr[s, i]
                j = i - 1
                while j >= 0 and self.nbr[s, j] > v:
                    self.nbr[s, j + 1] = self.nbr[s, j]
                    j -= 1
                self.nbr[s, j + 1] = v
        ti.loop_config(serialize=st.serial)
        for p in range(st.n_p):
            self.x_ref[p] = st.x[p]
        self.flags[1] = 0

    def rebuild(self) -> None:
        self.flags[0] = 0
        self._build()
        self.rebuilds += 1
        if self.flags[0]:
            raise NeighbourOverflow(
                f"more than {self.max_nbrs} segments within the neighbour radius of one segment: cells are packed "
                f"beyond area fraction 1 or blew up; set run.max_neighbours higher or use a smaller time step")

    @ti.func
    def store(self, p, xn):
        """Wrap and store particle p's new position; 1 if it has moved past half the skin since the build (the list
        stays valid while no two particles have closed in by more than the skin)."""
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
            self.flags[1] = 1
