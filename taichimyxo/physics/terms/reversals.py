"""Term 7, reversals (docs/model.md "Force terms"): each cell reverses its engine direction (k_e -> -k_e) when its
clock reaches its period; periods ~ Normal(T_R, sd) truncated below, initial phases uniform, drawn from a
counter-based random stream (taichimyxo/physics/rng.py), so runs are reproducible on any number of threads. With
suppression, a cell in a head-to-tail interaction this step does not reverse; its clock restarts (or, with
reversals.suppressed_wait = "contact_end", the reversal stays due and fires at its first step out of contact).
Clocks are integers (scene steps, run.dt_ms): exact over hours. A step of another length (run.step_control =
"error" takes whole multiples of the scene's step) advances them by its length in scene steps, rounded, at least one. A
rollback's redo splits each scene step into shorter ones; the clock is held on all but the last of them, so it
still counts scene steps (hold_clock)."""

import math

import taichi as ti

from ..rng import STREAM_REVERSAL, uniform_ti
from .base import Term


@ti.data_oriented
class Reversals(Term):
    name = "reversals"
    after_last_loop = True      # the reversal follows the slime write of the same step
    ADDED_LATER = ("rev_suppressed",)

    def __init__(self, scene, state, builder, head_tail=None):
        self.state = state
        self.seed = scene.seed
        T = scene.reversal_period_s / scene.dt
        self.dt0 = scene.dt
        self.period_mean_steps = T
        self.period_sd_steps = T * scene.reversal_sd_fraction
        self.period_min_steps = max(1.0, T * scene.reversal_min_fraction)
        self.head_tail = head_tail if scene.suppression else None
        self.suppressed = self.head_tail is not None
        self.until_contact_end = self.suppressed and scene.suppression_until_contact_end
        C = state.n_cells
        self.rev_clock = state.scalar(builder, C, ti.i32)      # steps since the last reversal
        self.rev_period = state.scalar(builder, C, ti.i32)     # this cycle's period, steps
        self.rev_count = state.scalar(builder, C, ti.i32)      # reversals so far (counter of the random stream)
        self.clock_held = state.scalar(builder, 1, ti.i32)     # 1: this step is a part of a split scene step
        self.rev_suppressed = state.scalar(builder, C, ti.i32)  # reversals skipped by suppression so far (event log)

    @ti.func
    def draw_period(self, c, count):
        u1 = uniform_ti(ti.u32(self.seed), ti.u32(STREAM_REVERSAL), ti.u32(c), ti.u32(2 * count))
        u2 = uniform_ti(ti.u32(self.seed), ti.u32(STREAM_REVERSAL), ti.u32(c), ti.u32(2 * count + 1))
        z = ti.sqrt(-2.0 * ti.log(u1)) * ti.cos(2.0 * math.pi * u2)
        p = self.period_mean_steps + self.period_sd_steps * z
        return ti.cast(ti.max(p, self.period_min_steps), ti.i32)

    @ti.kernel
    def start(self):
        """Periods drawn, initial phases uniform."""
        ti.loop_config(**self.state.loops.items)
        for c in range(self.state.n_cells):
            p = self.draw_period(c, 0)
            u = uniform_ti(ti.u32(self.seed), ti.u32(STREAM_REVERSAL + 100), ti.u32(c), ti.u32(0))
            self.rev_period[c] = p
            self.rev_clock[c] = ti.cast(u * p, ti.i32)
            self.rev_count[c] = 0

    @ti.func
    def after_move(self, c, dt):
        """Advance cell c's clock by a step of dt s; reverse when it reaches the period, unless suppressed."""
        st = self.state
        due_before = self.rev_clock[c] >= self.rev_period[c]     # held since an earlier step (contact_end)
        if self.clock_held[0] == 0:
            self.rev_clock[c] += ti.max(1, ti.cast(ti.round(dt / self.dt0), ti.i32))
        if self.rev_clock[c] >= self.rev_period[c]:
            # the scene steps past the period carry over (none with single steps), so a longer step delays a
            # reversal by less than one step and never shifts the ones after it
            self.rev_clock[c] -= self.rev_period[c]
            skip = False
            if ti.static(self.suppressed):
                skip = self.head_tail.interacts(c)
                if skip and not due_before:
                    self.rev_suppressed[c] += 1
                if ti.static(self.until_contact_end):
                    if skip:
                        self.rev_clock[c] = self.rev_period[c]      # still due: tried again next step
            if not skip:
                st.ke[c] = -st.ke[c]
                self.rev_count[c] += 1
                self.rev_period[c] = self.draw_period(c, self.rev_count[c])

    def checkpoint_fields(self) -> dict:
        return {n: getattr(self, n) for n in ("rev_clock", "rev_period", "rev_count", "rev_suppressed")}

    def hold_clock(self, held: bool) -> None:
        """Hold the clocks during the coming steps (parts of one split scene step) or let them count again."""
        self.clock_held[0] = int(held)
