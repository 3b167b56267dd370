"""Measures on centroid tracks (taichimyxo.io.tracks: a lab's, or a simulation's cells through ``from_frames``), the
same code for both: speeds between successive points, their distribution, and direction reversals with the run
durations between them.

A centroid track has no poles, so a reversal is read from the velocity: the direction of motion over a window of
``window`` steps turning by more than ``reversal_deg`` to the next window's, with the cell moving in both (speed
above ``min_speed_vb`` v_b). What needs a cell's orientation or poles (which end leads, head-to-tail contacts) is
not measurable from centroids."""
from __future__ import annotations

import numpy as np


def step_speeds(tracks) -> np.ndarray:
    """Every step's speed, µm/min, over all tracks."""
    out = [np.linalg.norm(np.diff(xy, axis=0), axis=1) / np.diff(t) * 60.0 for t, xy in tracks.tracks if len(t) > 1]
    return np.concatenate(out) if out else np.zeros(0)


def speed_distribution(tracks, v_b: float = 4.0, bins=np.arange(0.0, 6.01, 0.25)) -> dict:
    """Histogram of step speeds / v_b (density), with the mean, median and 95th percentile."""
    s = step_speeds(tracks) / v_b
    h, edges = np.histogram(s, bins=bins, density=True)
    q = np.percentile(s, [50, 95]) if len(s) else [np.nan, np.nan]
    return {"edges_vb": edges.tolist(), "density": h.tolist(), "mean_vb": float(s.mean()) if len(s) else np.nan,
            "median_vb": float(q[0]), "p95_vb": float(q[1]), "steps": int(len(s))}


def reversals(tracks, window: int = 2, reversal_deg: float = 150.0, min_speed_vb: float = 0.3,
              v_b: float = 4.0) -> dict:
    """Direction reversals per track (times, s) and the run durations between successive reversals of one track
    (s); the rate per cell-hour over the time the tracks span."""
    cos_max = np.cos(np.radians(reversal_deg))
    times, runs, span = [], [], 0.0
    for t, xy in tracks.tracks:
        if len(t) < 2 * window + 1:
            continue
        span += t[-1] - t[0]
        d = xy[window:] - xy[:-window]                       # displacement over `window` steps, ending at i + window
        dt = t[window:] - t[:-window]
        v = np.linalg.norm(d, axis=1) / dt * 60.0
        mine = []
        i = 0
        while i + window < len(d):
            a, b = d[i], d[i + window]                       # two windows meeting at point i + window
            moving = v[i] > min_speed_vb * v_b and v[i + window] > min_speed_vb * v_b
            if moving and np.dot(a, b) < cos_max * np.linalg.norm(a) * np.linalg.norm(b):
                mine.append(float(t[i + window]))
                i += window                                  # one reversal counted once
            i += 1
        times.append(mine)
        runs += list(np.diff(mine))
    n = sum(len(m) for m in times)
    return {"reversals": n, "per_cell_hour": n / (span / 3600.0) if span > 0 else np.nan,
            "run_durations_s": runs, "mean_run_s": float(np.mean(runs)) if runs else np.nan, "times_s": times}


def degrade(tracks, seed: int = 0, frame_s: float | None = None, noise_um: float = 0.0, missed: float = 0.0,
            swaps_per_track_hour: float = 0.0, **reading):
    """Tracks as a microscope and a tracker would give them (benchmarks/tracks_validation.py): resampled to frame_s,
    Gaussian position noise of noise_um per axis, a fraction `missed` of detections lost, and identity swaps (at a
    random time two tracks near each other exchange their ids from then on, swaps_per_track_hour per track-hour).
    The result is read back through the lab's path (taichimyxo.io.tracks.assemble: gaps split, jumps cut, counted),
    so a degraded simulation meets what a lab's tracks meet. reading: assemble's options."""
    from ..io.tracks import assemble
    from .track_groups import resample
    rng = np.random.default_rng(seed)
    tr = resample(tracks, frame_s) if frame_s else tracks
    ids = np.concatenate([np.full(len(t), k) for k, (t, _) in enumerate(tr.tracks)])
    ts = np.concatenate([t for t, _ in tr.tracks])
    xy = np.concatenate([p for _, p in tr.tracks]) + rng.normal(0.0, noise_um, (len(ts), 2)) if noise_um else \
        np.concatenate([p for _, p in tr.tracks])
    hours = sum(t[-1] - t[0] for t, _ in tr.tracks) / 3600.0
    for _ in range(rng.poisson(swaps_per_track_hour * hours) if swaps_per_track_hour > 0 else 0):
        t0 = rng.choice(ts)
        now = np.flatnonzero(ts == t0)
        a = rng.choice(now)
        d = np.linalg.norm(xy[now] - xy[a], axis=1)
        d[now == a] = np.inf
        b = now[int(np.argmin(d))]
        ia, ib = ids[a], ids[b]
        later = ts >= t0
        sa, sb = later & (ids == ia), later & (ids == ib)
        ids[sa], ids[sb] = ib, ia
    keep = rng.random(len(ts)) >= missed
    return assemble(ids[keep], ts[keep], xy[keep], tr.frame_s, source=f"{tracks.source} (degraded)",
                    box=tracks.box, **reading)
