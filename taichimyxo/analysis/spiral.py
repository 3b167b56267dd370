"""The paper's statement on prearranged spiral aggregates (S6 Fig, S9 and S10 Video), measured.

"Prearranged aggregates of rigid and very rigid cells were relatively stable, although they did lose some cells
(S6B Fig). However, the aggregates of the same initial size made of flexible and very flexible cells split after
some time into several smaller aggregates and swirling streams (S6C Fig)."

Per run that started as a spiral (population.start = "spiral"), over the last quarter of its analysed frames: the
rotating aggregates per frame and the share of all cells in the largest of them (the aggregate the spiral became,
or its largest piece). Judged over the runs' k_a, rigid being >= 1e-16 N·m and flexible <= 1e-17 N·m as the paper's
labels are: consistent when every rigid run keeps a larger share in its largest aggregate than every flexible run,
and the flexible runs have at least as many aggregates per frame on average. Without a rigid and a flexible spiral
run of at least an hour: "not measurable here"."""
from __future__ import annotations

import numpy as np

from .stats import late_start

RIGID_KA, FLEXIBLE_KA = 1e-16, 1e-17          # N·m: the paper's "rigid" and "flexible" (docs/model.md)
MIN_HOURS = 1.0


def spiral_measures(summary: dict, n_cells: int) -> dict:
    """Aggregates per frame and the largest aggregate's share of the cells, means over the last quarter of the
    analysed frames, with the run's simulated hours."""
    ts = summary["timeseries"]
    t = [float(x) for x in ts["time_min"]]
    if not t:
        return dict(n_aggregates=None, largest_fraction=None, hours=0.0)
    late = t[late_start(len(t)):]
    largest = {round(x, 6): 0 for x in late}
    for tr in summary.get("tracks", []):
        for tm, n in zip(tr["series"]["time_min"], tr["series"]["n_cells"]):
            k = round(float(tm), 6)
            if k in largest:
                largest[k] = max(largest[k], int(n))
    n_agg = np.asarray(ts["n_aggregates"][len(t) - len(late):], float)
    return dict(n_aggregates=float(np.mean(n_agg)), largest_fraction=float(np.mean(list(largest.values()))) /
                max(n_cells, 1), hours=t[-1] / 60.0)


def spiral_row(records: list[dict]) -> dict:
    """records: dict(label, k_a, measures) per spiral run -> the row's measured text, status and values."""
    long = [r for r in records if r["measures"]["hours"] >= MIN_HOURS - 1e-9]
    rigid = [r for r in long if r["k_a"] >= RIGID_KA * (1 - 1e-9)]
    flexible = [r for r in long if r["k_a"] <= FLEXIBLE_KA * (1 + 1e-9)]
    values = {r["label"]: dict(k_a_N_m=r["k_a"], **r["measures"]) for r in records}
    text = "; ".join(f"k_a {r['k_a']:g}: {r['measures']['n_aggregates']:.2g} aggregates/frame, largest holds "
                     f"{100 * r['measures']['largest_fraction']:.0f} % of cells ({r['measures']['hours']:.2g} h)"
                     for r in sorted(records, key=lambda r: -r["k_a"]))
    if not rigid or not flexible:
        why = ("needs a rigid (k_a >= 1e-16, S9) and a flexible (k_a <= 1e-17, S10) spiral run of at least "
               f"{MIN_HOURS:g} h")
        return dict(measured=text or "no spiral runs", status=f"not measurable here: {why}", values=values)
    kept = min(r["measures"]["largest_fraction"] for r in rigid) > \
        max(r["measures"]["largest_fraction"] for r in flexible)
    split = np.mean([r["measures"]["n_aggregates"] for r in flexible]) >= \
        np.mean([r["measures"]["n_aggregates"] for r in rigid])
    return dict(measured=text, status="consistent" if kept and split else "not consistent", values=values)
