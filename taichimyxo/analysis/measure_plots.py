"""The figures of the experimental measures (measures.py): the last frame with its director field and ±½ defects
(``<base>.defects.png``), and one panel each for defect counts, cluster sizes with their fits, correlation functions,
MSD and reversal intervals (``<base>.measures.png``). matplotlib is imported only when plots are asked for."""
from __future__ import annotations

import math
import textwrap

import numpy as np

from .defects import segments


def draw_defects(ax, last, every_node: int | None = None):
    """Cells (grey), director (black, length ∝ local order) and defects (+½ red circles, -½ blue triangles) of the
    last analysed frame, last = (CellGeometry, OrientationField, positions, charges), on ax."""
    from matplotlib.collections import LineCollection
    geo, field, dpos, dq = last
    every_node = every_node or max(1, min(field.q.shape) // 30)        # about 30 director lines across
    mid, vec = segments(geo.pos, geo.L)
    seg = np.stack([mid - 0.5 * vec, mid + 0.5 * vec], axis=1)
    ax.add_collection(LineCollection(seg, colors="0.65", linewidths=0.6))
    nodes = field.nodes()[::every_node, ::every_node].reshape(-1, 2)
    psi = field.psi[::every_node, ::every_node].reshape(-1)
    S = field.S[::every_node, ::every_node].reshape(-1)
    ok = np.isfinite(psi)
    half = 0.45 * every_node * float(field.h.min()) * np.nan_to_num(S[ok])
    d = np.stack([np.cos(psi[ok]), np.sin(psi[ok])], 1) * half[:, None]
    ax.add_collection(LineCollection(np.stack([nodes[ok] - d, nodes[ok] + d], 1), colors="k", linewidths=0.8))
    p, m = dq > 0, dq < 0
    ax.plot(dpos[p, 0], dpos[p, 1], "o", ms=7, mfc="none", mec="red", mew=2, label=f"+1/2 ({p.sum()})")
    ax.plot(dpos[m, 0], dpos[m, 1], "^", ms=7, mfc="none", mec="blue", mew=2, label=f"-1/2 ({m.sum()})")
    ax.set(xlim=(0, geo.L[0]), ylim=(0, geo.L[1]), aspect="equal", xlabel="x (µm)", ylabel="y (µm)",
           title=f"t = {geo.t_min:.1f} min: director and defects")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.8)


def write_measure_plots(ms: dict, last, base: str) -> list[str]:
    """Write <base>.defects.png (when a frame was analysed) and <base>.measures.png; return their paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter
    files = []
    if last is not None:
        fig, ax = plt.subplots(figsize=(7, 7), constrained_layout=True)
        draw_defects(ax, last)
        files.append(f"{base}.defects.png")
        fig.savefig(files[-1], dpi=80)
        plt.close(fig)
    fig, ax = plt.subplots(2, 3, figsize=(14, 8), constrained_layout=True)
    d = ms["defects"]
    ax[0, 0].plot(d["time_min"], d["n_plus_half"], "r", label="+1/2")
    ax[0, 0].plot(d["time_min"], d["n_minus_half"], "b", label="-1/2")
    ax[0, 0].set(xlabel="time (min)", ylabel="defects", title="defects per frame")
    ax[0, 0].legend(fontsize=8)
    _sizes_panel(ax[0, 1], ms["cluster_sizes"])
    a = ax[0, 2]
    for key, c in (("orientation_correlation", "C0"), ("velocity_correlation", "C1")):
        cf = ms.get(key)
        if not cf:
            continue
        r, C = np.asarray(cf["r_um"]), np.asarray(cf["C"], float)
        se = np.nan_to_num(np.asarray(cf["C_se"], float))
        ln = f"{cf['length_um']:.1f}" if cf["length_um"] is not None else f"> {r[-1]:.0f}"
        a.plot(r, C, c, label=f"{key.split('_')[0]} (ℓ = {ln} µm)")
        a.fill_between(r, C - se, C + se, color=c, alpha=0.3)
    a.axhline(math.exp(-1), color="k", ls=":", lw=0.8)
    a.set(xlabel="r (µm)", ylabel="C(r)", title="spatial correlations (± SE)")
    a.legend(fontsize=8)
    a = ax[1, 0]
    m = ms.get("msd")
    if m and m["lag_min"]:
        lag, y = np.asarray(m["lag_min"]), np.asarray(m["msd_um2"])
        a.errorbar(lag, y, yerr=np.nan_to_num(np.asarray(m["msd_se_um2"], float)), fmt="o", ms=3)
        if m["exponent"] is not None:
            f = lag <= m["fit_max_lag_min"]
            c = np.exp(np.mean(np.log(y[f]) - m["exponent"] * np.log(lag[f])))
            a.plot(lag[f], c * lag[f] ** m["exponent"], "k--",
                   label=f"slope {m['exponent']:.2f} ± {m['exponent_se'] or float('nan'):.2f}")
            a.legend(fontsize=8)
        a.set(xscale="log", yscale="log")
        a.xaxis.set_minor_formatter(NullFormatter())
    a.set(xlabel="lag (min)", ylabel="MSD (µm²)", title="mean-squared displacement of cell centres")
    a = ax[1, 1]
    ev = ms.get("events")
    if ev and ev["n_intervals"]:
        a.hist(ev["intervals_min"], bins=30, color="C2")
        fs = ev["fraction_suppressed"]
        a.set(title=f"reversal intervals ({ev['n_reversals']} reversals, "
                    f"{0 if fs is None else 100 * fs:.0f} % suppressed)")
    else:
        txt = "no event table" if not ev else (f"{ev['n_reversals']} reversals, {ev['n_suppressed']} suppressed:\n"
                                               f"no cell reversed twice")
        a.text(0.5, 0.5, f"no reversal intervals\n({txt})", ha="center", va="center", transform=a.transAxes)
    a.set(xlabel="interval (min)", ylabel="count")
    ax[1, 2].axis("off")
    skipped = ["skipped:"] + [textwrap.fill(s, 60) for s in ms.get("skipped", [])]
    ax[1, 2].text(0, 1, "\n".join(skipped) if len(skipped) > 1 else "every measure ran", va="top", fontsize=8)
    files.append(f"{base}.measures.png")
    fig.savefig(files[-1], dpi=75)
    plt.close(fig)
    return files


def _sizes_panel(a, cs):
    s, n = np.asarray(cs["sizes"], float), np.asarray(cs["counts"], float)
    if not len(s):
        return
    a.loglog(s, n / n.sum(), "o", ms=3, label="clusters")
    if cs.get("alpha") is not None:
        sg = np.arange(cs["s_min"], cs["s_max"] + 1, dtype=float)
        lam = 1.0 / cs["s_cut"] if cs["s_cut"] else 0.0
        pl = f"s^-{cs['alpha']:.2f}" + (f" e^(-s/{cs['s_cut']:.0f})" if cs["s_cut"] else "")
        for lp, lab, st in ((-cs["alpha"] * np.log(sg) - lam * sg, pl, "k-"),
                            (-cs["lam_exponential"] * sg, "exponential", "k:")):
            p = np.exp(lp - lp.max())
            p /= p.sum()
            keep = sg <= s.max()
            a.loglog(sg[keep], p[keep], st, label=lab)
    a.set(xlabel="cluster size s (cells)", ylabel="P(s)", ylim=(0.1 / max(n.sum(), 1), 1.5),
          title=f"cluster sizes: {cs.get('preferred') or 'no fit'}")
    a.legend(fontsize=8)
