"""Term 2, angular springs (docs/model.md "Force terms"): E = k_a / 2 theta^2 at each inner joint, theta the signed
angle between consecutive segments.

Parameters, force, energy (numpy) and the stiffness block for the linearly implicit step, together."""

import numpy as np
import taichi as ti

from ..state import perp
from .base import Term


@ti.func
def atan_unit(a):
    """atan(a) for a in [0, 1] in f32: Cephes' atanf (one range reduction at tan(pi/8), a degree-9 odd polynomial),
    within 2e-7 rad of the correctly rounded value."""
    r0 = a * 0.0
    z = a
    if a > 0.41421356237:
        r0 = 0.78539816339
        z = (a - 1.0) / (a + 1.0)
    z2 = z * z
    return r0 + ((((8.05374449538e-2 * z2 - 1.38776856032e-1) * z2 + 1.99777106478e-1) * z2
                  - 3.33329491539e-1) * z2 * z + z)


@ti.func
def angle(y, x, fast: ti.template()):
    """atan2(y, x). In force precision f32 (`fast`) an inlined polynomial (atan_unit) instead of libm's atan2f:
    cheaper in the step kernel and as accurate (docs/performance.md, "The step kernel"). In f64 ti.atan2."""
    r = x * 0.0
    if ti.static(fast):
        ax = ti.abs(x)
        ay = ti.abs(y)
        mx = ti.max(ax, ay)
        if mx > 0.0:
            r = atan_unit(ti.min(ax, ay) / mx)
            if ay > ax:
                r = 1.57079632679 - r
            if x < 0.0:
                r = 3.14159265359 - r
            if y < 0.0:
                r = -r
    else:
        r = ti.atan2(y, x)
    return r


@ti.data_oriented
class Bending(Term):
    name = "bending"

    def __init__(self, scene):
        self.k_a = scene.k_a          # pN·µm
        self.N = scene.N
        self.fast_angle = scene.precision != "f64"     # forces in f32: the polynomial atan2 (angle)

    @ti.func
    def add_forces(self, U, Ln, Fi):
        """Fi (N x 2) += bending forces at joints 1 .. N-2 (d theta / d x_k = perp(l1) / |l1|^2)."""
        for k in ti.static(range(self.N - 2)):
            u1 = ti.Vector([U[k, 0], U[k, 1]])
            u2 = ti.Vector([U[k + 1, 0], U[k + 1, 1]])
            th = angle(u1[0] * u2[1] - u1[1] * u2[0], u1.dot(u2), self.fast_angle)
            fA = -self.k_a * th * perp(u1) / Ln[k]
            fC = -self.k_a * th * perp(u2) / Ln[k + 1]
            Fi[k, 0] += fA[0]
            Fi[k, 1] += fA[1]
            Fi[k + 2, 0] += fC[0]
            Fi[k + 2, 1] += fC[1]
            Fi[k + 1, 0] -= fA[0] + fC[0]
            Fi[k + 1, 1] -= fA[1] + fC[1]
        return Fi

    @ti.func
    def add_stiffness(self, band: ti.template(), c, xrel: ti.template(), dt):
        """dt k_a g g^T per joint into cell c's band, g = d theta / dx over the joint's three particles (the
        theta d2theta term is dropped: K stays positive semidefinite)."""
        N = ti.static(self.N)
        pb = c * N
        ka = dt * self.k_a
        for j in range(N - 2):
            l1 = xrel[pb + j + 1] - xrel[pb + j]
            l2 = xrel[pb + j + 2] - xrel[pb + j + 1]
            gA = perp(l1) / l1.dot(l1)
            gC = perp(l2) / l2.dot(l2)
            gB = -(gA + gC)
            band.add_diag(c, j, ka * gA.outer_product(gA))
            band.add_diag(c, j + 1, ka * gB.outer_product(gB))
            band.add_diag(c, j + 2, ka * gC.outer_product(gC))
            band.add_lower(c, j + 1, j, ka * gB.outer_product(gA))
            band.add_lower(c, j + 2, j, ka * gC.outer_product(gA))
            band.add_lower(c, j + 2, j + 1, ka * gC.outer_product(gB))


def bend_angles(pos):
    """(..., N-2) signed angle between consecutive segments of chains pos (..., N, 2)."""
    d = np.diff(np.asarray(pos, dtype=np.float64), axis=-2)
    a, b = d[..., :-1, :], d[..., 1:, :]
    return np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], np.sum(a * b, -1))


def energy(pos, k_a):
    """Bending energy of chains pos (..., N, 2), pN·µm (numpy reference)."""
    return 0.5 * k_a * np.sum(bend_angles(pos) ** 2)
