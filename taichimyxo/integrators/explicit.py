"""The explicit step (docs/model.md "Equation of motion"): forces at x_n, then the semi-implicit Euler step of
m dv/dt = F - zeta v with the drag implicit, v_n+1 = (m v_n + dt F) / (m + dt zeta) per axis (t, n);
x_n+1 = x_n + dt v_n+1. With m = 0 (the paper's model, the default) this is the overdamped step
v = F_t / zeta_t + F_n / zeta_n. One fused kernel per step."""

import taichi as ti

from ..state import perp


@ti.data_oriented
class Explicit:
    name = "explicit"

    def __init__(self, scene, state, model, neighbours, fb):
        self.state, self.model, self.nl = state, model, neighbours
        self.N = scene.N
        self.zeta_t, self.zeta_n = scene.zeta_t, scene.zeta_n
        self.mass = scene.mass                  # pN s^2 / µm per particle; 0: overdamped
        self.v = state.vec(fb, state.n_p, state.fdt) if self.mass > 0 else None

    @ti.kernel
    def _step(self, dt: ti.f64) -> ti.i32:
        st = self.state
        m = self.model
        N = ti.static(self.N)
        m.pairs()
        ti.loop_config(**st.loops.items)
        for c in range(st.n_cells):
            x0, X, F, T, Fi = m.cell_forces(c)
            moved = 0
            for k in ti.static(range(N)):
                t = ti.Vector([T[k, 0], T[k, 1]])
                n = perp(t)
                f = ti.Vector([F[k, 0], F[k, 1]])
                ft = f.dot(t)
                fn = f.dot(n)
                v = ti.Vector([0.0, 0.0], dt=st.fdt)
                if ti.static(self.mass > 0):
                    vo = self.v[c * N + k]
                    v = (self.mass * vo.dot(t) + dt * ft) / (self.mass + dt * self.zeta_t) * t + \
                        (self.mass * vo.dot(n) + dt * fn) / (self.mass + dt * self.zeta_n) * n
                    self.v[c * N + k] = v
                else:
                    v = ft / self.zeta_t * t + fn / self.zeta_n * n
                xn = x0 + ti.cast(ti.Vector([X[k, 0], X[k, 1]]) + v * dt, st.pdt)
                moved |= self.nl.store(c * N + k, xn)
            m.after_move(c, moved)
        if ti.static(m.has_slime):
            ti.loop_config(**st.loops.items)
            for c in range(st.n_cells):
                m.deposit(c)
        return self.nl.flags[1]

    def step(self, dt: float) -> int:
        return self._step(dt)

    def reset(self) -> None:
        pass

    def checkpoint_fields(self) -> dict:
        return {"v": self.v} if self.v is not None else {}

    def stats(self) -> dict:
        return {}
