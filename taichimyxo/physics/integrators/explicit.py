"""The explicit step (docs/model.md "Equation of motion"): forces at x_n, then the semi-implicit Euler step of
m dv/dt = F - zeta v with the drag implicit, v_n+1 = (m v_n + dt F) / (m + dt zeta) per axis (t, n);
x_n+1 = x_n + dt v_n+1. With m = 0 (the paper's model, the default) this is the overdamped step
v = F_t / zeta_t + F_n / zeta_n. One fused kernel per step. With run.step_control = "error" the step's length is
chosen by the controller of step_control.py, whose estimate the kernel computes from each particle's velocity."""

import taichi as ti

from ...runtime.kernel_call import direct
from ..neighbours import FLAG_MOVED
from ..state import perp
from .codes import step_code
from .step_control import StepControl


@ti.data_oriented
class Explicit:
    name = "explicit"

    def __init__(self, scene, state, model, neighbours, builder):
        self.state, self.model, self.nl = state, model, neighbours
        self.N = scene.N
        self.zeta_t, self.zeta_n = scene.zeta_t, scene.zeta_n
        self.mass = scene.mass                  # pN s^2 / µm per particle; 0: overdamped
        self.v = state.vec(builder, state.n_p, state.fdt) if self.mass > 0 else None
        self.control = StepControl(scene, state, builder) if scene.step_control == "error" else None
        self.controlled = self.control is not None
        self._launch_step = direct(self._step)      # a step's kernel call without Taichi's Python work

    @ti.kernel
    def _step(self, dt: ti.f64) -> ti.i32:
        st = self.state
        m = self.model
        N = ti.static(self.N)
        m.pairs()
        ti.loop_config(**st.loops.items)
        for i in range(st.n_cells):
            c = st.cell_of(i)                       # the threads' shares spread over the cells (launch.py)
            x0, X, F, T, Fi = m.cell_forces(c)
            moved = 0
            dv = ti.cast(0.0, ti.f32)
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
                if ti.static(self.controlled):
                    dv = ti.max(dv, self.control.change(c * N + k, v))
                xn = x0 + ti.cast(ti.Vector([X[k, 0], X[k, 1]]) + v * dt, st.pdt)
                moved |= self.nl.store(c * N + k, xn)
            if ti.static(self.controlled):
                self.control.cell_dv[c] = dv
            m.after_move(c, moved, dt)
        if ti.static(m.has_last_loop):
            ti.loop_config(**st.loops.items)
            for c in range(st.n_cells):
                m.last_loop(c, dt)
        ratio = 0
        if ti.static(self.controlled):
            ratio = self.control.ratio_code(dt)
        return step_code(self.nl.flags[FLAG_MOVED], ratio)

    def step(self, dt: float) -> int:
        """One step of dt s; returns its step_code (integrators/__init__.py): the rebuild flag and, with
        run.step_control = "error", the controller's quantised error ratio (StepControl.took decodes it)."""
        return self._launch_step(dt)

    def reset(self, restored: bool = False) -> None:
        """The state was replaced (restored: from a checkpoint, with the controller's history)."""
        if self.control is not None:
            self.control.restored() if restored else self.control.start()

    def checkpoint_fields(self) -> dict:
        out = {"v": self.v} if self.v is not None else {}
        if self.control is not None:
            out.update(self.control.checkpoint_fields())
        return out

    def stats(self) -> dict:
        return self.control.stats() if self.control is not None else {}
