"""The claims table's figures: one per claim where a picture says it better (claims.<name>.png)."""
from __future__ import annotations

import math
import os

import numpy as np

from .aggregate_measure import RIGID_EXPONENT
from .claim_runs import KINDS, mean_se, runs_of, stable_tracks


def write_claim_plots(runs: list[dict], rows: list[dict], base: str) -> list[str]:
    """One figure per claim that has a picture; sets row["plot_file"]. Returns the paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = {}

    def save(fig, name):
        f = f"{base}.{name}.png"
        tmp = f"{base}.{name}.tmp-{os.getpid()}.png"
        fig.savefig(tmp, dpi=90)
        plt.close(fig)
        os.replace(tmp, f)
        files[name] = f

    lab = lambda r: f"{r['label']} ({KINDS.get(r['kind'], (r['kind'],))[0]})"     # noqa: E731
    wanted = {r["plot"] for r in rows if r["plot"]}

    if "speed" in wanted:
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        for i, r in enumerate(runs):
            h = r["summary"]["speed_histograms"]
            e = np.asarray(h["bin_edges_um_per_min"]) / r["v_b"]
            c = np.asarray(h["inside_aggregates"], float) + np.asarray(h["outside_aggregates"], float)
            if c.sum():
                ax.stairs(c / c.sum() / np.diff(e), e, color=f"C{i}", label=lab(r))
            p95 = np.nanmean(np.asarray(r["summary"]["timeseries"]["speed_p95_um_per_min"], float)) / r["v_b"]
            if math.isfinite(p95):
                ax.axvline(p95, color=f"C{i}", ls="--", lw=1)
        ax.axvline(1.0, color="k", ls=":", label="v_b")
        ax.set(xlabel="cell speed / v_b", ylabel="density", yscale="log",
               title="cell speeds, all frames (dashed: mean 95th percentile)")
        ax.legend(fontsize=8)
        save(fig, "speed")

    if "fraction" in wanted:
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        for i, r in enumerate(runs):
            ts = r["summary"]["timeseries"]
            ax.plot(ts["time_min"], ts["fraction_in_aggregates"], color=f"C{i}", label=lab(r))
        ax.set(xlabel="time (min)", ylabel="fraction of cells in rotating aggregates", ylim=(0, 1))
        ax.legend(fontsize=8)
        save(fig, "fraction")

    if "rigid" in wanted:
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        data, names = [], []
        for r in runs:
            al = [x for t in r["summary"]["tracks"] for x in t["series"].get("rigidity_exponent", [])
                  if x is not None]
            if al:
                data.append(al)
                names.append(lab(r))
        if data:
            ax.boxplot(data)
            ax.set_xticks(range(1, len(names) + 1), names, fontsize=8)
        else:
            ax.text(0.5, 0.5, "no aggregate spanning radii by a factor of 2", ha="center", transform=ax.transAxes)
        ax.axhline(1.0, color="C2", ls="--", label="rigid rotation, v = ω r")
        ax.axhline(RIGID_EXPONENT, color="k", ls=":", label=f"rigid when α >= {RIGID_EXPONENT:g}")
        ax.axhline(0.0, color="C3", ls="--", label="every cell at one speed")
        ax.legend(fontsize=7)
        ax.set(ylabel="rigidity exponent α (speed ~ r^α)", title="rigid rotation, aggregate-frames")
        save(fig, "rigid")

    if "edge_speed" in wanted:
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        for x, kind in enumerate(("active", "adhesion", "slime")):
            ev = [t["mean_edge_speed_vb"] for r in runs_of(runs, kind) for t in stable_tracks(r)]
            if ev:
                ax.scatter(x + 0.08 * np.random.default_rng(0).standard_normal(len(ev)), ev, s=12, alpha=0.6,
                           color=f"C{x}")
                m, se, _ = mean_se(ev)
                ax.errorbar(x + 0.25, m, yerr=2 * np.nan_to_num(se), fmt="ks", ms=5)
            else:
                ax.text(x, 1.0, "no run", ha="center")
        for y, name, c in ((4.0, "active max 4", "C0"), (4 / 3, "adhesion 4/3", "C1"), (1.0, "v_b (slime, free)", "k")):
            ax.axhline(y, color=c, ls=":", label=name)
        ax.set_xticks([0, 1, 2], [KINDS[k][0] for k in ("active", "adhesion", "slime")])
        ax.set(ylabel="edge speed / v_b (per track)", title="edge speed (square: mean ± 2 SE over tracks)")
        ax.legend(fontsize=8)
        save(fig, "edge_speed")

    if "edge_vs_radius" in wanted:
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        reg_row = next(r for r in rows if r["id"] == "edge_speed_vs_size")
        for i, kind in enumerate(("active", "adhesion")):
            tr = [t for r in runs_of(runs, kind) for t in stable_tracks(r)]
            if not tr:
                continue
            R = np.array([t["mean_radius_um"] for t in tr])
            E = np.array([t["mean_edge_speed_um_per_min"] for t in tr])
            ax.scatter(R, E, s=14, color=f"C{i}", label=f"{KINDS[kind][0]} tracks")
            reg = reg_row["values"].get(kind)
            if reg and len(tr) >= 3 and math.isfinite(reg["slope_um_per_min_per_um"]):
                rr = np.linspace(R.min(), R.max(), 10)
                ax.plot(rr, reg["intercept_um_per_min"] + reg["slope_um_per_min_per_um"] * rr, color=f"C{i}",
                        label=f"fit: {reg['slope_um_per_min_per_um']:.3f} ± {reg['stderr']:.3f} µm/min per µm")
        vb = runs[0]["v_b"] if runs else 4.0
        ax.axhline(vb, color="k", ls=":", label="v_b")
        ax.set(xlabel="aggregate radius R (µm, track mean)", ylabel="edge speed (µm/min, track mean)",
               title="edge speed vs aggregate size")
        ax.legend(fontsize=8)
        save(fig, "edge_vs_radius")

    if "lifetimes" in wanted:
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        allv = [t["lifetime_min"] for r in runs for t in r["summary"]["tracks"]]
        top = max(allv + [1.0])
        bins = np.arange(0, top + 2, max(1.0, math.ceil(top / 30)))
        for i, r in enumerate(runs):
            life = [t["lifetime_min"] for t in r["summary"]["tracks"]]
            if life:
                ax.hist(life, bins=bins, histtype="step", lw=1.5, color=f"C{i}", label=lab(r))
        st = runs[0]["summary"]["parameters"]["stable_lifetime_min"] if runs else 10
        ax.axvline(st, color="k", ls=":", label=f"{st:g} min")
        ax.set(xlabel="track lifetime (min; tracks alive at the start or end are censored)", ylabel="tracks",
               yscale="log", title="aggregate lifetimes")
        ax.legend(fontsize=8)
        save(fig, "lifetimes")

    if "strain" in wanted:
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        for i, r in enumerate(runs):
            ts = r["summary"]["timeseries"]
            if ts["strain_inside_aggregates_J"]:
                ax.plot(ts["time_min"], ts["strain_inside_aggregates_J"], color=f"C{i}", label=f"{lab(r)} inside")
                ax.plot(ts["time_min"], ts["strain_outside_aggregates_J"], color=f"C{i}", ls="--", label="outside")
        ax.set(xlabel="time (min)", ylabel="mean segment strain energy (J)", yscale="log",
               title="strain energy in and out of rotating aggregates")
        ax.legend(fontsize=8)
        save(fig, "strain")

    for r in rows:
        r["plot_file"] = files.get(r["plot"]) if r["plot"] else None
    return list(files.values())
