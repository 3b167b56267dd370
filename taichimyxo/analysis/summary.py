"""A whole trajectory: per-frame clusters, order and aggregates, then the summary and its JSON file.

``predictions.verdict`` condenses the paper's predictions: rigid rotation (>= 50 % of aggregate-frames rigid), edge
faster than v_b (mean edge speed / v_b over tracks > 1.15), size-independent edge speed (|t| < 2 with >= 3 tracks).

Frames whose particle speeds are all zero (the first frame of a run, before the speed window has elapsed) count for
the cluster, order and aggregate-number time series but not for speeds, tracks or profiles (meta lists their times).

Also reported: cluster statistics and size distribution over time; mean speed; polar and nematic order (global, and
local = mean over touching pairs); speed histograms of cells inside and outside aggregates; speed and strain energy
profiles against r / R pooled over aggregates and frames (strain only when logged; strain inner (r < R/2) over outer).
"""
from __future__ import annotations

import json
import math
import os
import time
import warnings
from typing import Iterable

import numpy as np

from ..io.frame import Frame
from .aggregate_measure import RIGID_EXPONENT
from .aggregates import find_aggregates
from .cells import CellGeometry
from .clusters import cell_clusters, touches_own_tail
from .measure_plots import write_measure_plots
from .measures import Measures, finish_measures
from .params import PAPER, R_BINS, fill_cell_defaults, parameters
from .plots import write_plots
from .tracking import confirmed, lifetime_stats, link_tracks, public, size_regression, track_summaries


