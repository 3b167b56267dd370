"""The run's progress line and time formatting: `duration` writes a time with its units, `StatusLine` writes one
status line (in place on a terminal, a line per interval elsewhere), `Progress` is the run's (simulated time of the
total, steps per second, time left)."""
from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

# what compiling a scene's kernels the first time takes on a 2-core machine, roughly (docs/performance.md)
FIRST_COMPILE_S = 30.0


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
    per half minute instead of by one endless carriage-return line.

    The first chunk of steps compiles the kernels, so the rate is measured from its end: until then the line says
    what is happening (`starting`, e.g. 'compiling kernels (first run of this scene, ~30 s)') and gives no time
    left."""

    def __init__(self, name: str, total_steps: int, dt: float, start_step: int, stream=None,
                 interval_s: float | None = None, starting: str = "starting"):
        self.status = StatusLine(stream, interval_s, file_interval_s=30.0)
        self.name, self.total, self.dt, self.start = name, total_steps, dt, start_step
        self.starting = starting
        self.t0 = time.perf_counter()
        self.measured_from: tuple[int, float] | None = None     # (step, time) at the end of the first chunk

    def first_chunk_seconds(self) -> float | None:
        return None if self.measured_from is None else self.measured_from[1] - self.t0

    def line(self, step: int) -> str:
        where = (f"{self.name}: {duration(step * self.dt)} of {duration(self.total * self.dt)} simulated "
                 f"({100.0 * step / max(self.total, 1):.0f} %)")
        if self.measured_from is None:
            return f"{where}, {self.starting} ..."
        s0, t0 = self.measured_from
        if step <= s0:
            return f"{where}, measuring the step rate ..."
        rate = (step - s0) / max(time.perf_counter() - t0, 1e-9)
        return f"{where}, {rate:.0f} steps/s, {duration((self.total - step) / rate)} left"

    def update(self, step: int, force: bool = False) -> None:
        if self.measured_from is None and step > self.start:
            self.measured_from = (step, time.perf_counter())
        if self.status.due(force):
            self.status.show(self.line(step))

    def close(self, step: int) -> None:
        self.update(step, force=True)
        if self.status.tty:
            self.status.stream.write("\n")
            self.status.stream.flush()


def compile_record() -> Path:
    """Where the first chunk's wall time of each scene configuration is kept between runs (the user's cache)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "taichimyxo" / "first_chunk_s.json"


def configuration_key(scene) -> str:
    """What the compiled kernels depend on: everything but the seed, the duration and the outputs."""
    import hashlib
    d = scene.trajectory_values()
    d["run"] = {k: v for k, v in d["run"].items() if k not in ("seed", "hours")}
    d["population"].pop("aligned_tilt_deg", None)            # placement only: the kernels do not read it
    return hashlib.sha1(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]


def starting_note(scene) -> str:
    """What the first line says while the first chunk runs: compiling (first run of this configuration here) or
    loading compiled kernels, with the time it took last."""
    try:
        record = json.loads(compile_record().read_text())
    except (OSError, ValueError):
        record = {}
    last = record.get(configuration_key(scene)) if isinstance(record, dict) else None
    if isinstance(last, (int, float)):
        return f"starting (kernels compiled before; the first steps took {duration(last)} last time)"
    longest = max([v for v in record.values() if isinstance(v, (int, float))] + [FIRST_COMPILE_S]) \
        if isinstance(record, dict) else FIRST_COMPILE_S
    return f"compiling kernels (first run of this scene, ~{longest:.0f} s)"


def remember_first_chunk(scene, seconds: float) -> None:
    """Keep the first chunk's wall time for the next run's first line; a cache that cannot be written is skipped."""
    path = compile_record()
    try:
        record = json.loads(path.read_text())
        record = record if isinstance(record, dict) else {}
    except (OSError, ValueError):
        record = {}
    record[configuration_key(scene)] = round(float(seconds), 1)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(record))
        os.replace(tmp, path)
    except OSError:
        pass
