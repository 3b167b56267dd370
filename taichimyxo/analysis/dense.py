"""The paper's statements on high-density populations (Fig 3, S11-S14 Video), measured.

"A population of non-guided cells did not show any discernible characteristic movement pattern for all bending
stiffness values except very rigid ones (Fig 3B, S11 Video). Interestingly, very rigid cells were able to sort
themselves into straight streams (S12 Video). However, in populations of flexible and very flexible cells with
head-to-tail adhesion or active following there was a visible stable circular movement within the population (Fig
3C, S13 Video). Rigid and very rigid cells sorted themselves into adjacent straight streams (S14 Video) [...] in
populations with active following, whole streams moved with a speed larger than the equilibrium speed v_b."

A run is dense when it started from the aligned packing (population.start = "aligned"; claim_runs.run_kind). Per
dense run, from its analysis summary, over the last quarter of its analysed frames (the claims table's convention):
  fraction_in_aggregates  fraction of the cells in rotating aggregates, mean ± SD
  long_lived_fraction     fraction of its aggregate-frames in tracks living >= 10 min (whole run)
  nematic_order           global nematic order of the cells' axes, mean ± SD: straight streams across the periodic
                          box, whichever way each runs, share one axis; a crowd without pattern does not
  local_polar_order       mean cosine between the headings of touching cells, mean ± SD: sorted streams
                          (neighbours heading one way) against the aligned start's random polarities (~0)
  fast_fraction           fraction of cell-frames (whole run) faster than FAST_VB v_b, from the speed histogram
  speed_p95_vb            95th percentile of cell speed / v_b, mean ± SE over frames (batch means)
Flexible is k_a <= 1e-17 N·m, very rigid 1e-15, rigid 1e-16 (the paper's labels; docs/model.md). Three rows:
  dense_circular_movement: flexible guided (active following or adhesion) dense runs against flexible non-guided
    ones. Consistent when every guided run has a larger fraction of its cells in rotating aggregates than every
    non-guided run, and at least half of its aggregate-frames in long-lived tracks (stable).
  dense_straight_streams: the runs the paper saw sort into straight streams (non-guided very rigid, S12; guided rigid
    or very rigid, S14) against flexible dense runs (S11, S13). Consistent when every stream run's nematic order
    exceeds every flexible run's.
  dense_stream_speedup: active-following dense runs against non-guided ones. Consistent when every active run has a
    larger fraction of cells faster than FAST_VB v_b than every non-guided run, and its p95 speed exceeds v_b by 2 SE.
A row whose runs are missing, or shorter than MIN_HOURS, says "not measurable here" and which scenes it needs."""
from __future__ import annotations

import numpy as np

from .stats import late_start, series_mean_se

FLEXIBLE_KA, RIGID_KA, VERY_RIGID_KA = 1e-17, 1e-16, 1e-15      # N·m
FAST_VB = 1.1               # "faster than v_b": above the speed a free cell keeps, with the histogram's bin width
MIN_HOURS = 1.0             # the aligned rows break within minutes; patterns need an hour to show
GUIDED = ("active", "adhesion")


def _late(x) -> np.ndarray:
    a = np.asarray(x, float)
    return a[late_start(len(a)):]


def _mean_sd(x) -> tuple[float, float]:
    a = x[np.isfinite(x)]
    return (float(a.mean()) if len(a) else float("nan"), float(a.std(ddof=1)) if len(a) > 1 else float("nan"))


def dense_measures(summary: dict, v_b: float) -> dict:
    """The measures of one dense run (module docstring) from its analysis summary, with its simulated hours."""
    ts = summary["timeseries"]
    t = np.asarray(ts["time_min"], float)
    fr, fr_sd = _mean_sd(_late(ts["fraction_in_aggregates"]))
    nem, nem_sd = _mean_sd(_late(ts["nematic_order"]))
    lp, lp_sd = _mean_sd(_late(ts.get("local_polar_order", [float("nan")])))
    p95, p95_se, _ = series_mean_se(_late(ts["speed_p95_um_per_min"]) / v_b)
    h = summary.get("speed_histograms") or {}
    edges = np.asarray(h.get("bin_edges_um_per_min", []), float)
    counts = np.asarray(h.get("inside_aggregates", []), float) + np.asarray(h.get("outside_aggregates", []), float)
    fast = edges[:-1] >= FAST_VB * v_b if len(counts) else np.zeros(0, bool)
    return dict(fraction_in_aggregates=fr, fraction_sd=fr_sd, nematic_order=nem, nematic_sd=nem_sd,
                local_polar_order=lp, local_polar_sd=lp_sd,
                speed_p95_vb=p95, speed_p95_se=p95_se,
                fast_fraction=float(counts[fast].sum() / counts.sum()) if counts.sum() else float("nan"),
                fast_above_um_per_min=float(edges[:-1][fast][0]) if fast.any() else float("nan"),
                long_lived_fraction=(summary.get("lifetimes") or {}).get("fraction_aggregate_frames_long_lived"),
                from_min=float(_late(t)[0]) if len(t) else 0.0, hours=float(t[-1]) / 60 if len(t) else 0.0)


