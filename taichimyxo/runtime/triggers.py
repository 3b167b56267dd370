"""Triggers: when a writer acts, in the way HOOMD-blue's ``hoomd.trigger`` objects do.

A trigger is called with the step number and says whether its writer acts at that step: ``trigger(step) -> bool``.

- :class:`Periodic` fires on the scene's step grid, every ``seconds`` / ``minutes`` of simulated time (rounded to
  whole steps, at least one, as the scene rounds ``output.frame_interval_min``) or every ``steps`` steps, at the
  multiples of its period counted from step 0 (so a resumed run fires at the same steps as an uninterrupted one).
  the run loop stops the simulation exactly at the steps it fires (:func:`taichimyxo.runtime.run_loop.drive`).
- :class:`WallClock` fires at most once every ``seconds`` of wall-clock time; the run loop asks it between chunks of
  steps (at most ``chunk_steps`` apart). For checkpoints: it never decides where the simulation stops.

Simulated-time triggers know their period in steps once bound to the time step (``bind(dt)``; the run loop binds
them to the simulation's scene step).
"""
from __future__ import annotations

import time


class Trigger:
    """Base class. Step triggers define ``next_after(step)`` and ``prev_before(step)``; others poll."""

    def bind(self, dt: float) -> "Trigger":
        return self

    def __call__(self, step: int) -> bool:
        raise NotImplementedError


class Periodic(Trigger):
    """Every ``seconds`` or ``minutes`` of simulated time (on the step grid), or every ``steps`` steps."""

    def __init__(self, seconds: float | None = None, *, minutes: float | None = None, steps: int | None = None):
        given = [v is not None for v in (seconds, minutes, steps)]
        if sum(given) != 1:
            raise ValueError("Periodic: give exactly one of seconds=, minutes=, steps=")
        self.seconds = seconds if seconds is not None else (minutes * 60.0 if minutes is not None else None)
        if self.seconds is not None and not self.seconds > 0:
            raise ValueError(f"Periodic: the period must be positive (got {self.seconds!r} s)")
        if steps is not None and int(steps) < 1:
            raise ValueError(f"Periodic: steps={steps!r} must be at least 1")
        self.steps = int(steps) if steps is not None else None

    def bind(self, dt: float) -> "Periodic":
        if self.seconds is not None:
            self.steps = max(1, int(round(self.seconds / dt)))
        return self

    @property
    def period(self) -> int:
        if self.steps is None:
            raise RuntimeError("Periodic(seconds=...) is not bound to a time step yet (bind(dt))")
        return self.steps

    def __call__(self, step: int) -> bool:
        return step % self.period == 0

    def next_after(self, step: int) -> int:
        """The first step after `step` at which it fires."""
        return (step // self.period + 1) * self.period

    def prev_before(self, step: int) -> int:
        """The last step before `step` (> 0) at which it fires."""
        return (step - 1) // self.period * self.period

    def __repr__(self) -> str:
        what = f"seconds={self.seconds:g}" if self.seconds is not None else f"steps={self.steps}"
        return f"Periodic({what})"


class WallClock(Trigger):
    """At most once every ``seconds`` (or ``minutes``) of wall-clock time, counted from the start of the run."""

    def __init__(self, seconds: float | None = None, *, minutes: float | None = None):
        if (seconds is None) == (minutes is None):
            raise ValueError("WallClock: give one of seconds=, minutes=")
        self.seconds = float(seconds if seconds is not None else minutes * 60.0)
        if not self.seconds >= 0.0:
            raise ValueError(f"WallClock: the interval must be zero or positive, e.g. seconds=300 (got "
                             f"{self.seconds:g} s)")
        self.last = time.perf_counter()

    def restart(self) -> None:
        self.last = time.perf_counter()

    def __call__(self, step: int) -> bool:
        now = time.perf_counter()
        if now - self.last > self.seconds:
            self.last = now
            return True
        return False

    def __repr__(self) -> str:
        return f"WallClock(seconds={self.seconds:g})"


def is_step_trigger(trigger) -> bool:
    """True for triggers the run loop schedules stops for (they define next_after / prev_before)."""
    return trigger is not None and hasattr(trigger, "next_after") and hasattr(trigger, "prev_before")
