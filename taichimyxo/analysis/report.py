"""The short human-readable report of a summary (what `python -m taichimyxo analyze` prints)."""
from __future__ import annotations

import math


def fmt(x, spec=".2f"):
    """x formatted with spec, or "n/a" when it is missing or not finite."""
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def _rigid(a: dict) -> str:
    """The aggregate's verdict by its rigidity exponent (n/a: its particles span too few radii to judge)."""
    if a.get("rigidity_exponent") is None:
        return "n/a"
    return "yes" if a["rigid"] else "no"


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
        lines.append("    centre (µm)        R (µm)  cells  ω (rad/min)  edge (µm/min)  edge/v_b  α(v~r^α)  rigid")
        for a in sorted(fin, key=lambda a: -a["n_cells"]):
            c = a["centre_um"]
            lines.append(f"  ({c[0]:7.1f}, {c[1]:7.1f})  {a['radius_um']:6.1f}  {a['n_cells']:5d}  "
                         f"{fmt(a['omega_rad_per_min'], '+8.3f')}     {fmt(a['edge_speed_um_per_min'], '6.2f')}"
                         f"        {fmt(a['edge_speed_vb'], '5.2f')}    {fmt(a.get('rigidity_exponent'), '5.2f')}    "
                         f"{_rigid(a)}")
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
        q = rr.get("rigidity_exponent_quartiles") or [None, None]
        lines.append(f"rigid rotation (rigidity exponent α: speed ~ r^α over an aggregate; 1 rigid, 0 one speed; "
                     f"rigid when α >= 0.5): median α {fmt(rr.get('rigidity_exponent_median'))} (quartiles "
                     f"{fmt(q[0])}-{fmt(q[1])}), {fmt(_pct(rr.get('fraction_rigid')), '.0f')} % rigid, over "
                     f"{rr.get('n_measurable', 0)} of {rr['n_aggregate_frames']} aggregate-frames (the others span "
                     f"too few radii to judge)")
    sh = summary["speed_histograms"]
    if sh["mean_inside"] is not None:
        lines.append(f"mean cell speed inside aggregates {sh['mean_inside']:.2f}, outside "
                     f"{fmt(sh['mean_outside'], '.2f')} µm/min")
    sp = summary.get("strain_profile")
    if sp:
        lines.append(f"strain energy inner (r < R/2) / outer: {fmt(sp['inner_over_outer'], '.2f')}")
    if summary.get("measures"):
        lines.extend(format_measures(summary["measures"]))
    if "analysis_seconds" in summary:
        lines.append(f"analysis took {summary.get('total_seconds', summary['analysis_seconds']):.1f} s")
    return "\n".join(lines)


def _mean(x):
    return sum(x) / len(x) if len(x) else float("nan")


def format_measures(ms: dict) -> list[str]:
    """The lines of the experimental measures (analysis/measures.py) in the analyze report."""
    lines = []
    d = ms["defects"]
    if d["time_min"]:
        lines.append(f"defects (Q field, grid {d['spacing_um']:g}, smoothing {d['smoothing_um']:g} µm): last frame "
                     f"{d['n_plus_half'][-1]} +1/2, {d['n_minus_half'][-1]} -1/2; mean per frame "
                     f"{_mean(d['n_plus_half']):.1f} +1/2, {_mean(d['n_minus_half']):.1f} -1/2; {d['n_tracks']} "
                     f"tracks, median lifetime {fmt(d['track_lifetime_min_median'], '.1f')} min")
    cs = ms["cluster_sizes"]
    if cs.get("alpha") is None:
        lines.append(f"cluster sizes: {cs['n_clusters']} clusters of {len(cs['sizes'])} size(s): too few sizes to fit")
    else:
        ci = cs.get("alpha_ci95") or [None, None]
        sc = fmt(cs["s_cut"], ".1f") if cs["s_cut"] else "none (pure power law)"
        lines.append(f"cluster sizes ({cs['n_clusters']} clusters): P(s) ~ s^-a exp(-s/s_c), a = {cs['alpha']:.2f} "
                     f"[{fmt(ci[0])}, {fmt(ci[1])}], s_c = {sc}; exponential p = "
                     f"{cs['p_exponential']:.2g}; preferred: {cs['preferred']}")
    for key, name in (("orientation_correlation", "orientation"), ("velocity_correlation", "velocity")):
        c = ms.get(key)
        if c:
            ln = fmt(c["length_um"], ".1f") if c["length_um"] is not None else f"> {c['r_um'][-1]:.0f}"
            lines.append(f"{name} correlation length {ln} µm (per-frame mean "
                         f"{fmt(c['length_frame_mean_um'], '.1f')} ± {fmt(c['length_se_um'], '.1f')} over the "
                         f"{c['n_frames_with_length']} of {c['n_frames']} frames where C falls below 1/e)")
    m = ms.get("msd")
    if m and m.get("exponent") is not None:
        lines.append(f"MSD exponent {m['exponent']:.2f} ± {fmt(m['exponent_se'], '.2f')} (lags up to "
                     f"{m['fit_max_lag_min']:.0f} min)")
    ev = ms.get("events")
    if ev and not ev["n_reversals"] + ev["n_suppressed"]:
        lines.append(f"no reversals logged; guiding links formed {ev['n_links_formed']}, broken "
                     f"{ev['n_links_broken']}, median duration {fmt(ev['link_duration_median_min'], '.2f')} min")
    elif ev:
        lines.append(f"reversals: {ev['n_reversals']}, interval median {fmt(ev['interval_median_min'], '.1f')} min "
                     f"(mean {fmt(ev['interval_mean_min'], '.1f')}, CV {fmt(ev['interval_cv'])}); "
                     f"{fmt(None if ev['fraction_suppressed'] is None else 100 * ev['fraction_suppressed'], '.0f')} % "
                     f"of due reversals suppressed; guiding links formed {ev['n_links_formed']}, broken "
                     f"{ev['n_links_broken']}")
    lines.extend(f"skipped: {s}" for s in ms.get("skipped", []))
    return lines
