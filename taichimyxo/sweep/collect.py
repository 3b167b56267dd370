"""A sweep's results as one table and plots: `collect(sweep, root)` reads every point's result.json and writes

  sweep.csv            one row per run: the swept values, seed, status, simulated and wall time, the outcomes
  sweep.<KEY>.png      for each swept key, a panel per outcome against that key: mean ± SD over seeds, a dot per
                       seed, one line per combination of the other swept keys (e.g. aggregate size against
                       cell.k_a_N_m, guided and non-guided)

The outcomes of a run (`outcomes(analysis)`, from the analysis summary of taichimyxo.analysis), each averaged over
the last quarter of the analysed frames (the convention of taichimyxo.analysis.claims), when the population has
settled:
  n_aggregates            rotating aggregates per frame
  aggregate_cells         mean size of an aggregate, cells (over aggregate-frames)
  aggregate_radius_um     mean radius of an aggregate, µm (over aggregate-frames)
  fraction_in_aggregates  fraction of the cells in rotating aggregates
  edge_speed_vb           edge speed of an aggregate / v_b (over aggregate-frames; empty without aggregates)
  speed_p95_vb            95th-percentile cell speed / v_b
  free_cell_speed_vb      mean speed of cells touching no other / v_b
  cluster_cells           mean size of the cluster a cell is in, cells (touching cells; the non-guided measure)
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from .rundir import read_result, state

OUTCOMES = {   # name -> label on the plots
    "n_aggregates": "rotating aggregates",
    "aggregate_cells": "aggregate size (cells)",
    "aggregate_radius_um": "aggregate radius (µm)",
    "fraction_in_aggregates": "fraction of cells in aggregates",
    "edge_speed_vb": "edge speed / v_b",
    "speed_p95_vb": "95th-percentile speed / v_b",
    "free_cell_speed_vb": "free-cell speed / v_b",
    "cluster_cells": "cluster a cell is in (cells)",
}


# the least top of each panel's y axis (every axis starts at 0): a difference smaller than this is noise to the eye
# too, so a flat outcome stays flat instead of being stretched to fill the panel
Y_TOP = {"n_aggregates": 2.0, "aggregate_cells": 10.0, "aggregate_radius_um": 5.0, "fraction_in_aggregates": 1.0,
         "edge_speed_vb": 2.0, "speed_p95_vb": 2.0, "free_cell_speed_vb": 1.2, "cluster_cells": 5.0}


def _mean(x) -> float | None:
    a = np.asarray([v for v in x if v is not None], float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if len(a) else None


def outcomes(analysis: dict) -> dict:
    """The outcomes of one run (module docstring) from its analysis summary (taichimyxo.analysis.analyze's dict or
    its JSON); None where there is nothing to average (no aggregate, no free cell)."""
    from ..analysis.stats import late_start  # here: the analysis package is heavy to import for a worker
    ts = analysis["timeseries"]
    v_b = float(analysis["meta"]["v_b_um_per_min"])
    t = np.asarray(ts["time_min"], float)
    q0 = late_start(len(t))
    t_from = float(t[q0])
    last = lambda k: ts[k][q0:]                                  # noqa: E731
    cells, radius, edge = [], [], []
    for tr in analysis.get("tracks", []):
        s = tr["series"]
        none = [None] * len(s["time_min"])        # a figure record keeps no radius or edge series (figures/records.py)
        for tm, n, r, e in zip(s["time_min"], s["n_cells"], s.get("radius_um") or none,
                               s.get("edge_speed_um_per_min") or none):
            if tm >= t_from - 1e-9:
                cells.append(n)
                radius.append(r)
                edge.append(e)
    p95 = _mean(last("speed_p95_um_per_min"))
    free = _mean(last("free_cell_speed_um_per_min"))
    edge_m = _mean(edge)
    return {"n_aggregates": _mean(last("n_aggregates")), "aggregate_cells": _mean(cells),
            "aggregate_radius_um": _mean(radius), "fraction_in_aggregates": _mean(last("fraction_in_aggregates")),
            "edge_speed_vb": None if edge_m is None else edge_m / v_b,
            "speed_p95_vb": None if p95 is None else p95 / v_b,
            "free_cell_speed_vb": None if free is None else free / v_b,
            "cluster_cells": _mean(ts.get("mean_cluster_size_weighted", [])[q0:]),
            "from_min": t_from, "to_min": float(t[-1]), "frames": len(t) - q0}


def rows(points, root, swept_keys=None) -> list[dict]:
    """A row per point (a point without a result yet: status 'not run')."""
    out = []
    for p in points:
        d = p.run_dir(root)
        r = read_result(d) or {}
        oc = r.get("outcomes") or {}
        row = {"name": p.name, "run_dir": str(d.relative_to(root)), "status": r.get("status") or
               {"interrupted": "interrupted", "new": "not run"}.get(state(d), "not run")}
        row.update({k: v for k, v in p.overrides.items()})
        for k in swept_keys or ():
            if k not in p.overrides:                 # a key another [[grid]] sweeps: this run's resolved value
                sec, _, key = k.partition(".")
                row[k] = p.scene.raw.get(sec, {}).get(key, "")
        row.update(seed=p.seed, simulated_s=r.get("simulated_seconds"), wall_s=r.get("wall_seconds"),
                   steps=r.get("steps"), cells=r.get("cells"))
        row.update({k: oc.get(k) for k in OUTCOMES})
        row["error"] = r.get("error") or ""
        out.append(row)
    return out


def _fmt(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}" if math.isfinite(v) else ""
    return v


def write_csv(table: list[dict], path: Path) -> Path:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, list(table[0]))
        w.writeheader()
        for r in table:
            w.writerow({k: _fmt(v) for k, v in r.items()})
    return path


def _positions(values: list) -> tuple[dict, bool]:
    """x position of each value, and whether the axis is logarithmic (positive numbers spanning two decades)."""
    nums = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    if not nums:
        return {v: i for i, v in enumerate(values)}, False
    log = min(values) > 0 and max(values) / min(values) >= 100
    return {v: float(v) for v in values}, log


def plot_against(table: list[dict], key: str, others: list[str], path: Path) -> Path:
    """A panel per outcome against `key`; a line per combination of the `others`' values; mean ± SD over seeds and a
    dot per seed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .spec import value_text
    values = list(dict.fromkeys(r[key] for r in table))
    xpos, log = _positions(values)
    groups: dict = {}
    for r in table:
        groups.setdefault(tuple(r[o] for o in others), []).append(r)
    n = len(OUTCOMES)
    cols = 4 if n > 4 else n
    fig, axes = plt.subplots((n + cols - 1) // cols, cols, figsize=(4.2 * cols, 3.4 * ((n + cols - 1) // cols)),
                             squeeze=False)
    for ax, (oc, label) in zip(axes.flat, OUTCOMES.items()):
        for gi, (combo, rs) in enumerate(groups.items()):
            colour = f"C{gi % 10}"
            name = ", ".join(f"{o}={value_text(v)}" for o, v in zip(others, combo)) or None
            xs, ms, sds = [], [], []
            for v in values:
                ys = np.asarray([r[oc] for r in rs if r[key] == v and r[oc] is not None], float)
                ys = ys[np.isfinite(ys)]
                if not len(ys):
                    if any(r[key] == v for r in rs):        # runs there, but nothing to measure: say so
                        ax.annotate("none", (xpos[v], 0), xytext=(0, 4), textcoords="offset points", ha="center",
                                    va="bottom", color="0.4", fontsize=8)
                    continue
                ax.plot(np.full(len(ys), xpos[v]), ys, "o", color=colour, alpha=0.35, ms=4)
                xs.append(xpos[v])
                ms.append(ys.mean())
                sds.append(ys.std(ddof=1) if len(ys) > 1 else 0.0)
            if xs:
                ax.errorbar(xs, ms, yerr=sds, color=colour, marker="s", ms=5, capsize=3, label=name)
        ax.set_title(label, fontsize=10)
        ax.set_xlabel(key)
        if log:
            ax.set_xscale("log")
        if not all(isinstance(xpos[v], float) for v in values):      # categories: one tick each, with margins
            ax.set_xticks(list(xpos.values()), [value_text(v) for v in values])
            ax.set_xlim(-0.5, len(values) - 0.5)
        if not ax.lines:
            ax.text(0.5, 0.5, "none in any run" if oc.startswith(("aggregate_", "edge_")) else "no values",
                    transform=ax.transAxes, ha="center", va="center", color="0.4")
        else:
            ax.ticklabel_format(axis="y", useOffset=False)
            top = max([float(np.nanmax(ln.get_ydata())) for ln in ax.lines if len(ln.get_ydata())] + [0.0])
            ax.set_ylim(0.0, max(Y_TOP.get(oc, 0.0), 1.15 * top))
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    for ax in axes.flat:
        h, lab = ax.get_legend_handles_labels()
        if len(h) > len(handles):
            handles, labels = h, lab
    if labels:
        fig.legend(handles, labels, loc="lower right", fontsize=9, title="mean ± SD over seeds; dots: seeds")
    fig.suptitle(f"outcomes against {key}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def collect(sweep, root, points=None) -> dict:
    """Write sweep.csv and the plots (module docstring) into root from the results of the sweep's points (given, or
    resolved again). Returns dict(csv, plots, rows)."""
    root = Path(root)
    table = rows(sweep.points() if points is None else points, root, sweep.swept_keys)
    csv_path = write_csv(table, root / "sweep.csv")
    plots = []
    done = [r for r in table if r["status"] == "completed"]
    if done:
        for key in sweep.swept_keys:
            others = [k for k in sweep.swept_keys if k != key]
            safe = key.replace("/", "-")
            plots.append(str(plot_against(done, key, others, root / f"sweep.{safe}.png")))
    return {"csv": str(csv_path), "plots": plots, "rows": table}
