"""Rotating groups found from centroid tracks alone (a lab's, or a simulation's through ``from_frames``), and the
speeds inside and outside them: the measures of the paper's proposed experiment (docs/lab-tracks.md).

A centroid has no orientation, so a group is read from the motion (docs/measures.md gives why each step reads the
paper's "circular aggregates"):

1. Each point of a track gets the circle its last and next points lie on: a least-squares circle through the points
   of a window centred on it. The window is the time the tracks' median cell takes to glide ``window_path_um`` (four
   cell lengths; ``window_min`` fixes it instead): a length, not a time, so that slow cells in large aggregates
   (a lab's, at 0.7 µm/min) and fast ones in small aggregates (the simulations', at 4 µm/min) are read alike. The
   point is *circling* when the cell moves (mean speed over the window >= ``min_speed_um_per_min``), the circle is
   not a straight path (radius <= ``max_radius_um``), the window sweeps at least ``min_sweep_deg`` around it, and
   steadily (the signed sweep is at least ``min_steady`` of the steps' sizes summed: a cell jittering in a jam
   turns both ways); its sense is the sign of the swept angle.
2. In one frame, circling points that turn the same way about centres closer than ``centre_tol_um`` or
   ``centre_tol_rel`` of the smaller radius (a large circle's centre is known less well) are linked; a connected set
   of at least ``min_tracks`` of them is a group when its members surround the common centre (the largest angular
   gap between them <= 360 - ``min_cover_deg``: a ring, not a bend of a stream).
3. A group must be seen again in the previous or the next frame, sharing at least two tracks (a curl seen once is
   not an aggregate; taichimyxo.analysis.tracking.confirmed, the same rule as the aggregate finder's).
4. Every point of the frame within the group's radius (its farthest circling member's distance from the centre) is
   in the group, the non-circling ones included (a jammed core turns slowly, and belongs to the aggregate's speeds).

Speeds are the path speed through a point (its two steps over their time), µm/min. They are chords: at a frame
interval where a cell turns by a large angle per frame they read low, the same for measured and simulated tracks when
both are taken at one frame interval (``resample``); the mechanism report does so.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .tracking import confirmed

DEFAULTS = dict(window_path_um=20.0, window_min=None, min_speed_um_per_min=0.2, max_radius_um=60.0,
                min_sweep_deg=20.0, min_steady=0.8, centre_tol_um=2.5, centre_tol_rel=0.25, min_tracks=4,
                min_cover_deg=180.0)


def window_minutes(tracks, P: dict) -> float:
    """The window of step 1, minutes: window_min when given, else window_path_um at the tracks' median speed."""
    if P.get("window_min"):
        return float(P["window_min"])
    sp = [np.linalg.norm(np.diff(xy, axis=0), axis=1) / np.diff(t) for t, xy in tracks.tracks if len(t) > 1]
    v = float(np.median(np.concatenate(sp))) * 60.0 if sp else 0.0
    return P["window_path_um"] / v if v > 0 else 4.0


@dataclass
class TrackPoints:
    """One row per interior point of every track: its track, frame, time (s), position (µm), path speed (µm/min),
    the centre and radius of its circle (NaN where the point is not circling), sense (+1 counter-clockwise, -1
    clockwise, 0 not circling), straightness over the window (net displacement / path, NaN at a track's ends);
    ``group`` (-1 outside every group) and distance from the group's centre over its radius, filled by
    :func:`find_groups`."""
    track: np.ndarray
    frame: np.ndarray
    t: np.ndarray
    xy: np.ndarray
    speed: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    sense: np.ndarray
    straight: np.ndarray
    group: np.ndarray
    r_over_R: np.ndarray


def resample(tracks, frame_s: float):
    """The tracks at a longer frame interval: every k-th point of each track, k = frame_s / its interval (rounded);
    the same tracks when frame_s is not longer."""
    from dataclasses import replace
    k = int(round(frame_s / tracks.frame_s)) if tracks.frame_s > 0 else 1
    if k <= 1:
        return tracks
    kept = [(t[::k], xy[::k]) for t, xy in tracks.tracks if len(t[::k]) >= 3]
    return replace(tracks, tracks=kept, frame_s=tracks.frame_s * k)