def json_clean(o):
    """JSON-safe: numpy to Python, non-finite floats to None."""
    if isinstance(o, dict):
        return {str(k): json_clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return json_clean(o.tolist())
    if isinstance(o, (np.bool_, bool)):
        return bool(o)
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        f = float(o)
        return float(f"{f:.7g}") if math.isfinite(f) else None
    return o


def _size_bins(n: int) -> np.ndarray:
    e = [1, 2]
    while e[-1] <= n:
        e.append(2 * e[-1] - 1)       # 1, 2, 3, 5, 9, 17, ... (bins [1], [2], [3,4], [5,8], ...)
    return np.array(e)


def detected_aggregates(frames: Iterable[Frame], v_b: float, P: dict):
    """Per frame (CellGeometry, clusters, aggregates): the circulating groups find_aggregates finds that are also
    seen in the previous or the next frame (tracking.confirmed; all of them with ``confirm_by_neighbours`` False).
    Reads one frame ahead."""
    prev = held = None
    for fr in frames:
        geo = CellGeometry(fr)
        if held is None and prev is None:
            fill_cell_defaults(P, geo)
        cl = cell_clusters(geo.pos, geo.L, geo.W, P["contact_tol_um"])
        cur = (geo, cl, find_aggregates(geo, cl, v_b=v_b, **P))
        if held is not None:
            yield _confirm(held, [x[2] for x in (prev, cur) if x is not None], P)
            prev = held
        held = cur
    if held is not None:
        yield _confirm(held, [prev[2]] if prev is not None else [], P)


def _confirm(item, neighbours, P):
    geo, cl, aggs = item
    if P["confirm_by_neighbours"]:
        aggs = confirmed(aggs, neighbours, P["link_overlap"], P["link_min_shared"])
    return geo, cl, aggs


def analyze_frames(frames: Iterable[Frame], v_b: float = 4.0, measures=None, **params) -> dict:
    """Analyse an iterable of Frames (see the module docstring). Returns the summary dict (JSON-ready after
    json_clean); private keys starting with '_' carry data for the plots. measures: a measures.Measures that is
    fed every frame (its geometry and cluster sizes)."""
    P = parameters(**params)
    t0 = time.perf_counter()
    ts = dict(time_min=[], mean_speed_um_per_min=[], polar_order=[], nematic_order=[], local_polar_order=[],
              local_nematic_order=[], n_clusters=[], largest_cluster=[], mean_cluster_size_weighted=[],
              fraction_in_clusters=[], n_aggregates=[], fraction_in_aggregates=[], free_cell_speed_um_per_min=[],
              free_cell_speed_along_um_per_min=[],
              n_free_cells=[], speed_p95_um_per_min=[], strain_inside_aggregates_J=[],
              strain_outside_aggregates_J=[])
    per_frame: list[list[dict]] = []
    size_dist = []
    hist_edges = np.arange(0.0, P["speed_hist_max"] + 1e-9, P["speed_hist_bin"])
    h_in = np.zeros(len(hist_edges) - 1)
    h_out = np.zeros(len(hist_edges) - 1)
    s_io = np.zeros(2)          # exact speed sums inside / outside
    no_speed: list[float] = []  # times of frames without logged speeds
    sprof = [np.zeros(len(R_BINS) - 1), np.zeros(len(R_BINS) - 1)]
    eprof = [np.zeros(len(R_BINS) - 1), np.zeros(len(R_BINS) - 1)]
    have_strain = False
    meta = None
    last_geo = None
    last_agg_frame = None
    for geo, (lab, sizes, ci, cj), aggs in detected_aggregates(frames, v_b, P):
        if meta is None:
            meta = dict(n_cells=geo.n, particles_per_cell=geo.N, box_um=[float(geo.L[0]), float(geo.L[1])],
                        width_um=geo.W, cell_length_um=geo.cell_len)
            sbins = _size_bins(geo.n)
        # time series
        ts["time_min"].append(geo.t_min)
        ts["mean_speed_um_per_min"].append(float(geo.cspeed.mean()))
        hd = geo.head
        ts["polar_order"].append(float(np.hypot(*hd.mean(0))))
        th = np.arctan2(hd[:, 1], hd[:, 0])
        ts["nematic_order"].append(float(np.abs(np.exp(2j * th).mean())))
        if len(ci):
            cdot = (hd[ci] * hd[cj]).sum(1)
            ts["local_polar_order"].append(float(cdot.mean()))
            ts["local_nematic_order"].append(float((2 * cdot * cdot - 1).mean()))
        else:
            ts["local_polar_order"].append(float("nan"))
            ts["local_nematic_order"].append(float("nan"))
        if measures is not None:
            measures.add(geo, sizes)
        csize = sizes[lab]
        ts["n_clusters"].append(int((sizes >= 2).sum()))
        ts["largest_cluster"].append(int(sizes.max()))
        ts["mean_cluster_size_weighted"].append(float(csize.mean()))
        ts["fraction_in_clusters"].append(float((csize >= 2).mean()))
        size_dist.append(np.histogram(sizes, bins=sbins, weights=sizes)[0] / geo.n)
        inside = np.zeros(geo.n, bool)
        for a in aggs:
            inside[a["_members"]] = True
        ts["n_aggregates"].append(len(aggs))
        ts["fraction_in_aggregates"].append(float(inside.mean()))
        if geo.strain is not None:
            # mean segment strain energy (J) of cells in aggregates and of the others
            e = geo.strain.mean(axis=1)
            ts["strain_inside_aggregates_J"].append(float(e[inside].mean()) if inside.any() else float("nan"))
            ts["strain_outside_aggregates_J"].append(float(e[~inside].mean()) if (~inside).any() else float("nan"))
        free = (csize == 1) & ~touches_own_tail(geo.pos, geo.W, P["contact_tol_um"])
        ts["n_free_cells"].append(int(free.sum()))
        last_geo = (geo, aggs)
        if not np.any(geo.pspeed > 0):
            # no speeds yet (the first frame of a run: the speed window has not elapsed): geometry only
            no_speed.append(geo.t_min)
            per_frame.append(None)
            ts["free_cell_speed_um_per_min"].append(float("nan"))
            ts["free_cell_speed_along_um_per_min"].append(float("nan"))
            ts["speed_p95_um_per_min"].append(float("nan"))
            continue
        # free cells: touching no other cell (clusters of one) nor their own tail
        ts["free_cell_speed_um_per_min"].append(float(geo.cspeed[free].mean()) if free.any() else float("nan"))
        # the part of it along each particle's own forward tangent: a force across the body (slime steering the
        # head) moves particles sideways without changing this part (docs/measures.md, free cells)
        ts["free_cell_speed_along_um_per_min"].append(
            float((geo.vel[free] * geo.ptan[free]).sum(-1).mean()) if free.any() else float("nan"))
        ts["speed_p95_um_per_min"].append(float(np.percentile(geo.cspeed, 95.0)))
        for a in aggs:
            sprof[0] += a["_speed_prof"][0]
            sprof[1] += a["_speed_prof"][1]
            if "_strain_prof" in a:
                have_strain = True
                eprof[0] += a["_strain_prof"][0]
                eprof[1] += a["_strain_prof"][1]
        sp = np.clip(geo.cspeed, 0, hist_edges[-1] - 1e-9)
        h_in += np.histogram(sp[inside], bins=hist_edges)[0]
        h_out += np.histogram(sp[~inside], bins=hist_edges)[0]
        s_io += (geo.cspeed[inside].sum(), geo.cspeed[~inside].sum())
        per_frame.append(aggs)
        if aggs:
            last_agg_frame = (geo, aggs)
    if meta is None:
        raise ValueError("no frames to analyse")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)      # NaN means/medians of empty or all-NaN lists
        summary = _summarise(P, v_b, t0, ts, per_frame, size_dist, sbins, hist_edges, h_in, h_out, s_io, sprof,
                             eprof, have_strain, meta, last_agg_frame)
    summary["meta"]["frames_without_speed_min"] = no_speed
    summary["_last"] = last_geo
    summary["_last_agg"] = last_agg_frame
    return summary