def dense_record(label: str, scene: dict, summary: dict, v_b: float) -> dict:
    """One dense run as the rows take it: label, guiding kind, k_a and its measures."""
    return dict(label=label, guiding=str((scene.get("guiding") or {}).get("kind", "none")),
                k_a=float((scene.get("cell") or {}).get("k_a_N_m", FLEXIBLE_KA)), measures=dense_measures(summary, v_b))


def _is(ka: float, ref: float, above: bool) -> bool:
    return ka >= ref * (1 - 1e-9) if above else ka <= ref * (1 + 1e-9)


def _fmt(r: dict, key: str, spread: str, spec: str = ".2f") -> str:
    m = r["measures"]
    s = m[spread]
    return (f"{r['label']} ({r['guiding']}, k_a {r['k_a']:g}): {m[key]:{spec}}" +
            (f" ± {s:{spec}}" if np.isfinite(s) else ""))


def _row(cid, claim, paper, needs, groups, measured, judge) -> dict:
    """groups: the two lists of records the row compares (both needed); judge(a, b) -> bool."""
    a, b = groups
    used = a + b
    values = {r["label"]: dict(guiding=r["guiding"], k_a_N_m=r["k_a"], **r["measures"]) for r in used}
    if not a or not b:
        status = f"not measurable here: needs {needs} of at least {MIN_HOURS:g} h"
    else:
        status = "consistent" if judge(a, b) else "not consistent"
    return dict(id=cid, claim=claim, paper=paper, measured="; ".join(measured(r) for r in used) or "no dense runs",
                status=status, values=values, labels=[r["label"] for r in used])


def dense_rows(records: list[dict]) -> list[dict]:
    """records: dense_record per dense run -> the three rows (module docstring): dict(id, claim, paper, measured,
    status, values, labels)."""
    long = [r for r in records if r["measures"]["hours"] >= MIN_HOURS - 1e-9]
    flexible = [r for r in long if _is(r["k_a"], FLEXIBLE_KA, False)]
    guided = [r for r in flexible if r["guiding"] in GUIDED]
    non_guided = [r for r in flexible if r["guiding"] == "none"]
    streams = [r for r in long if (r["guiding"] == "none" and _is(r["k_a"], VERY_RIGID_KA, True)) or
               (r["guiding"] in GUIDED and _is(r["k_a"], RIGID_KA, True))]
    active = [r for r in long if r["guiding"] == "active"]
    all_non_guided = [r for r in long if r["guiding"] == "none"]
    m = lambda r, k: r["measures"][k]         # noqa: E731
    return [
        _row("dense_circular_movement", "High density: circular movement with guiding, none without "
             "(fraction of cells in rotating aggregates, mean ± SD, last quarter)",
             "non-guided flexible cells show no discernible movement pattern (Fig 3B, S11); flexible and very "
             "flexible cells with active following or adhesion a visible stable circular movement (Fig 3C, S13)",
             "a flexible guided dense run (S13) and a flexible non-guided one (S11)", (guided, non_guided),
             lambda r: _fmt(r, "fraction_in_aggregates", "fraction_sd") +
             f", {100 * (m(r, 'long_lived_fraction') or 0):.0f} % of aggregate-frames long-lived",
             lambda a, b: min(m(r, "fraction_in_aggregates") for r in a) >
             max(m(r, "fraction_in_aggregates") for r in b) and
             all((m(r, "long_lived_fraction") or 0) >= 0.5 for r in a)),
        _row("dense_straight_streams", "High density: rigid cells sort into straight streams (global nematic "
             "order, mean ± SD, last quarter)",
             "very rigid non-guided cells sort themselves into straight streams (S12); rigid and very rigid cells "
             "with active following into adjacent straight streams (S14); flexible cells do not (S11, S13)",
             "a dense run of very rigid non-guided (S12) or rigid guided cells (S14) and a flexible one (S11 or "
             "S13)", (streams, flexible), lambda r: _fmt(r, "nematic_order", "nematic_sd"),
             lambda a, b: min(m(r, "nematic_order") for r in a) > max(m(r, "nematic_order") for r in b)),
        _row("dense_stream_speedup", f"High density: active following speeds whole streams above v_b (fraction "
             f"of cell-frames faster than {FAST_VB:g} v_b; p95 speed / v_b ± SE)",
             "in populations with active following whole streams move faster than v_b, each cell responding to "
             "the speed-up of the cell in front of it; with the periodic box the speed-up sustains itself",
             "an active-following dense run (S13 or S14) and a non-guided one (S11 or S12)",
             (active, all_non_guided),
             lambda r: f"{r['label']} ({r['guiding']}, k_a {r['k_a']:g}): {100 * m(r, 'fast_fraction'):.0f} % "
             f"faster, p95 {m(r, 'speed_p95_vb'):.2f}" +
             (f" ± {m(r, 'speed_p95_se'):.2f}" if np.isfinite(m(r, "speed_p95_se")) else "") + " v_b",
             lambda a, b: min(m(r, "fast_fraction") for r in a) > max(m(r, "fast_fraction") for r in b) and
             all(m(r, "speed_p95_vb") - 2 * np.nan_to_num(m(r, "speed_p95_se")) > 1 for r in a)),
    ]
