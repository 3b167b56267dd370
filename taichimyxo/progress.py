"""The run's progress line and time formatting: `duration` writes a time with its units, `StatusLine` writes one
status line (in place on a terminal, a line per interval elsewhere), `Progress` is the run's (simulated time of the
total, steps per second, time left)."""
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


class StatusLine:
    """One status line on a stream (stderr by default): on a terminal redrawn in place, at most every `interval_s`
    (1 s); to a file or a pipe a plain line at most every `file_interval_s`, so a log grows by short lines instead of
    one endless carriage-return line. What the line says is the caller's (Progress, the sweep's SweepProgress)."""

    def __init__(self, stream=None, interval_s: float | None = None, file_interval_s: float = 30.0):
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = interval_s if interval_s is not None else (1.0 if self.tty else file_interval_s)
        self.last = -math.inf
        self.width = 0

    def due(self, force: bool = False) -> bool:
        """Whether a line is due now (always when forced)."""
        return force or time.monotonic() - self.last >= self.interval

    def show(self, text: str) -> None:
        self.last = time.monotonic()
        if self.tty:
            self.stream.write("\r" + text.ljust(self.width))
            self.width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def clear(self) -> None:
        """Erase the terminal's line (before a line of its own is written under it); nothing to do in a file."""
        if self.tty and self.width:
            self.stream.write("\r" + " " * self.width + "\r")
            self.width = 0


class Progress:
    """One status line on stderr: simulated time of the total, one rate (steps per second of wall time in this
    session) and the time left at that rate. On a terminal it is redrawn in place every second; otherwise (a log
    file, a pipe) it is a plain line when the run starts, every 30 s, and at the end, so a log grows by a short line
    per half minute instead of by one endless carriage-return line."""

    def __init__(self, name: str, total_steps: int, dt: float, start_step: int, stream=None,
                 interval_s: float | None = None):
        self.status = StatusLine(stream, interval_s, file_interval_s=30.0)
        self.name, self.total, self.dt, self.start = name, total_steps, dt, start_step
        self.t0 = time.perf_counter()

    def line(self, step: int) -> str:
        el = time.perf_counter() - self.t0
        done = step - self.start
        rate = done / el if el > 0 and done > 0 else 0.0
        left = duration((self.total - step) / rate) if rate > 0 else "?"
        pct = 100.0 * step / max(self.total, 1)
        return (f"{self.name}: {duration(step * self.dt)} of {duration(self.total * self.dt)} simulated "
                f"({pct:.0f} %), {rate:.0f} steps/s, {left} left")

    def update(self, step: int, force: bool = False) -> None:
        if self.status.due(force):
            self.status.show(self.line(step))

    def close(self, step: int) -> None:
        self.update(step, force=True)
        if self.status.tty:
            self.status.stream.write("\n")
            self.status.stream.flush()
