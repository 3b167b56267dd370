"""The short human-readable report of a summary (what `python -m taichimyxo analyze` prints)."""
from __future__ import annotations

import math


def fmt(x, spec=".2f"):
    """x formatted with spec, or "n/a" when it is missing or not finite."""
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def _fit_r2(a: dict):
    """R² of the aggregate's fit of v = ω × (r − c) to its particle velocities (None without velocities)."""
    return (a.get("rotation_fit") or {}).get("r2")


def _pct(x):
    return None if x is None else 100.0 * x


def format_summary(summary: dict) -> str:
    """Short human-readable report of an analyze() summary."""
    m = summary["meta"]
    vb = m["v_b_um_per_min"]
    lines = [f"{m.get('trajectory', 'trajectory')}: {m['n_cells']} cells, box {m['box_um'][0]:g} x "
             f"{m['box_um'][1]:g} µm, {m['n_frames_analyzed']} frames, t = {m['time_range_min'][0]:.1f}-"
             f"{m['time_range_min'][1]:.1f} min, v_b = {vb:g} µm/min"]
    ts = summary["timeseries"]
    if ts["time_min"]:
        lines.append(f"last frame: mean speed {ts['mean_speed_um_per_min'][-1]:.2f} µm/min, "
                     f"{ts['fraction_in_clusters'][-1] * 100:.0f} % of cells in clusters (largest "
                     f"{ts['largest_cluster'][-1]}), {ts['fraction_in_aggregates'][-1] * 100:.0f} % in aggregates, "
                     f"nematic order {ts['nematic_order'][-1]:.2f} (local {fmt(ts['local_nematic_order'][-1])})")
    fin = summary["aggregates_final"]
    t = summary.get("final_time_min")
    lines.append(f"{len(fin)} rotating aggregate(s)" + (f" at t = {t:.1f} min" if t is not None else ""))
    if fin:
        lines.append("    centre (µm)        R (µm)  cells  ω (rad/min)  edge (µm/min)  edge/v_b  R²(fit)  rigid")
        for a in sorted(fin, key=lambda a: -a["n_cells"]):
            c = a["centre_um"]
            lines.append(f"  ({c[0]:7.1f}, {c[1]:7.1f})  {a['radius_um']:6.1f}  {a['n_cells']:5d}  "
                         f"{fmt(a['omega_rad_per_min'], '+8.3f')}     {fmt(a['edge_speed_um_per_min'], '6.2f')}"
                         f"        {fmt(a['edge_speed_vb'], '5.2f')}    {fmt(_fit_r2(a), '5.2f')}   "
                         f"{'yes' if a['rigid'] else 'no'}")
    pr = summary["predictions"]
    st = [tr for tr in summary["tracks"] if tr["stable"]]
    lines.append(f"{len(summary['tracks'])} aggregate track(s), {len(st)} seen in >= "
                 f"{summary.get('min_track_frames_effective', summary['parameters']['min_track_frames'])} frame(s)")
    lt = summary.get("lifetimes")
    if lt and lt["n_tracks"]:
        ev = lt["events"]
        lines.append(f"tracks by shared cells: {ev['birth']} birth(s), {ev['merge']} merge(s), {ev['split']} split(s), "
                     f"{ev['dispersal']} dispersal(s); lifetime median {fmt(lt['median_lifetime_min'], '.0f')}, "
                     f"longest {fmt(lt['max_lifetime_min'], '.0f')} min; "
                     f"{fmt(_pct(lt['fraction_aggregate_frames_long_lived']), '.0f')} % of aggregate-frames in tracks "
                     f"living >= {lt['stable_lifetime_min']:g} min")
    if pr.get("edge_speed_vb_mean") is not None:
        lines.append(f"edge speed / v_b over tracks: mean {pr['edge_speed_vb_mean']:.2f} "
                     f"(paper: adhesion 1.33, active following up to 4, slime trails ~1)")
    reg = pr["edge_speed_vs_radius_tracks"]
    if reg["n_aggregates"] >= 3 and reg["stderr"] is not None:
        lines.append(f"edge speed vs radius: slope {fmt(reg['slope_um_per_min_per_um'], '.3f')} ± "
                     f"{fmt(reg['stderr'], '.3f')} µm/min per µm (t = {fmt(reg['t'], '.1f')}; "
                     f"{'consistent' if reg['consistent_with_zero'] else 'NOT consistent'} with size-independence), "
                     f"log-log exponent {fmt(reg['loglog_exponent'], '.2f')}")
    rr = pr["rigid_rotation"]
    if rr["n_aggregate_frames"]:
        q = rr.get("rotation_fit_r2_quartiles") or [None, None]
        lines.append(f"rigid rotation: median R² of the fit v = ω × (r − c) {fmt(rr.get('rotation_fit_r2_median'))} "
                     f"(quartiles {fmt(q[0])}-{fmt(q[1])}, {rr.get('n_rotation_fits', 0)} aggregate-frames); "
                     f"{rr['fraction_rigid'] * 100:.0f} % rigid by speed ∝ r, median ω_fit/ω_tan "
                     f"{fmt(rr['omega_fit_over_omega_tan_median'], '.2f')}")
    sh = summary["speed_histograms"]
    if sh["mean_inside"] is not None:
        lines.append(f"mean cell speed inside aggregates {sh['mean_inside']:.2f}, outside "
                     f"{fmt(sh['mean_outside'], '.2f')} µm/min")
    sp = summary.get("strain_profile")
    if sp:
        lines.append(f"strain energy inner (r < R/2) / outer: {fmt(sp['inner_over_outer'], '.2f')}")
    if "analysis_seconds" in summary:
        lines.append(f"analysis took {summary.get('total_seconds', summary['analysis_seconds']):.1f} s")
    return "\n".join(lines)
