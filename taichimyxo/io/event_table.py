"""A run's per-cell events as a sidecar table next to its trajectory: ``<run>.events.csv``, one row per event,
columns ``time_s,step,cell,kind,partner``. Kinds: ``reversal`` (the cell's engine direction flipped), ``suppressed``
(its reversal came due during a head-to-tail interaction and was skipped), ``link_formed`` / ``link_broken`` (the
cell's head started / stopped following ``partner``'s tail: gap below the guiding range d_g). partner is -1 where
there is none. Written by taichimyxo.io.event_log.EventLog; read with one call, ``read_events(path)``.

Plain CSV so that a spreadsheet, pandas or an experimental pipeline (tracked reversals from a movie) can read and
write the same table; rows are in time order (ties: by cell)."""
from __future__ import annotations

import os

import numpy as np

COLUMNS = ("time_s", "step", "cell", "kind", "partner")
KINDS = ("reversal", "suppressed", "link_formed", "link_broken")


def events_path(path: str) -> str:
    """The event table of a trajectory (``RUN.gsd`` -> ``RUN.events.csv``); an ``.events.csv`` path as given."""
    p = os.fspath(path)
    if p.endswith(".events.csv"):
        return p
    return os.path.splitext(p)[0] + ".events.csv"


def read_events(path: str) -> dict:
    """The events of a run (its trajectory or its table): dict of arrays time_s (float), step, cell, partner
    (int64), kind (str). FileNotFoundError when the run has no table."""
    p = events_path(path)
    if not os.path.isfile(p):
        raise FileNotFoundError(f"{p} not found: the run logged no events (trajectories from runs without "
                                f"reversals or guiding, or written before events were logged)")
    rows = np.genfromtxt(p, delimiter=",", names=True, dtype=None, encoding="utf-8", ndmin=1)
    if rows.dtype.names is None or tuple(rows.dtype.names) != COLUMNS:
        raise ValueError(f"{p}: expected the columns {','.join(COLUMNS)}")
    return dict(time_s=np.asarray(rows["time_s"], float).reshape(-1),
                step=np.asarray(rows["step"], np.int64).reshape(-1),
                cell=np.asarray(rows["cell"], np.int64).reshape(-1),
                kind=np.asarray(rows["kind"]).astype(str).reshape(-1),
                partner=np.asarray(rows["partner"], np.int64).reshape(-1))


class EventTable:
    """Appends rows to a run's table; mode "w" starts it (with the header), "a" continues it (--resume)."""

    def __init__(self, path: str, mode: str = "w"):
        self.path = events_path(path)
        fresh = mode == "w" or not os.path.isfile(self.path)
        self._f = open(self.path, "w" if fresh else "a", encoding="utf-8")
        if fresh:
            self._f.write(",".join(COLUMNS) + "\n")
        self.rows_written = 0

    def add(self, time_s, step, cells, kind: str, partners=None) -> None:
        cells = np.asarray(cells, np.int64).reshape(-1)
        times = np.broadcast_to(np.asarray(time_s, float), cells.shape)
        steps = np.broadcast_to(np.asarray(step, np.int64), cells.shape)
        part = np.full(len(cells), -1, np.int64) if partners is None else np.asarray(partners, np.int64)
        self._f.writelines(f"{t:.6f},{s},{c},{kind},{p}\n" for t, s, c, p in zip(times, steps, cells, part))
        self.rows_written += len(cells)

    def flush(self) -> None:
        self._f.flush()

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()
