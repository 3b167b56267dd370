"""Term 3, the distributed engine (docs/model.md "Force terms"): each particle is pushed with F_e / N along the
cell's local forward tangent, toward the head. The forward tangents are also the axes of the anisotropic drag.

engine_direction k_e = ±1 (State.ke): +1 when particle 0 is the head."""

import taichi as ti

from .base import Term


@ti.data_oriented
class Engine(Term):
    name = "engine"

    def __init__(self, scene, state):
        self.state = state
        self.N = scene.N
        self.f_engine = scene.engine_force / scene.N       # per particle, pN

    @ti.func
    def tangents(self, c, U):
        """Forward unit tangents (N x 2) of cell c from its unit segment vectors U (k -> k+1): at the poles the end
        segment's direction, inside the mean of the two segments meeting there, signed toward the head."""
        st = self.state
        N = ti.static(self.N)
        ke = ti.cast(st.ke[c], st.fdt)
        T = ti.Matrix.zero(st.fdt, N, 2)
        for k in ti.static(range(N)):
            v = ti.Vector([0.0, 0.0], dt=st.fdt)
            if ti.static(k == 0):
                v = -ti.Vector([U[0, 0], U[0, 1]])
            elif ti.static(k == N - 1):
                v = -ti.Vector([U[N - 2, 0], U[N - 2, 1]])
            else:
                v = -(ti.Vector([U[k - 1, 0], U[k - 1, 1]]) + ti.Vector([U[k, 0], U[k, 1]]))
                v = v / ti.max(v.norm(), 1e-12)
            T[k, 0] = ke * v[0]
            T[k, 1] = ke * v[1]
        return T

    @ti.func
    def forces(self, Fi, T):
        """F = Fi + F_e / N along each tangent (a new N x 2 matrix; Fi, the internal forces, is kept)."""
        st = self.state
        F = ti.Matrix.zero(st.fdt, self.N, 2)
        for k in ti.static(range(self.N)):
            f = ti.Vector([Fi[k, 0], Fi[k, 1]]) + self.f_engine * ti.Vector([T[k, 0], T[k, 1]])
            F[k, 0] = f[0]
            F[k, 1] = f[1]
        return F
