"""Term 6, slime trails (docs/model.md "Force terms"): long-range guiding on a grid.

Each step every cell's rear particle writes its forward direction into the grid element under it (one writer per
element: the highest-numbered cell over an element wins, a fixed rule independent of thread order, by a claim pass
and a write pass); a head over a marked element is steered along the trail (either sense, whichever is nearer its
own direction) with F_max^s, normal to the head's direction. Trails persist. The grid is allocated only when the
scene uses slime.
"""

import taichi as ti

from ..state import perp
from .base import Term


@ti.data_oriented
class Slime(Term):
    name = "slime"

    def __init__(self, scene, state, builder):
        self.state = state
        self.N = scene.N
        self.dx, self.f_max = scene.slime_grid, scene.slime_f_max
        self.sgx = max(1, int(round(state.Lx / self.dx)))
        self.sgy = max(1, int(round(state.Ly / self.dx)))
        self.slime = ti.Vector.field(2, dtype=ti.f32)      # trail direction per element (0: unmarked)
        self.slime_claim = ti.field(ti.i32)
        builder.dense(ti.ij, (self.sgx, self.sgy)).place(self.slime, self.slime_claim)

    def checkpoint_fields(self) -> dict:
        return {"slime": self.slime}

    @ti.func
    def element(self, x):
        ix = ti.cast(ti.floor(x[0] / self.dx), ti.i32) % self.sgx
        iy = ti.cast(ti.floor(x[1] / self.dx), ti.i32) % self.sgy
        return ix, iy

    @ti.func
    def add_cell_forces(self, c, T, F):
        """Steer cell c's head along the trail under it."""
        st = self.state
        N = ti.static(self.N)
        head = 0 if st.ke[c] > 0 else N - 1
        th_ = ti.Vector([T[head, 0], T[head, 1]])
        nh = perp(th_)
        ix, iy = self.element(st.x[c * N + head])
        sv = ti.cast(self.slime[ix, iy], st.fdt)
        if sv.dot(sv) > 0.0:
            sg = 1.0 if th_.dot(sv) >= 0.0 else -1.0
            fsl = sg * self.f_max * sv
            fsl = fsl.dot(nh) * nh
            F[head, 0] += fsl[0]
            F[head, 1] += fsl[1]
        return F

    @ti.func
    def _rear(self, c):
        """Rear particle's element and its forward unit tangent (new positions)."""
        st = self.state
        N = ti.static(self.N)
        tail = c * N + (N - 1 if st.ke[c] > 0 else 0)
        nxt = c * N + (N - 2 if st.ke[c] > 0 else 1)
        xr = st.x[tail]
        t = ti.cast(st.mi(st.x[nxt] - xr), ti.f32)
        t = t / ti.max(t.norm(), 1e-12)
        ix, iy = self.element(xr)
        return ix, iy, t

    @ti.func
    def after_move(self, c, dt):
        """Claim the element under cell c's rear particle (the highest cell index wins, last_loop writes)."""
        ix, iy, _ = self._rear(c)
        ti.atomic_max(self.slime_claim[ix, iy], c + 1)

    @ti.func
    def last_loop(self, c, dt):
        """Write cell c's forward direction into the element it won."""
        ix, iy, t = self._rear(c)
        if self.slime_claim[ix, iy] == c + 1:
            self.slime[ix, iy] = t
            self.slime_claim[ix, iy] = 0
