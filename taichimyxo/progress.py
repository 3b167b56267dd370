"""The run's progress line and time formatting: `duration` writes a time with its units, `Progress` is the one
status line on stderr (simulated time of the total, steps per second, time left)."""
from __future__ import annotations

import math
import sys
import time


def duration(seconds: float) -> str:
    """A time with its units: '1 h 05 min' from an hour on, '6 min 05 s' from a minute on, else '3.6 s'."""
    if not math.isfinite(seconds):
        return "?"
    if seconds >= 3600 - 30:
        m = int(round(seconds / 60.0))
        return f"{m // 60} h {m % 60:02d} min"
    if seconds >= 60 - 0.5:
        s = int(round(seconds))
        return f"{s // 60} min {s % 60:02d} s"
    return f"{seconds:.1f} s"


class Progress:
    """One status line on stderr: simulated time of the total, one rate (steps per second of wall time in this
    session) and the time left at that rate. On a terminal it is redrawn in place every second; otherwise (a log
    file, a pipe) it is a plain line when the run starts, every 30 s, and at the end, so a log grows by a short line
    per half minute instead of by one endless carriage-return line."""

    def __init__(self, name: str, total_steps: int, dt: float, start_step: int, stream=None,
                 interval_s: float | None = None):
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = interval_s if interval_s is not None else (1.0 if self.tty else 30.0)
        self.name, self.total, self.dt, self.start = name, total_steps, dt, start_step
        self.t0 = time.perf_counter()
        self.last = -math.inf
        self.width = 0

    def line(self, step: int) -> str:
        el = time.perf_counter() - self.t0
        done = step - self.start
        rate = done / el if el > 0 and done > 0 else 0.0
        left = duration((self.total - step) / rate) if rate > 0 else "?"
        pct = 100.0 * step / max(self.total, 1)
        return (f"{self.name}: {duration(step * self.dt)} of {duration(self.total * self.dt)} simulated "
                f"({pct:.0f} %), {rate:.0f} steps/s, {left} left")

    def update(self, step: int, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now - self.last < self.interval:
            return
        self.last = now
        text = self.line(step)
        if self.tty:
            self.stream.write("\r" + text.ljust(self.width))
            self.width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self, step: int) -> None:
        self.update(step, force=True)
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
