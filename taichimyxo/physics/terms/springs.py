"""Term 1, linear springs (docs/model.md "Force terms"): E = k_s / 2 (|l_k| - l0)^2 per segment.

Everything about the term is here: its parameters, its force (`add_forces`, in a cell's frame), its energy (numpy,
for the finite-difference tests) and its stiffness block for the linearly implicit step (`add_stiffness`)."""

import numpy as np
import taichi as ti

from .base import Term


@ti.data_oriented
class Springs(Term):
    name = "springs"

    def __init__(self, scene):
        self.k_s = scene.k_s          # pN/µm
        self.l0 = scene.rest_length   # µm
        self.N = scene.N

    @ti.func
    def add_forces(self, U, Ln, Fi):
        """Fi (N x 2) += spring forces, from the unit segment vectors U (N-1 x 2) and lengths Ln."""
        for k in ti.static(range(self.N - 1)):
            u = ti.Vector([U[k, 0], U[k, 1]])
            fs = self.k_s * (Ln[k] - self.l0) * u              # pulls k toward k+1 when stretched
            Fi[k, 0] += fs[0]
            Fi[k, 1] += fs[1]
            Fi[k + 1, 0] -= fs[0]
            Fi[k + 1, 1] -= fs[1]
        return Fi

    @ti.func
    def add_stiffness(self, band: ti.template(), c, xrel: ti.template(), dt):
        """dt K of the springs into cell c's band: k_s [u u^T + max(0, 1 - l0/l) (I - u u^T)] per segment (the
        compressive geometric part, which is negative, is dropped: K stays positive semidefinite)."""
        N = ti.static(self.N)
        pb = c * N
        I2 = ti.Matrix.identity(band.dtype, 2)
        for k in range(N - 1):
            l = xrel[pb + k + 1] - xrel[pb + k]
            ln = l.norm()
            u = l / ln
            g = ti.max(0.0, 1.0 - self.l0 / ln)
            Ks = dt * self.k_s * ((1.0 - g) * u.outer_product(u) + g * I2)
            band.add_diag(c, k, Ks)
            band.add_diag(c, k + 1, Ks)
            band.add_lower(c, k + 1, k, -Ks)


def energy(pos, k_s, l0):
    """Spring energy of chains pos (..., N, 2), pN·µm (numpy reference)."""
    l = np.linalg.norm(np.diff(pos, axis=-2), axis=-1)
    return 0.5 * k_s * np.sum((l - l0) ** 2)
