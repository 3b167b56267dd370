"""The stiffness series of S2 Fig and S3 Fig from their finished runs: a CSV table (kind, k_a, measure, mean, SD,
n seeds), a plot of each measure against k_a (mean ± SD over the seeds, a dot per seed) and the paper's four
statements on stiffness as claims rows (taichimyxo.analysis.stiffness measures and judges them)."""
from __future__ import annotations

import csv
from pathlib import Path

from ..analysis.stiffness import MEASURES, STIFFNESS, run_measures, series, stiffness_rows
from .plan import FINISHED

KIND = {"S2Fig": "non-guided", "S3Fig": "active"}


def records(runs) -> list[dict]:
    """One record per finished run of a stiffness figure (its analysis JSON beside the trajectory or in its kept
    record, taichimyxo.figures.records)."""
    out = []
    kind = KIND[runs.figure.name]
    for p, st in zip(runs.points, runs.states()):
        analysis = runs.analysis(p) if st in FINISHED else None
        if analysis is None:
            continue
        out.append(dict(kind=kind, k_a=float(p.scene.raw["cell"]["k_a_N_m"]), seed=p.seed,
                        measures=run_measures(analysis)))
    return out


def _both(runs) -> list[dict]:
    """This figure's records and those of the other stiffness figure at the same scale and seeds, where run."""
    from .plan import FigureError, plan_figure
    from .specs import FIGURES
    recs = records(runs)
    other = "S3Fig" if runs.figure.name == "S2Fig" else "S2Fig"
    try:
        plan = plan_figure(FIGURES[other], runs.scale_name, runs.root.parent, len(runs.sweep.seeds),
                           scale=runs.sweep.scale or 1.0, hours=runs.sweep.hours, min_cells=1)
    except FigureError:
        return recs
    plan.records = runs.records
    return recs + records(plan)


def write_stiffness(runs, out: Path) -> list[Path]:
    """OUT/stiffness[.SCALE].csv, .png, .claims.md and .claims.csv. Returns the files written."""
    recs = _both(runs)
    stem = "stiffness" if runs.scale_name == "paper" else f"stiffness.{runs.scale_name}"
    out = Path(out)
    files = {k: out / f"{stem}.{k}" for k in ("csv", "png", "claims.md", "claims.csv")}
    table = series(recs)
    with open(files["csv"], "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["kind", "k_a_N_m", "stiffness", "measure", "mean", "sd", "n_seeds", "hours", "values"])
        for r in table:
            w.writerow([r["kind"], f"{r['k_a_N_m']:g}", r["stiffness"], r["measure"],
                        "" if r["mean"] is None else f"{r['mean']:.6g}", "" if r["sd"] is None else f"{r['sd']:.6g}",
                        r["n_seeds"], f"{r['hours']:.4g}", " ".join(f"{v:.6g}" for v in r["values"])])
    _plot(table, files["png"], len(recs))
    rows = stiffness_rows(recs)
    cols = ("claim", "measured", "paper", "status")
    esc = lambda s: str(s).replace("|", "\\|")        # noqa: E731
    md = ["# The paper's statements on bending stiffness", "", "| # | " + " | ".join(cols) + " |",
          "|---" * (len(cols) + 1) + "|"]
    md += [f"| {i} | " + " | ".join(esc(r[c]) for c in cols) + " |" for i, r in enumerate(rows, 1)]
    files["claims.md"].write_text("\n".join(md) + "\n")
    with open(files["claims.csv"], "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("id",) + cols)
        for r in rows:
            w.writerow([r["id"]] + [r[c] for c in cols])
    return list(files.values())


def _plot(table: list[dict], path: Path, n_runs: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    shown = [m for m in MEASURES if m != "long_lived_fraction"]
    fig, axes = plt.subplots(1, len(shown), figsize=(4 * len(shown), 3.4))
    for ax, m in zip(axes, shown):
        for kind, mark in (("non-guided", "s"), ("active", "o")):
            rows = [r for r in table if r["kind"] == kind and r["measure"] == m and r["mean"] is not None]
            if not rows or (m == "mean_cluster_size") != (kind == "non-guided"):
                continue
            ks = [r["k_a_N_m"] for r in rows]
            ax.errorbar(ks, [r["mean"] for r in rows], yerr=[r["sd"] or 0 for r in rows], marker=mark, capsize=3,
                        label="non-guided (S2 Fig)" if kind == "non-guided" else "active following (S3 Fig)")
            for r in rows:
                ax.plot([r["k_a_N_m"]] * len(r["values"]), r["values"], ".", color="grey", alpha=0.6)
        ax.set_xscale("log")
        ax.set_xlim(min(STIFFNESS) / 2, max(STIFFNESS) * 2)     # the four stiffnesses, with or without their runs
        if not ax.get_lines():
            ax.text(0.5, 0.5, "no runs", transform=ax.transAxes, ha="center", va="center", color="grey")
            ax.set_yticks([])
        ax.set_xticks(list(STIFFNESS), [f"{k:g}\n{v}" for k, v in STIFFNESS.items()], fontsize=7)
        ax.set(xlabel="k_a (N·m)", title=MEASURES[m])
        ax.title.set_fontsize(9)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.suptitle(f"Stiffness series over {n_runs} runs: mean ± SD over seeds (dots: seeds), last quarter of each run",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