def _circles(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares (Kasa) circles through windows xy (m, w, 2): centres (m, 2), radii (m,), the signed angle swept
    through the window and the sum of its steps' sizes (rad; equal when the point turns steadily one way)."""
    o = xy.mean(1, keepdims=True)
    p = xy - o                                               # about the window's mean: a well-conditioned fit
    x, y = p[..., 0], p[..., 1]
    A = np.stack([x, y, np.ones_like(x)], -1)
    b = -(x * x + y * y)
    M = np.einsum("mwi,mwj->mij", A, A)
    r = np.einsum("mwi,mw->mi", A, b)
    ok = np.abs(np.linalg.det(M)) > 1e-12
    sol = np.full((len(xy), 3), np.nan)
    sol[ok] = np.linalg.solve(M[ok], r[ok][..., None])[..., 0]
    c = -sol[:, :2] / 2
    rad = np.sqrt(np.maximum((c * c).sum(1) - sol[:, 2], 0.0))
    q = p - c[:, None, :]
    ang = np.arctan2(q[..., 1], q[..., 0])
    steps = np.angle(np.exp(1j * np.diff(ang, axis=1)))
    return c + o[:, 0], rad, steps.sum(1), np.abs(steps).sum(1)


def track_points(tracks, **params) -> TrackPoints:
    """Step 1 of the module docstring on every track."""
    P = {**DEFAULTS, **params}
    w = max(4, int(round(window_minutes(tracks, P) * 60.0 / tracks.frame_s)) + 1) if tracks.frame_s > 0 else 5
    half = w // 2
    cols = {k: [] for k in ("track", "frame", "t", "xy", "speed", "centre", "radius", "sense", "straight")}
    for k, (t, xy) in enumerate(tracks.tracks):
        n = len(t)
        if n < 3:
            continue
        i = np.arange(1, n - 1)
        seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        speed = (seg[:-1] + seg[1:]) / (t[2:] - t[:-2]) * 60.0
        cen = np.full((len(i), 2), np.nan)
        rad = np.full(len(i), np.nan)
        sense = np.zeros(len(i), np.int8)
        straight = np.full(len(i), np.nan)
        if n >= w:
            win = np.lib.stride_tricks.sliding_window_view(xy, (w, 2))[:, 0]          # (n - w + 1, w, 2)
            c, r, sweep, turned = _circles(win)
            mid = np.arange(half, half + len(win))                                   # the point each window centres
            path = np.lib.stride_tricks.sliding_window_view(seg, w - 1).sum(1)
            v = path / (t[w - 1:] - t[:n - w + 1]) * 60.0
            good = ((v >= P["min_speed_um_per_min"]) & (r <= P["max_radius_um"])
                    & (np.abs(sweep) >= np.radians(P["min_sweep_deg"])) & np.isfinite(r)
                    & (np.abs(sweep) >= P["min_steady"] * turned))
            net = np.linalg.norm(xy[w - 1:] - xy[:n - w + 1], axis=1)
            j = mid - 1
            inside = (j >= 0) & (j < len(i))
            straight[j[inside]] = (net / np.maximum(path, 1e-12))[inside]
            j, good, c, r, sweep = j[inside], good[inside], c[inside], r[inside], sweep[inside]
            cen[j[good]] = c[good]
            rad[j[good]] = r[good]
            sense[j[good]] = np.sign(sweep[good]).astype(np.int8)
        frame = np.round(t[i] / tracks.frame_s).astype(np.int64) if tracks.frame_s > 0 else np.arange(len(i))
        for name, val in (("track", np.full(len(i), k)), ("frame", frame), ("t", t[i]), ("xy", xy[i]),
                          ("speed", speed), ("centre", cen), ("radius", rad), ("sense", sense),
                          ("straight", straight)):
            cols[name].append(val)
    if not cols["track"]:
        z = np.zeros(0)
        return TrackPoints(z.astype(int), z.astype(int), z, np.zeros((0, 2)), z, np.zeros((0, 2)), z,
                           z.astype(np.int8), z, z.astype(int), z)
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    n = len(cat["track"])
    return TrackPoints(**cat, group=np.full(n, -1), r_over_R=np.full(n, np.nan))


def _min_image(d: np.ndarray, box) -> np.ndarray:
    return d if box is None else d - np.asarray(box) * np.round(d / np.asarray(box))


def _frame_groups(pts: TrackPoints, rows: np.ndarray, box, P) -> list[dict]:
    """Step 2 on one frame's rows: candidate groups as dicts (centre, radius, circling rows, their tracks)."""
    circ = rows[pts.sense[rows] != 0]
    if len(circ) < P["min_tracks"]:
        return []
    c = pts.centre[circ]
    rad = pts.radius[circ]
    tree = cKDTree(np.mod(c, box), boxsize=box) if box is not None else cKDTree(c)
    reach = max(P["centre_tol_um"], P["centre_tol_rel"] * float(rad.max()))
    pairs = tree.query_pairs(reach, output_type="ndarray")
    if len(pairs) == 0:
        return []
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.hypot(*_min_image(c[i] - c[j], box).T)
    tol = np.maximum(P["centre_tol_um"], P["centre_tol_rel"] * np.minimum(rad[i], rad[j]))
    pairs = pairs[(pts.sense[circ[i]] == pts.sense[circ[j]]) & (d <= tol)]
    m = len(circ)
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    _, lab = connected_components(g, directed=False)
    out = []
    for q in np.unique(lab):
        mem = np.flatnonzero(lab == q)
        if len(mem) < P["min_tracks"]:
            continue
        centre = c[mem[0]] + _min_image(c[mem] - c[mem[0]], box).mean(0)
        d = _min_image(pts.xy[circ[mem]] - centre, box)
        ang = np.sort(np.arctan2(d[:, 1], d[:, 0]))
        gaps = np.diff(np.concatenate([ang, [ang[0] + 2 * np.pi]]))
        if gaps.max() > 2 * np.pi - np.radians(P["min_cover_deg"]):
            continue
        out.append({"centre": centre, "radius_um": float(np.hypot(d[:, 0], d[:, 1]).max()), "rows": circ[mem],
                    "_members": np.unique(pts.track[circ[mem]]), "sense": int(pts.sense[circ[mem[0]]])})
    return out


def find_groups(tracks, **params) -> tuple[TrackPoints, list[dict]]:
    """Steps 1-4 of the module docstring: the points with their group, and the groups (frame, time, centre, radius,
    sense, circling tracks, members)."""
    P = {**DEFAULTS, **params}
    pts = track_points(tracks, **P)
    box = tracks.box
    frames = np.unique(pts.frame)
    by_frame = {f: np.flatnonzero(pts.frame == f) for f in frames}
    cand = {f: _frame_groups(pts, by_frame[f], box, P) for f in frames}
    groups = []
    for f in frames:
        near = [cand[g] for g in (f - 1, f + 1) if g in cand]
        kept = confirmed(cand[f], near) if any(near) else []
        rows = by_frame[f]
        for a in kept:
            d = _min_image(pts.xy[rows] - a["centre"], box)
            r = np.hypot(d[:, 0], d[:, 1])
            sel = (r <= a["radius_um"]) & (pts.group[rows] < 0)
            inside = rows[sel]
            gid = len(groups)
            pts.group[inside] = gid
            pts.r_over_R[inside] = r[sel] / a["radius_um"]
            groups.append({"id": gid, "frame": int(f), "time_min": float(pts.t[rows[0]] / 60.0),
                           "centre_um": [float(x) for x in a["centre"]], "radius_um": a["radius_um"],
                           "sense": a["sense"], "circling": int(len(a["rows"])), "members": int(len(inside))})
    return pts, groups


PROFILE_BINS = np.linspace(0.0, 1.0, 6)


def free_speed(pts: TrackPoints, min_straight: float = 0.8, min_points: int = 20) -> tuple[float, str]:
    """The free-cell speed read from the tracks: the median speed of points outside every group where the cell
    glides straight (straightness >= min_straight over the window): a cell jammed in a cluster or curled on itself is
    not free, and its speed is not v_b. Falls back to every point outside the groups when too few glide."""
    out = pts.group < 0
    glide = out & (pts.straight >= min_straight)
    if glide.sum() >= min_points:
        return float(np.median(pts.speed[glide])), "median speed of straight-gliding cells outside groups"
    if out.sum() >= min_points:
        return float(np.median(pts.speed[out])), "median speed outside groups (too few straight gliders)"
    return np.nan, "too few points outside groups"


def group_speeds(pts: TrackPoints, groups: list[dict], v_b: float | None = None) -> dict:
    """Speeds inside and outside the groups in units of v_ref: the free-cell speed v_b when given, else read from
    the tracks (free_speed: a lab does not know its cells' v_b; the simulations are read the same way); their
    distributions, the speed against distance from a group's centre (r / R), and the edge speed (r / R >= 2/3)."""
    inside = pts.group >= 0
    out_speeds = pts.speed[~inside]
    v_ref, v_from = (float(v_b), "v_b given") if v_b else free_speed(pts)
    s_in, s_out = pts.speed[inside] / v_ref, out_speeds / v_ref
    rr = pts.r_over_R[inside]
    prof = []
    for a, b in zip(PROFILE_BINS[:-1], PROFILE_BINS[1:]):
        sel = (rr >= a) & (rr <= b) if b == 1.0 else (rr >= a) & (rr < b)
        prof.append(float(np.mean(s_in[sel])) if sel.any() else np.nan)
    edge = s_in[rr >= 2.0 / 3.0]

    def med(x):
        return float(np.median(x)) if len(x) else np.nan

    n_frames = len(np.unique(pts.frame)) if len(pts.frame) else 0
    return {"v_ref_um_per_min": v_ref, "v_ref_from": v_from,
            "points": int(len(pts.speed)), "points_in_groups": int(inside.sum()),
            "fraction_in_groups": float(inside.mean()) if len(inside) else np.nan,
            "groups_per_frame": len(groups) / n_frames if n_frames else 0.0,
            "group_radius_um_median": med([g["radius_um"] for g in groups]),
            "speed_in_median_vref": med(s_in), "speed_out_median_vref": med(s_out),
            "edge_speed_median_vref": med(edge), "edge_points": int(len(edge)),
            "profile_r_over_R": PROFILE_BINS.tolist(), "profile_speed_vref": prof,
            "_in": s_in, "_out": s_out, "_in_track": pts.track[inside], "_edge": edge}
