"""Statistics of a run's per-cell events (taichimyxo.events: reversals, suppressed reversals, guiding links formed
and broken): reversal intervals, the fraction of due reversals suppressed, guiding-link counts and durations.

An interval is the time between two consecutive reversals of one cell (the time before a cell's first logged
reversal is censored by the start of the run and not counted). A suppressed reversal is one whose clock came due
while the cell was in a head-to-tail interaction (docs/model.md, term 7); fraction suppressed = suppressed /
(reversals + suppressed). A link's duration runs from "link_formed" to the next "link_broken" of the same
(follower, leader) pair; links still open at the end are not counted."""
from __future__ import annotations

import numpy as np


def event_stats(ev: dict, n_cells: int | None = None) -> dict:
    """Reversal intervals and suppression, link counts and durations of an event table (taichimyxo.events)."""
    kind = np.asarray(ev["kind"]).astype(str)
    t = np.asarray(ev["time_s"], float) / 60.0
    cell = np.asarray(ev["cell"], np.int64)
    partner = np.asarray(ev["partner"], np.int64)
    rev = kind == "reversal"
    n_rev, n_sup = int(rev.sum()), int((kind == "suppressed").sum())
    order = np.lexsort((t[rev], cell[rev]))
    rc, rt = cell[rev][order], t[rev][order]
    same = rc[1:] == rc[:-1]
    iv = (rt[1:] - rt[:-1])[same]
    durations = []
    open_links: dict = {}
    for k in np.nonzero((kind == "link_formed") | (kind == "link_broken"))[0]:
        key = (int(cell[k]), int(partner[k]))
        if kind[k] == "link_formed":
            open_links[key] = t[k]
        elif key in open_links:
            durations.append(t[k] - open_links.pop(key))
    mean = float(iv.mean()) if len(iv) else None
    return dict(
        n_reversals=n_rev, n_suppressed=n_sup,
        fraction_suppressed=n_sup / (n_rev + n_sup) if n_rev + n_sup else None,
        n_intervals=int(len(iv)),
        interval_mean_min=mean,
        interval_median_min=float(np.median(iv)) if len(iv) else None,
        interval_cv=float(iv.std(ddof=1) / mean) if len(iv) >= 2 and mean else None,
        intervals_min=iv,
        reversals_per_cell=n_rev / n_cells if n_cells else None,
        n_links_formed=int((kind == "link_formed").sum()), n_links_broken=int((kind == "link_broken").sum()),
        link_duration_median_min=float(np.median(durations)) if durations else None,
        n_link_durations=len(durations),
    )
