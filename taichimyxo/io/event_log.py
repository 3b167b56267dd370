"""The run's per-cell events (reversals, suppressed reversals, guiding links formed and broken) logged to the sidecar
table ``<run>.events.csv`` (taichimyxo.io.event_table; read back with ``read_events``).

How: the kernels keep per-cell integers only (plain writes, no atomics, so 1 and 2 threads stay bit-identical):
the reversal unit's count of reversals (``rev_count``, the random stream's counter) and of suppressed reversals
(``rev_suppressed``), its clock (scene steps since the last reversal or suppression: the clock restarts at both),
and the guiding unit's ``leader`` (the cell whose tail the head follows, gap below d_g, nearest first; -1: none).
After every chunk of steps (at most ``chunk_steps``, 2000 by default) this writer compares them with the previous
chunk's. Times: a reversal or suppression is stamped exactly, now minus the cell's clock, when it is the cell's only
one in the chunk (periods are minutes, chunks seconds); more in one chunk (periods shorter than a chunk) are stamped
at the chunk's start except the last. Links are stamped at the end of the chunk in which they changed, so a link
made and broken within one chunk is not seen, and after --resume links are logged from the first chunk on (those
open at the resume are not). A step-size rollback that lowers a counter resynchronises silently."""
from __future__ import annotations

import os

import numpy as np

from .event_table import EventTable, events_path
from .writers import Writer


def _np(field):
    return None if field is None else field.to_numpy()


def _leader(guiding):
    """Per cell the cell its head follows, -1: none (the kernel stores 1 + it, so that zeroed memory means none)."""
    f = getattr(guiding, "leader", None)
    return None if f is None else f.to_numpy().astype(np.int64) - 1


class EventLog(Writer):
    """Per-cell events of a run to ``<run>.events.csv`` next to the trajectory ``path``; append=True continues the
    table (--resume)."""

    def __init__(self, path, *, append: bool = False):
        self.path = path
        self.append = append
        self.table = None
        self.prev = None

    @staticmethod
    def has_events(sim) -> bool:
        m = sim.model
        return m.reversals is not None or getattr(m.head_to_tail, "leader", None) is not None

    def _read(self, sim):
        m = sim.model
        rev, gd = m.reversals, m.head_to_tail
        return dict(step=int(sim.step_count), time=float(sim.time),
                    count=_np(getattr(rev, "rev_count", None)), supp=_np(getattr(rev, "rev_suppressed", None)),
                    clock=_np(getattr(rev, "rev_clock", None)), leader=_leader(gd))

    def start(self, run) -> None:
        if not self.has_events(run.sim):
            if not self.append and os.path.isfile(events_path(self.path)):
                os.remove(events_path(self.path))       # an earlier run's table must not pass for this run's
            return
        self.table = EventTable(self.path, mode="a" if self.append else "w")
        self.prev = self._read(run.sim)
        if self.append and self.prev["leader"] is not None:
            self.prev["leader"] = None          # a resumed run's links are not known before its first step

    def after_chunk(self, run) -> None:
        if self.table is None:
            return
        cur = self._read(run.sim)
        prev, self.prev = self.prev, cur
        if cur["step"] <= prev["step"]:
            return
        dt = run.sim.scene.dt
        rows = []                                    # (time, step, cell, kind, partner)
        n_rev = None if cur["count"] is None else cur["count"] - prev["count"]
        n_sup = None if cur["supp"] is None else cur["supp"] - prev["supp"]
        if n_rev is not None and ((n_rev < 0).any() or (n_sup is not None and (n_sup < 0).any())):
            return                                   # rolled back: counters went down
        kinds = [("reversal", n_rev), ("suppressed", n_sup)]
        tot = sum(n for _, n in kinds if n is not None) if n_rev is not None else None
        for kind, n in kinds:
            if n is None:
                continue
            for c in np.nonzero(n > 0)[0]:
                last_step = cur["step"] - int(cur["clock"][c])
                for k in range(int(n[c])):
                    # the cell's latest event carries the clock's exact step; earlier ones in the chunk its start
                    exact = tot[c] == 1 or (k == n[c] - 1 and self._is_latest(kind, c, n_rev, n_sup))
                    st = last_step if exact else prev["step"]
                    rows.append((cur["time"] - (cur["step"] - st) * dt, st, int(c), kind, -1))
        if cur["leader"] is not None and prev["leader"] is not None:
            old, new = prev["leader"], cur["leader"]
            for c in np.nonzero(old != new)[0]:
                if old[c] >= 0:
                    rows.append((cur["time"], cur["step"], int(c), "link_broken", int(old[c])))
                if new[c] >= 0:
                    rows.append((cur["time"], cur["step"], int(c), "link_formed", int(new[c])))
        rows.sort(key=lambda r: (r[1], r[2]))
        for t, st, c, kind, p in rows:
            self.table.add(t, st, [c], kind, [p])
        self.table.flush()

    @staticmethod
    def _is_latest(kind, c, n_rev, n_sup):
        # with both kinds in one chunk the order is unknown: the clock is given to the reversal
        return kind == "reversal" or n_rev is None or n_rev[c] == 0

    def close(self) -> None:
        if self.table is not None:
            self.table.close()
