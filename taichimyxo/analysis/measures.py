"""The measures experimental groups make on myxobacteria movies, in one pass over frames, so that a simulation and a
microscopy experiment (cells as chains of points, as in a Frame) go through the same code: nematic defects
(defects.py), the cluster-size distribution and its fits (cluster_sizes.py), velocity and orientation correlations
and the MSD (correlations.py), reversal intervals and suppression from a run's event table (events.py).

``analyze(..., measures=True)`` (``python -m taichimyxo analyze RUN.gsd --measures``) feeds its frames through a
``Measures`` and adds ``summary["measures"]``; ``measure_frames(frames)`` does the same alone. A measure whose input
is missing (no velocities, no event table, too few equally spaced frames) is skipped with one line in
``measures["skipped"]`` saying what it needs; the others still run."""
from __future__ import annotations

import os

import numpy as np

from ..io.event_table import events_path, read_events
from .cells import CellGeometry
from .cluster_sizes import SIZE_DEFAULTS, size_distribution
from .clusters import cell_clusters
from .correlations import CORR_DEFAULTS, average_correlations, frame_correlations, msd, uniform_prefix, unwrap_tracks
from .defects import FIELD_DEFAULTS, find_defects, frame_field, track_defects
from .events import event_stats
from .params import DEFAULTS

MEASURE_DEFAULTS = dict(FIELD_DEFAULTS, **CORR_DEFAULTS, n_boot=SIZE_DEFAULTS["n_boot"])


class Measures:
    """Accumulates the per-frame measures; ``add(geo, cluster_sizes)`` per frame, then ``finish(events)``."""

    def __init__(self, **kw):
        unknown = set(kw) - set(MEASURE_DEFAULTS)
        if unknown:
            raise TypeError(f"unknown measure parameter(s): {sorted(unknown)}")
        self.P = dict(MEASURE_DEFAULTS, **kw)
        for k in ("spacing_um", "smoothing_um", "dr_um", "r_max_um"):
            if not self.P[k] > 0:
                raise ValueError(f"measure parameter {k} = {self.P[k]}: must be above 0")
        self.times, self.centres, self.sizes, self.defects, self.corr = [], [], [], [], []
        self.box = None
        self.n_cells = 0
        self.no_velocity_frames = 0
        self.last = None

    def add(self, geo: CellGeometry, cluster_sizes) -> None:
        P = self.P
        self.box = geo.L
        self.n_cells = geo.n
        self.times.append(geo.t_min)
        self.centres.append(geo.cen.copy())
        self.sizes.append(np.asarray(cluster_sizes, int))
        field = frame_field(geo.pos, geo.L, spacing_um=P["spacing_um"], smoothing_um=P["smoothing_um"],
                            min_density=P["min_density"])
        dpos, dq = find_defects(field)
        self.defects.append((dpos, dq))
        vel = geo.cvel if geo.pvel is not None and np.any(geo.pspeed > 0) else None
        if vel is None:
            self.no_velocity_frames += 1
        self.corr.append(frame_correlations(geo.cen, geo.head, geo.L, velocities=vel, dr_um=P["dr_um"],
                                            r_max_um=P["r_max_um"]))
        self.last = (geo, field, dpos, dq)

    def finish(self, events=None, events_note: str | None = None) -> dict:
        P = self.P
        skipped = []
        t = self.times
        ids = track_defects(self.defects, self.box, P["max_step_um"]) if self.defects else []
        first, last = {}, {}
        for tt, tid in zip(t, ids):
            for x in tid:
                first.setdefault(int(x), tt)
                last[int(x)] = tt
        life = [last[k] - first[k] for k in first]
        defects = dict(
            time_min=t, n_plus_half=[int((q == 0.5).sum()) for _, q in self.defects],
            n_minus_half=[int((q == -0.5).sum()) for _, q in self.defects],
            n_other=[int((np.abs(q) != 0.5).sum()) for _, q in self.defects],
            positions_um=[p for p, _ in self.defects], charges=[q for _, q in self.defects], track=ids,
            n_tracks=len(first), track_lifetime_min_median=float(np.median(life)) if life else None,
            spacing_um=P["spacing_um"], smoothing_um=P["smoothing_um"])
        out = dict(parameters=P, defects=defects,
                   cluster_sizes=size_distribution(self.sizes, n_cells=self.n_cells, n_boot=P["n_boot"]),
                   orientation_correlation=average_correlations(self.corr, "orientation"),
                   velocity_correlation=average_correlations(self.corr, "velocity"))
        if out["velocity_correlation"] is None:
            skipped.append("velocity correlation: needs particle velocities (particles/velocity in the GSD file, "
                           "written by runs since velocities were stored); this trajectory has none")
        n_uni = uniform_prefix(t)
        if n_uni >= 3:
            dt = t[1] - t[0]
            out["msd"] = msd(unwrap_tracks(np.array(self.centres[:n_uni]), self.box), dt, **{
                k: P[k] for k in ("msd_fit_max_fraction", "msd_lags")})
            out["msd"]["n_frames"] = n_uni
        else:
            out["msd"] = None
            skipped.append("MSD: needs at least 3 equally spaced frames")
        if events is not None:
            out["events"] = event_stats(events, self.n_cells)
        else:
            out["events"] = None
            skipped.append(events_note or "reversal intervals and suppressed reversals: need the run's event table "
                                          "(<run>.events.csv, written next to the trajectory by runs with reversals)")
        out["skipped"] = skipped
        return out


def finish_measures(m: Measures, gsd_path: str) -> dict:
    """m.finish with the run's event table when there is one next to the trajectory."""
    try:
        ev, note = read_events(gsd_path), None
    except FileNotFoundError:
        ev, note = None, (f"reversal intervals and suppressed reversals: need the run's event table "
                          f"{os.path.basename(events_path(gsd_path))} (written next to the trajectory by runs with "
                          f"reversals or guiding); there is none")
    return m.finish(ev, note)


def measure_frames(frames, events=None, contact_tol_um: float = DEFAULTS["contact_tol_um"], **kw) -> dict:
    """The measures of an iterable of Frames on their own (clusters of touching cells found here)."""
    m = Measures(**kw)
    for fr in frames:
        geo = CellGeometry(fr)
        m.add(geo, cell_clusters(geo.pos, geo.L, geo.W, contact_tol_um)[1])
    if not m.times:
        raise ValueError("no frames to measure")
    return m.finish(events)
