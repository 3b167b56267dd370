"""Per-cell banded symmetric matrices for the linearly implicit step: storage, assembly by 2 x 2 blocks, Cholesky
factorisation, solve and product, one cell per thread.

Vectors are scalar fields over degrees of freedom: dof 2 p + a is axis a of particle p, so cell c owns dofs
c n2 ... c n2 + n2 - 1 (n2 = 2N). Lf holds, per dof row i of a cell, the lower band L[i, j] at Lf[base + i, i - j]
and 1 / L[i, i] in the last slot. Loops over dofs are dynamic (not unrolled): with the band held in registers and
every solve unrolled, Taichi took five minutes to compile; these loops are short and cache-resident. Only the
factorisation, which appears once in the program, is unrolled (~15 % faster steps than dynamic loops)."""

import taichi as ti


@ti.data_oriented
class BandedCells:
    def __init__(self, n_cells: int, N: int, dtype, builder):
        self.N, self.n2 = N, 2 * N
        self.BW = min(6, self.n2)                 # lower band incl. the diagonal: bending couples k and k+2
        self.dtype = dtype
        self.Lf = ti.field(dtype)
        builder.dense(ti.ij, (n_cells * self.n2, self.BW + 1)).place(self.Lf)
        self.tmp = ti.field(dtype)
        builder.dense(ti.i, n_cells * self.n2).place(self.tmp)

    @ti.func
    def clear(self, c):
        base = c * self.n2
        for i in range(self.n2):
            for j in ti.static(range(self.BW + 1)):
                self.Lf[base + i, j] = 0.0

    @ti.func
    def add_lower(self, c, pi, pj, B):
        """Add the 2 x 2 block B at particle rows pi > pj (particles of cell c, 0 .. N-1)."""
        base = c * self.n2
        for a in ti.static(range(2)):
            for b in ti.static(range(2)):
                i = 2 * pi + a
                j = i - 2 * pj - b
                self.Lf[base + i, j] = self.Lf[base + i, j] + B[a, b]

    @ti.func
    def add_diag(self, c, pi, B):
        """Add the symmetric 2 x 2 block B on the diagonal of particle pi of cell c."""
        # plain read-modify-write: `field[i] += x` compiles to an atomic add, several times slower
        i = c * self.n2 + 2 * pi
        self.Lf[i, 0] = self.Lf[i, 0] + B[0, 0]
        self.Lf[i + 1, 0] = self.Lf[i + 1, 0] + B[1, 1]
        self.Lf[i + 1, 1] = self.Lf[i + 1, 1] + B[1, 0]

    @ti.func
    def factor(self, c):
        """Cholesky-factorise cell c's matrix in place."""
        n2 = ti.static(self.n2)
        BW = ti.static(self.BW)
        base = c * n2
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
    def solve(self, c, src: ti.template(), dst: ti.template()):
        """dst = M^-1 src on cell c's dofs (M = L L^T); src may be dst."""
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
    def multiply(self, c, y: ti.template(), out: ti.template()):
        """out = M y on cell c's dofs (L L^T y)."""
        n2 = ti.static(self.n2)
        BW = ti.static(self.BW)
        base = c * n2
        for i in range(n2):
            acc = ti.cast(0.0, self.dtype)
            for k in range(i, ti.min(n2, i + BW)):
                acc += self.Lf[base + k, k - i] * y[base + k]
            self.tmp[base + i] = acc
        for i in range(n2):
            acc = ti.cast(0.0, self.dtype)
            for k in range(ti.max(0, i - BW + 1), i + 1):
                acc += self.Lf[base + i, i - k] * self.tmp[base + k]
            out[base + i] = acc

    @ti.func
    def dot(self, c, a: ti.template(), b: ti.template()):
        base = c * self.n2
        acc = ti.cast(0.0, ti.f64)
        for i in range(self.n2):
            acc += ti.cast(a[base + i] * b[base + i], ti.f64)
        return acc
