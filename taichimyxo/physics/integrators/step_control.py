"""The step-size controller (docs/model.md "Numerics", docs/accuracy.md): run.step_control = "error" lets
the explicit step take 1 to run.step_max_multiple scene steps (run.dt_ms) at once, chosen from the estimated local
error of the last step.

The estimate costs no extra force evaluation. Explicit Euler's local error is 1/2 h^2 |dv/dt| per particle, and
h |dv/dt| ~ |v_n - v_n-1| (the change of the particle's velocity between two successive steps), so

    e = 1/2 h max_p |v_n,p - v_n-1,p|                            (µm)

over every particle: the largest error any one particle made (a max, not a mean: a head that loses its guide or a
pole that hits a side is where a large step goes wrong). The step kernel keeps the per-cell maxima and returns
e / tol quantised to 1e-3 alongside the rebuild flag (no field read per step). The next step's multiple is the
largest m <= step_max_multiple with e (m / h_m)^2 <= tol (the error of an order-one method grows as h^2), at most one
more than the last (growth one scene step at a time), never fewer than 1. The step is not redone when e > tol: the
controller shrinks the next one. Steps are whole multiples of the scene's step, so the run's clock (its step count
in scene steps), the frame times, the reversal clocks and --resume stay exact; a step that would pass the end of a
chunk (a frame, a check) is cut to fit, which leaves the controller's multiple unchanged.

In forming aggregates the largest errors are not smooth (they scale with h, not h^2): force jumps no step size
resolves (a guided head's pull is F_max^g at gap d_g and zero beyond it, docs/model.md term 5; a pole in the concave
side of a bent neighbour's joint, whose nearest segment alternates between the two meeting there, term 4). So in
aggregates the controller takes mostly single steps; the measured estimates and steps: docs/accuracy.md.
"""

import math

import taichi as ti

from .codes import error_ratio_code, needs_rebuild

# the quantum of the returned error ratio, and its cap (so that flag + 2 q fits an i32)
RATIO_SCALE = 1000
RATIO_CAP = 1.0e5


@ti.data_oriented
class StepControl:
    def __init__(self, scene, state, builder):
        self.tol = scene.step_tolerance_um
        self.n_cells = state.n_cells
        self.max_multiple = scene.step_max_multiple
        self.v_prev = state.vec(builder, state.n_p, state.fdt)       # each particle's velocity in the last step
        self.cell_dv = state.scalar(builder, state.n_cells, ti.f32)  # per cell: max |v_n - v_n-1| this step
        self.saved = state.scalar(builder, 3, ti.i32)                # multiple, steps taken, scene steps: checkpoints
        self.multiple = 1
        self.steps_taken = 0
        self.ticks = 0

    # ------------------------------------------------------------------ in the step kernel
    @ti.func
    def change(self, p, v):
        """|v - v_prev| of particle p, which moved at v this step; v becomes its previous velocity."""
        d = ti.cast((v - self.v_prev[p]).norm(), ti.f32)
        self.v_prev[p] = v
        return d

    @ti.func
    def ratio_code(self, dt):
        """e / tol for the step just taken, quantised: an integer in [0, RATIO_CAP * RATIO_SCALE]. Called at the
        step kernel's top level: the maximum over cells is a serial loop in cell order (no atomics)."""
        m = ti.cast(0.0, ti.f32)
        ti.loop_config(serialize=True)
        for c in range(self.n_cells):
            m = ti.max(m, self.cell_dv[c])
        r = ti.min(0.5 * dt * ti.cast(m, ti.f64) / self.tol, RATIO_CAP)
        return ti.cast(r * RATIO_SCALE, ti.i32)

    # ------------------------------------------------------------------ on the host
    def next_step(self, left: int) -> int:
        """Scene steps the next step covers: the controller's multiple, cut to the `left` of this chunk."""
        return min(self.multiple, left)

    def took(self, code: int, m: int) -> int:
        """After a step of m scene steps whose kernel returned `code` (integrators.step_code): update the multiple
        (unless the step was cut to fit a chunk) and return the rebuild flag."""
        self.steps_taken += 1
        self.ticks += m
        if m == self.multiple:
            ratio = error_ratio_code(code) / RATIO_SCALE
            grow = self.max_multiple if ratio <= 0 else int(m / math.sqrt(ratio))
            self.multiple = max(1, min(grow, m + 1, self.max_multiple))
        return needs_rebuild(code)

    def start(self) -> None:
        """A new state: no velocity history, so the first step is a single scene step (its estimate compares with
        zero velocities: large, and the multiple stays 1 until the second)."""
        self.v_prev.fill(0)
        self.multiple = 1
        self.steps_taken = self.ticks = 0

    def checkpoint_fields(self) -> dict:
        self.saved[0], self.saved[1], self.saved[2] = self.multiple, self.steps_taken, self.ticks
        return {"step_v_prev": self.v_prev, "step_control": self.saved}

    def restored(self) -> None:
        self.multiple, self.steps_taken, self.ticks = int(self.saved[0]), int(self.saved[1]), int(self.saved[2])

    def stats(self) -> dict:
        return {"steps_taken": self.steps_taken, "scene_steps": self.ticks,
                "mean_multiple": self.ticks / self.steps_taken if self.steps_taken else 0.0,
                "multiple": self.multiple}
