"""The sweep's progress: runs done, running, failed and waiting, and the time left, on one line of stderr.

An executor reports to it: ``started(run_dir)`` when a run begins to run (not when it is queued),
``finished(run_dir, result)`` when it ends (result: what taichimyxo.sweep.runner.run_point returns), ``note(text)``
for anything else worth a line (a requeue, a lost node), ``tick()`` now and then so a terminal's line stays fresh.
On a terminal the line is redrawn in place every second; to a file or a pipe it is written every minute, and every
run that ends gets a line of its own either way (a failed one with its error)."""
from __future__ import annotations

import time

from ..runtime.status_line import StatusLine, duration


class SweepProgress:
    def __init__(self, name: str, total: int, skipped: int, jobs: int, stream=None, interval_s: float | None = None,
                 on_completed=None):
        """on_completed(run_dir): called as each run completes, before the others end (a figure keeps its record)."""
        self.on_completed = on_completed
        self.status = StatusLine(stream, interval_s, file_interval_s=60.0)
        self.stream = self.status.stream
        self.name, self.total, self.skipped, self.jobs = name, total, skipped, max(1, jobs)
        self.running: dict[str, float] = {}
        self.counts = {"completed": 0, "failed": 0, "interrupted": 0}
        self.durations: list[float] = []

    # ---- what executors call
    def started(self, run_dir: str) -> None:
        self.running[str(run_dir)] = time.monotonic()
        self.tick(force=True)

    def finished(self, run_dir: str, result: dict) -> None:
        t0 = self.running.pop(str(run_dir), None)
        status = result.get("status", "failed")
        status = "completed" if status == "skipped" else status
        self.counts[status] = self.counts.get(status, 0) + 1
        took = time.monotonic() - t0 if t0 is not None else None
        name = result.get("name") or str(run_dir)
        if status == "completed":
            if took is not None:
                self.durations.append(took)
            self.note(f"done {name}" + (f" in {duration(took)}" if took is not None else ""))
            if self.on_completed is not None:
                try:
                    self.on_completed(str(run_dir))
                except Exception as e:          # noqa: BLE001 -- the other runs go on; the caller retries at the end
                    self.note(f"{name}: {type(e).__name__}: {e}")
        elif status == "failed":
            self.note(f"failed {name}: {result.get('error') or 'no error message'}")
        else:
            self.note(f"{status} {name}")

    def note(self, text: str) -> None:
        self.status.clear()
        self.stream.write(f"{self.name}: {text}\n")
        self.stream.flush()
        self.tick(force=True)

    def tick(self, force: bool = False) -> None:
        if not self.status.due(force):
            return
        if not self.status.tty and force:
            return                  # to a file: events have their own lines, the status line every interval
        self.status.show(self.line())

    def close(self) -> None:
        self.status.clear()
        self.stream.write(self.line() + "\n")
        self.stream.flush()

    # ---- the line
    @property
    def waiting(self) -> int:
        ended = sum(self.counts.values())
        return max(0, self.total - self.skipped - ended - len(self.running))

    def eta_seconds(self) -> float | None:
        """Time left: the runs waiting and what the running ones have left, at the mean duration of the runs that
        ended in this session, shared by the runs that can run at once. None before a run has ended."""
        if not self.durations:
            return None
        mean = sum(self.durations) / len(self.durations)
        now = time.monotonic()
        work = self.waiting * mean + sum(max(mean - (now - t0), 0.0) for t0 in self.running.values())
        return work / min(self.jobs, max(1, self.waiting + len(self.running)))

    def line(self) -> str:
        done = self.counts["completed"] + self.skipped
        eta = self.eta_seconds()
        if not (self.waiting or self.running):
            left = "nothing left"
        elif eta is None:
            left = "time left: after the first run"
        elif eta < 1.0:
            left = "the last runs are taking longer than the others took"
        else:
            left = f"about {duration(eta)} left"
        earlier = f" ({self.skipped} before)" if self.skipped else ""
        extra = f", {self.counts['interrupted']} interrupted" if self.counts["interrupted"] else ""
        return (f"{self.name}: {done} of {self.total} done{earlier}, {len(self.running)} running, "
                f"{self.counts['failed']} failed{extra}, {self.waiting} waiting; {left}")
