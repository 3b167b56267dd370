"""The analysis plots (PNG): time series, the aggregates' rigid-body and size tests, distributions, and a snapshot
of the last frame with its aggregates circled. matplotlib is imported only when plots are asked for."""
from __future__ import annotations

import math

import numpy as np

from .params import R_BINS
from .report import fmt


def write_plots(s: dict, base: str) -> list[str]:
    """The four figures of an analyze_frames() summary s, written to <base>.<name>.png. Returns their paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    files = []

    def save(fig, name):
        f = f"{base}.{name}.png"
        fig.savefig(f, dpi=90)
        plt.close(fig)
        files.append(f)

    vb = s["meta"]["v_b_um_per_min"]
    ts = s["timeseries"]
    t = np.array(ts["time_min"])

    # 1. time series
    fig, ax = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    ax[0, 0].plot(t, ts["mean_speed_um_per_min"], label="all cells")
    ax[0, 0].axhline(vb, color="k", ls=":", label="v_b")
    ax[0, 0].set(xlabel="time (min)", ylabel="mean speed (µm/min)", title="speed")
    ax[0, 0].legend()
    for k in ("polar_order", "nematic_order", "local_polar_order", "local_nematic_order"):
        ax[0, 1].plot(t, ts[k], label=k.replace("_", " "))
    ax[0, 1].set(xlabel="time (min)", ylabel="order", ylim=(-0.05, 1.05), title="orientational order")
    ax[0, 1].legend(fontsize=8)
    n = s["meta"]["n_cells"]
    ax[1, 0].plot(t, np.array(ts["largest_cluster"]) / n, label="largest cluster / N")
    ax[1, 0].plot(t, ts["fraction_in_clusters"], label="fraction in clusters (>= 2)")
    ax[1, 0].plot(t, np.array(ts["mean_cluster_size_weighted"]) / n, label="cell-weighted mean size / N")
    ax[1, 0].set(xlabel="time (min)", ylabel="fraction", title="clusters of touching cells")
    ax[1, 0].legend(fontsize=8)
    ax[1, 1].plot(t, ts["n_aggregates"], "C0", label="aggregates")
    ax[1, 1].set(xlabel="time (min)", ylabel="number of aggregates", title="rotating aggregates")
    a2 = ax[1, 1].twinx()
    a2.plot(t, ts["fraction_in_aggregates"], "C1", label="fraction of cells in aggregates")
    a2.set_ylabel("fraction of cells in aggregates", color="C1")
    save(fig, "timeseries")

    # 2. aggregates: rigid-body test and size independence
    fig, ax = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
    la = s.get("_last_agg")
    if la:
        geo, aggs = la
        big = max(aggs, key=lambda a: a["n_cells"])
        r, sp = big["_scatter"]
        ax[0, 0].scatter(r, sp, s=3, alpha=0.4, label="particles")
        rr = np.linspace(0, r.max(), 50)
        ax[0, 0].plot(rr, big["omega_fit_rad_per_min"] * rr, "r", label=f"rigid: ω r, ω = "
                      f"{big['omega_fit_rad_per_min']:.3f} rad/min; rigidity exponent α = "
                      f"{fmt(big.get('rigidity_exponent'))}")
        ax[0, 0].axhline(vb, color="k", ls=":", label="v_b")
        ax[0, 0].axvline(big["radius_um"], color="g", ls="--", label="R")
        ax[0, 0].set(xlabel="distance from centre (µm)", ylabel="speed (µm/min)",
                     title=f"largest aggregate at t = {geo.t_min:.0f} min ({big['n_cells']} cells)")
        ax[0, 0].legend(fontsize=8)
    else:
        ax[0, 0].text(0.5, 0.5, "no aggregates", ha="center", transform=ax[0, 0].transAxes)
    sp_ = s["speed_profile"]
    mid = 0.5 * (R_BINS[1:] + R_BINS[:-1])
    ax[0, 1].plot(mid, sp_["mean_speed_vb"], "o-", label="mean speed / v_b (all aggregates)")
    la_all = [a for tr in s["tracks"] for a in [tr["last"]]]
    if la_all:
        rig = float(np.nanmedian([a["edge_speed_rigid_vb"] for a in la_all]))
        ax[0, 1].plot([0, 1], [0, rig], "r--", label="rigid body ω r (median ω R)")
    ax[0, 1].axhline(1, color="k", ls=":", label="v_b")
    ax[0, 1].set(xlabel="r / R", ylabel="speed / v_b", title="pooled speed profile")
    ax[0, 1].legend(fontsize=8)
    st = [tr for tr in s["tracks"] if tr["stable"]]
    if st:
        R = np.array([tr["mean_radius_um"] for tr in st])
        E = np.array([tr["mean_edge_speed_vb"] for tr in st])
        ax[1, 0].scatter(R, E, c="C0", label="tracks (time means)")
        reg = s["predictions"]["edge_speed_vs_radius_tracks"]
        if reg["slope_um_per_min_per_um"] is not None and math.isfinite(reg["slope_um_per_min_per_um"]):
            rr = np.linspace(R.min(), R.max(), 10)
            ax[1, 0].plot(rr, (reg["intercept_um_per_min"] + reg["slope_um_per_min_per_um"] * rr) / vb, "C0-",
                          label=f"fit slope {reg['slope_um_per_min_per_um']:.3f} ± {fmt(reg['stderr'], '.3f')}")
        for name, y, c in (("adhesion 4/3", 4 / 3, "C2"), ("active max 4", 4, "C3"), ("slime ~1", 1, "k")):
            ax[1, 0].axhline(y, color=c, ls=":", label=name)
        ax[1, 0].legend(fontsize=8)
    ax[1, 0].set(xlabel="aggregate radius (µm)", ylabel="edge speed / v_b", title="edge speed vs size")
    for tr in sorted(s["tracks"], key=lambda tr: -tr["n_frames"])[:20]:
        ax[1, 1].plot(tr["series"]["time_min"], np.abs(tr["series"]["omega_rad_per_min"]), ".-", ms=3)
    ax[1, 1].set(xlabel="time (min)", ylabel="|ω| (rad/min)", title="angular speed per track (20 longest)")
    save(fig, "aggregates")

    # 3. distributions
    fig, ax = plt.subplots(1, 3, figsize=(14, 4), constrained_layout=True)
    h = s["speed_histograms"]
    e = np.asarray(h["bin_edges_um_per_min"])
    for k, lab in (("inside_aggregates", "inside aggregates"), ("outside_aggregates", "outside")):
        c = np.asarray(h[k], float)
        if c.sum():
            ax[0].stairs(c / c.sum() / np.diff(e), e, label=lab)
    ax[0].axvline(vb, color="k", ls=":", label="v_b")
    ax[0].set(xlabel="cell speed (µm/min)", ylabel="density", title="speed distribution (all frames)")
    ax[0].legend()
    cd = s["cluster_size_distribution"]
    fr = np.asarray(cd["fraction_of_cells"])
    ed = np.asarray(cd["size_bin_edges"])
    nfr = len(fr)
    for i, lab in ((0, "first"), (nfr // 2, "middle"), (nfr - 1, "last")):
        ax[1].step(ed[:-1], fr[i], where="post", label=f"{lab} frame (t = {ts['time_min'][i]:.0f} min)")
    ax[1].set(xscale="log", xlabel="cluster size (cells)", ylabel="fraction of cells",
              title="cluster size distribution")
    ax[1].legend(fontsize=8)
    sp_ = s["strain_profile"]
    if sp_ is not None:
        ax[2].plot(mid, sp_["mean_strain_energy_J"], "o-")
        ax[2].set(xlabel="r / R", ylabel="mean segment strain energy (J)", title="strain energy in aggregates")
    else:
        ax[2].text(0.5, 0.5, "strain energy not logged", ha="center", transform=ax[2].transAxes)
        ax[2].set_axis_off()
    save(fig, "distributions")

    # 4. snapshot of the last frame with aggregates circled
    geo, aggs = s["_last"]
    L = geo.L
    fig, ax = plt.subplots(figsize=(8, 8 * L[1] / L[0] + 0.6), constrained_layout=True)
    shift = np.floor(geo.pos[:, :1] / L) * L
    p = geo.pos - shift
    segs = np.stack([p[:, :-1], p[:, 1:]], axis=2).reshape(-1, 2, 2)
    spd = (0.5 * (geo.pspeed[:, 1:] + geo.pspeed[:, :-1])).ravel()
    out = (segs < 0).any(axis=(1, 2)) | (segs >= L).any(axis=(1, 2))       # periodic copies of crossing segments
    if out.any():
        cs, cv = [segs], [spd]
        for ox in (-L[0], 0.0, L[0]):
            for oy in (-L[1], 0.0, L[1]):
                if ox or oy:
                    cs.append(segs[out] + np.array([ox, oy]))
                    cv.append(spd[out])
        segs, spd = np.concatenate(cs), np.concatenate(cv)
    lw = max(0.3, 8 * 72 * geo.W / L[0] * 0.8)
    lc = LineCollection(segs, array=spd, cmap="jet", norm=plt.Normalize(0, 4 * vb), linewidths=lw)
    ax.add_collection(lc)
    for a in aggs:
        c = a["centre_um"]
        for ox in (-L[0], 0, L[0]):
            for oy in (-L[1], 0, L[1]):
                ax.add_patch(plt.Circle((c[0] + ox, c[1] + oy), a["radius_um"], fill=False, ec="k", lw=1.2))
        ax.plot(*c, "k+", ms=8)
        ax.annotate(f"{a['edge_speed_vb']:.1f} v_b", (c[0] + 0.71 * a["radius_um"], c[1] + 0.71 * a["radius_um"]),
                    xytext=(2, 2), textcoords="offset points", fontsize=7)
    ax.set(xlim=(0, L[0]), ylim=(0, L[1]), aspect="equal", xlabel="x (µm)", ylabel="y (µm)",
           title=f"t = {geo.t_min:.0f} min: {len(aggs)} aggregates (circles: radius R, label: edge speed)")
    fig.colorbar(lc, ax=ax, orientation="horizontal", fraction=0.04, pad=0.06, label="segment speed (µm/min)")
    save(fig, "snapshot")
    if aggs:
        save(profile_figure(plt, aggs, vb, geo.t_min), "profiles")
    return files


def profile_figure(plt, aggs: list[dict], vb: float, t_min: float, most: int = 12):
    """Speed against radius, one panel per aggregate (the largest `most`): its particles, the rigid line ω r, one
    speed v_b and the rigidity exponent α with the verdict it gives (the one rigidity measure: aggregate_measure)."""
    aggs = sorted(aggs, key=lambda a: -a["n_cells"])[:most]
    nc = min(4, len(aggs))
    nr = -(-len(aggs) // nc)
    fig, axes = plt.subplots(nr, nc, figsize=(3.2 * nc, 2.8 * nr), constrained_layout=True, squeeze=False)
    for ax in axes.ravel()[len(aggs):]:
        ax.set_axis_off()
    for ax, a in zip(axes.ravel(), aggs):
        r, sp = a["_scatter"]
        ax.scatter(r, sp, s=2, alpha=0.4)
        rr = np.linspace(0, max(float(r.max()), a["radius_um"]), 30)
        ax.plot(rr, a["omega_fit_rad_per_min"] * rr, "r", lw=1, label="ω r (rigid)")
        ax.axhline(vb, color="k", ls=":", lw=1, label="v_b (one speed)")
        ax.axvline(a["radius_um"], color="g", ls="--", lw=1, label="R")
        al = a.get("rigidity_exponent")
        verdict = "n/a: too few radii" if al is None else ("rigid" if a["rigid"] else "not rigid")
        ax.set_title(f"{a['n_cells']} cells, α = {fmt(al)}: {verdict}\nedge {a['edge_speed_vb']:.2f} v_b, ω R "
                     f"{a['edge_speed_rigid_vb']:.2f} v_b", fontsize=8)
        ax.set(xlabel="r (µm)", ylabel="speed (µm/min)")
    axes.ravel()[0].legend(fontsize=6)
    fig.suptitle(f"speed against radius per aggregate, t = {t_min:.0f} min", fontsize=9)
    return fig