def _summarise(P, v_b, t0, ts, per_frame, size_dist, sbins, hist_edges, h_in, h_out, s_io, sprof, eprof, have_strain,
               meta, last_agg_frame):
    n_fr = len(per_frame)
    np.array(meta["box_um"])
    min_tf = min(P["min_track_frames"], n_fr)
    tracks, events = link_tracks(per_frame, ts["time_min"], P["max_gap_frames"], P["link_overlap"],
                                 P["link_min_shared"])
    track_out = track_summaries(tracks, min_tf, P["stable_lifetime_min"])
    lifetimes = lifetime_stats(track_out, events, P["stable_lifetime_min"])
    stable = [t for t in track_out if t["stable"]]
    final = last_agg_frame[1] if last_agg_frame else []
    all_aggs = [a for fa in per_frame if fa for a in fa]
    r2v = [a["rotation_fit"]["r2"] for a in all_aggs if a.get("rotation_fit")]
    alphas = [a["rigidity_exponent"] for a in all_aggs if a.get("rigidity_exponent") is not None]
    ratio = [a["omega_fit_over_omega_tan"] for a in all_aggs]
    predictions = dict(
        paper=PAPER,
        v_b_um_per_min=v_b,
        edge_speed_vb_per_track=[t["mean_edge_speed_vb"] for t in stable],
        edge_speed_vb_mean=float(np.mean([t["mean_edge_speed_vb"] for t in stable])) if stable else None,
        edge_speed_vb_final=[a["edge_speed_vb"] for a in final],
        edge_speed_vs_radius_tracks=size_regression([t["mean_radius_um"] for t in stable],
                                                    [t["mean_edge_speed_um_per_min"] for t in stable]),
        edge_speed_vs_radius_final=size_regression([a["radius_um"] for a in final],
                                                   [a["edge_speed_um_per_min"] for a in final]),
        rigid_rotation=dict(
            n_aggregate_frames=len(all_aggs),
            # the one rigidity measure (aggregate_measure.rigidity_exponent), over the aggregate-frames it can judge
            measure="rigidity exponent: slope of ln(speed) against ln(r); rigid when >= 0.5",
            n_measurable=len(alphas),
            rigidity_exponent_median=float(np.median(alphas)) if alphas else None,
            rigidity_exponent_quartiles=[float(np.percentile(alphas, 25)), float(np.percentile(alphas, 75))]
            if alphas else None,
            fraction_rigid=float(np.mean([a >= RIGID_EXPONENT for a in alphas])) if alphas else None,
            r2_origin_median=float(np.nanmedian([a["r2_origin"] for a in all_aggs])) if all_aggs else None,
            r2_linear_median=float(np.nanmedian([a["linear_fit"]["r2"] for a in all_aggs])) if all_aggs else None,
            omega_fit_over_omega_tan_median=float(np.nanmedian(ratio)) if all_aggs else None,
            speed_grows_with_radius_fraction=float(np.mean([a["linear_fit"]["slope"] > 0 for a in all_aggs]))
            if all_aggs else None,
            rotation_fit_r2_median=float(np.nanmedian(r2v)) if r2v else None,
            rotation_fit_r2_quartiles=[float(np.nanpercentile(r2v, 25)), float(np.nanpercentile(r2v, 75))]
            if r2v else None,
            n_rotation_fits=len(r2v),
        ),
    )
    reg = predictions["edge_speed_vs_radius_tracks"]
    rr = predictions["rigid_rotation"]
    em = predictions["edge_speed_vb_mean"]
    predictions["verdict"] = dict(
        criteria="aggregates: stable tracks (>= min_track_frames); rigid: half or more of the measurable "
                 "aggregate-frames have a rigidity exponent >= 0.5 (the median >= 0.5); "
                 "edge faster than v_b: mean edge speed / v_b over tracks > 1.15; size-independent: |t| of the edge "
                 "speed vs radius slope < 2 (needs >= 3 tracks)",
        n_stable_aggregates=len(stable),
        rigid_rotation=(rr["fraction_rigid"] >= 0.5) if rr["fraction_rigid"] is not None else None,
        edge_faster_than_v_b=(em > 1.15) if em is not None else None,
        edge_speed_size_independent=reg["consistent_with_zero"] if reg["n_aggregates"] >= 3 else None,
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        speed_prof = dict(r_over_R_edges=R_BINS, mean_speed_vb=sprof[0] / sprof[1], n_particles=sprof[1])
        strain_prof = dict(r_over_R_edges=R_BINS, mean_strain_energy_J=eprof[0] / eprof[1], n_segments=eprof[1]) \
            if have_strain else None
    if strain_prof is not None:
        s, c = eprof
        inner = s[R_BINS[:-1] < 0.5].sum() / max(c[R_BINS[:-1] < 0.5].sum(), 1)
        outer = s[(R_BINS[:-1] >= 0.5) & (R_BINS[1:] <= 1.0 + 1e-9)].sum() / \
            max(c[(R_BINS[:-1] >= 0.5) & (R_BINS[1:] <= 1.0 + 1e-9)].sum(), 1)
        strain_prof["inner_over_outer"] = inner / outer if outer > 0 else float("nan")
        strain_prof["highest_toward_centre"] = bool(inner > outer) if outer > 0 else None
    summary = dict(
        meta=dict(meta, n_frames_analyzed=n_fr, v_b_um_per_min=v_b,
                  time_range_min=[ts["time_min"][0], ts["time_min"][-1]]),
        parameters=P,
        n_aggregates_final=len(final),
        min_track_frames_effective=min_tf,
        final_time_min=(last_agg_frame[0].t_min if last_agg_frame else None),
        aggregates_final=[public(a) for a in final],
        tracks=track_out,
        events=events,
        lifetimes=lifetimes,
        predictions=predictions,
        timeseries=ts,
        cluster_size_distribution=dict(size_bin_edges=sbins, fraction_of_cells=np.array(size_dist),
                                       note="row per analysed frame; column b: fraction of cells in clusters of "
                                            "size in [edges[b], edges[b+1])"),
        speed_histograms=dict(bin_edges_um_per_min=hist_edges, inside_aggregates=h_in, outside_aggregates=h_out,
                              mean_inside=float(s_io[0] / h_in.sum()) if h_in.sum() else None,
                              mean_outside=float(s_io[1] / h_out.sum()) if h_out.sum() else None,
                              note="cell speeds (mean of its particles), counts over all analysed frames; "
                                   "speeds above the last edge are counted in the last bin"),
        speed_profile=speed_prof,
        strain_profile=strain_prof,
        analysis_seconds=time.perf_counter() - t0,
    )
    return summary


def analyze(gsd_path: str, out_dir: str | None = None, every: int = 1, v_b: float | None = None,
            plots: bool = True, measures: bool = False, measure_params: dict | None = None, **params) -> dict:
    """Analyse a trajectory; write <stem>.analysis.json (and PNG plots) next to it or in out_dir. Returns the summary
    (JSON-clean). v_b: free-cell speed in µm/min; default from the stored scene (cell.speed_um_per_min) or 4.
    measures: also the experimental measures (measures.py: defects, cluster sizes, correlations, MSD, events)."""
    from ..io.trajectory import read_frames, read_scene
    t0 = time.perf_counter()
    scene = read_scene(gsd_path)
    if v_b is None:
        v_b = float((scene.get("cell") or {}).get("speed_um_per_min", 4.0) or 4.0)
    acc = Measures(**(measure_params or {})) if measures else None
    s = analyze_frames(read_frames(gsd_path, every=every), v_b=v_b, measures=acc, **params)
    if acc is not None:
        s["measures"] = finish_measures(acc, gsd_path)
    out_dir = out_dir or os.path.dirname(os.path.abspath(gsd_path))
    os.makedirs(out_dir, exist_ok=True)
    stem = os.path.splitext(os.path.basename(gsd_path))[0]
    s["meta"].update(trajectory=os.path.abspath(gsd_path), every=every, scene_name=scene.get("name"))
    files = []
    if plots:
        files = write_plots(s, os.path.join(out_dir, stem + ".analysis"))
        if acc is not None:
            files += write_measure_plots(s["measures"], acc.last, os.path.join(out_dir, stem + ".analysis"))
    s["plots"] = files
    s["total_seconds"] = time.perf_counter() - t0
    clean = json_clean({k: v for k, v in s.items() if not k.startswith("_")})
    path = os.path.join(out_dir, stem + ".analysis.json")
    with open(path, "w") as f:
        json.dump(clean, f, indent=1)
    clean["json"] = path
    return clean
