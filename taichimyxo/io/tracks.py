"""Cell tracks as labs export them, read into one table: TrackMate's spots table (CSV) and a plain CSV of track, time,
x, y; positions in µm and times in s once read (units given by the caller: pixel size, frame interval).

``read_tracks(path, pixel_um=None, frame_s=None)`` returns a :class:`Tracks`: per track its times and positions in
time order, and what was done on the way, counted (never silently dropped): rows without a track, tracks split where
a frame is missing (a gap longer than ``max_gap_frames``) or where a step is a jump no cell makes (an identity swap:
faster than ``max_speed_um_per_min``), and pieces shorter than ``min_points``. The measures come from
taichimyxo.analysis.lab_tracks, the same for measured tracks and for a simulation's centroids (``from_frames``).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .schema import SceneError


class TracksError(SceneError):
    """A tracks file that cannot be read; the message is one line naming the file and what is expected."""


# TrackMate's spots table: its column names (units in the header rows of recent versions)
TRACKMATE = {"track": "TRACK_ID", "x": "POSITION_X", "y": "POSITION_Y", "t": "POSITION_T", "frame": "FRAME"}
PLAIN = {"track": ("track", "track_id", "id", "cell"), "t": ("time", "t", "time_s", "frame"), "x": ("x", "x_um"),
         "y": ("y", "y_um")}


@dataclass
class Tracks:
    """Tracks in µm and s: ``tracks[k] = (t (n,), xy (n, 2))`` in time order, and the counts of what reading did;
    the frame interval (s), and the periodic box (µm) of a simulation's unwrapped tracks (None for a lab's)."""
    tracks: list = field(default_factory=list)
    counts: dict = field(default_factory=dict)
    source: str = ""
    frame_s: float = 0.0
    box: tuple | None = None

    @property
    def n_points(self) -> int:
        return sum(len(t) for t, _ in self.tracks)


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    except FileNotFoundError:
        raise TracksError(f"tracks file {path} not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise TracksError(f"tracks file {path} cannot be read: {e}") from None
    if not rows:
        raise TracksError(f"tracks file {path} is empty: expected a header row and one row per spot")
    return [c.strip() for c in rows[0]], rows[1:]


def _number(cell: str) -> float | None:
    try:
        v = float(cell)
    except ValueError:
        return None
    return v if np.isfinite(v) else None


_TIME_UNITS = {"sec": 1.0, "s": 1.0, "min": 60.0, "hou": 3600.0, "h": 3600.0, "ms": 1e-3}


def _xml_number(el, key: str, path: Path):
    v = el.get(key)
    x = _number(v) if v is not None else None
    if x is None:
        raise TracksError(f"{path}: a {el.tag} without a number for {key} (TrackMate XML)")
    return x


def read_xml(path) -> tuple[str, np.ndarray, np.ndarray, np.ndarray, int, float | None]:
    """TrackMate's XML: the full model file (spots in AllSpots, a track's spots from its edges, FilteredTracks
    honoured) or "Export tracks to XML" (particles of detections, t a frame index). Returns (kind, ids, times (the
    file's time unit converted to s; frames times the interval in the export), xy, spots in no kept track, frame
    interval in s or None).
    Read incrementally: a model file of a long movie is hundreds of MB."""
    import xml.etree.ElementTree as ET
    path = Path(path)
    spots, edges, kept, ids, ts, xy = {}, {}, None, [], [], []
    kind, frame_s, track, untracked, particles, to_s = None, None, None, 0, 0, 1.0
    try:
        for event, el in ET.iterparse(path, events=("start", "end")):
            tag = el.tag
            if event == "start":
                if tag == "Tracks" and kind is None:
                    kind = "trackmate-tracks-xml"
                    to_s = _TIME_UNITS.get(el.get("timeUnits", "sec").lower()[:3], 1.0)
                    frame_s = _number(el.get("frameInterval", "")) or None
                    frame_s = frame_s * to_s if frame_s else None
                elif tag == "Model":
                    kind = "trackmate-xml"
                    to_s = _TIME_UNITS.get(el.get("timeunits", "sec").lower()[:3], 1.0)
                elif tag == "particle":
                    track, particles = particles, particles + 1
                elif tag == "Track":
                    track = int(_xml_number(el, "TRACK_ID", path))
                elif tag == "FilteredTracks":
                    kept = set()
                continue
            if tag == "detection" and kind == "trackmate-tracks-xml":
                ids.append(track)
                ts.append(_xml_number(el, "t", path) * (frame_s or 1.0))          # t counts frames
                xy.append((_xml_number(el, "x", path), _xml_number(el, "y", path)))
            elif tag == "Spot":
                t = el.get("POSITION_T")
                spots[el.get("ID")] = (_number(t) if t is not None else None, _xml_number(el, "FRAME", path)
                                       if t is None else None, _xml_number(el, "POSITION_X", path),
                                       _xml_number(el, "POSITION_Y", path))
            elif tag == "Edge":
                for key in ("SPOT_SOURCE_ID", "SPOT_TARGET_ID"):
                    edges.setdefault(el.get(key), track)
            elif tag == "TrackID" and kept is not None:
                kept.add(int(_xml_number(el, "TRACK_ID", path)))
            elif tag == "ImageData" and frame_s is None:
                frame_s = _number(el.get("timeinterval", "")) or None
                frame_s = frame_s * to_s if frame_s else None
            el.clear()
    except FileNotFoundError:
        raise TracksError(f"tracks file {path} not found") from None
    except ET.ParseError as e:
        raise TracksError(f"{path}: not readable as XML ({e})") from None
    if kind is None:
        raise TracksError(f"{path}: XML but not TrackMate's (expected a TrackMate model file or its tracks export)")
    if kind == "trackmate-xml":
        for sid, (t, frame, x, y) in spots.items():
            k = edges.get(sid)
            if k is None or (kept is not None and k not in kept):
                untracked += 1
                continue
            ids.append(k)
            ts.append(t * to_s if t is not None else frame * (frame_s or 1.0))
            xy.append((x, y))
    if not ids:
        raise TracksError(f"{path}: no spot belongs to a track")
    return kind, np.asarray(ids), np.asarray(ts, float), np.asarray(xy, float), untracked, frame_s


def read_table(path) -> tuple[str, np.ndarray, np.ndarray, np.ndarray, int]:
    """(kind, track ids, times in the file's unit, xy in the file's unit, rows without a track): TrackMate's spots
    table (its extra header rows skipped) or a plain CSV of track, time, x, y."""
    path = Path(path)
    head, rows = _rows(path)
    upper = [h.upper() for h in head]
    if TRACKMATE["track"] in upper and TRACKMATE["x"] in upper:
        kind = "trackmate"
        col = {k: upper.index(v) for k, v in TRACKMATE.items() if v in upper}
        if "t" not in col and "frame" not in col:
            raise TracksError(f"{path}: a TrackMate table needs POSITION_T or FRAME")
        tcol = col.get("t", col.get("frame"))
    else:
        kind = "plain"
        low = [h.lower() for h in head]
        col = {}
        for k, names in PLAIN.items():
            hit = next((low.index(n) for n in names if n in low), None)
            if hit is None:
                raise TracksError(f"{path}: no {k!r} column (expected one of {', '.join(names)}; or TrackMate's "
                                  f"TRACK_ID, POSITION_X, POSITION_Y, POSITION_T)")
            col[k] = hit
        tcol = col["t"]
    ids, ts, xy, untracked = [], [], [], 0
    for r in rows:
        vals = [_number(r[i]) if i < len(r) else None for i in (col["track"], tcol, col["x"], col["y"])]
        if vals[1] is None or vals[2] is None or vals[3] is None:
            if kind == "trackmate" and ids == [] and any(_number(c) is None for c in r):
                continue                        # TrackMate's second to fourth header rows (names, short names, units)
            if vals[0] is None and all(v is not None for v in vals[1:]):
                untracked += 1
                continue
            raise TracksError(f"{path}: row {r[:4]!r} lacks a number for time, x or y")
        if vals[0] is None:
            untracked += 1                      # a spot TrackMate linked to no track
            continue
        ids.append(int(vals[0]))
        ts.append(vals[1])
        xy.append((vals[2], vals[3]))
    if not ids:
        raise TracksError(f"{path}: no spot belongs to a track")
    return kind, np.asarray(ids), np.asarray(ts, float), np.asarray(xy, float), untracked


def split_track(t: np.ndarray, xy: np.ndarray, frame_s: float, max_gap_frames: int, max_step_um: float):
    """A track's pieces: cut where more than max_gap_frames frames are missing, or where one step is longer than a
    cell moves (max_step_um per frame interval, an identity swap). Returns (pieces, gaps cut, jumps cut)."""
    if len(t) < 2:
        return [(t, xy)], 0, 0
    dt = np.diff(t)
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    gap = dt > (max_gap_frames + 1) * frame_s * (1 + 1e-6)
    jump = step > max_step_um * np.maximum(dt / frame_s, 1.0)
    cut = np.flatnonzero(gap | jump) + 1
    pieces = [(a, b) for a, b in zip(np.split(t, cut), np.split(xy, cut))]
    return pieces, int(np.sum(gap)), int(np.sum(jump & ~gap))


def assemble(ids, ts, xy, frame_s: float, *, max_gap_frames: int = 2, max_speed_um_per_min: float = 30.0,
             min_points: int = 5, source: str = "", extra_counts: dict | None = None, box=None) -> Tracks:
    """Tracks from per-spot rows (ids, times s, xy µm): each in time order (a spot listed twice at one time keeps
    the first), split at gaps and jumps, pieces shorter than min_points set aside; everything counted."""
    counts = {"tracks_read": 0, "spots_read": int(len(ids)), "duplicate_spots": 0, "split_at_gaps": 0,
              "split_at_jumps": 0, "pieces_too_short": 0, "tracks_kept": 0, **(extra_counts or {})}
    max_step = max_speed_um_per_min / 60.0 * frame_s
    out = []
    for k in np.unique(ids):
        sel = ids == k
        order = np.argsort(ts[sel], kind="stable")
        t, p = ts[sel][order], xy[sel][order]
        keep = np.concatenate([[True], np.diff(t) > 0])
        counts["duplicate_spots"] += int(np.sum(~keep))
        t, p = t[keep], p[keep]
        counts["tracks_read"] += 1
        pieces, gaps, jumps = split_track(t, p, frame_s, max_gap_frames, max_step)
        counts["split_at_gaps"] += gaps
        counts["split_at_jumps"] += jumps
        for a, b in pieces:
            if len(a) < min_points:
                counts["pieces_too_short"] += 1
            else:
                out.append((a, b))
    counts["tracks_kept"] = len(out)
    return Tracks(out, counts, source, float(frame_s), None if box is None else tuple(float(b) for b in box))


def read_tracks(path, *, pixel_um: float | None = None, frame_s: float | None = None, time_unit: str = "s",
                **options) -> Tracks:
    """A lab's tracks in µm and s. pixel_um: µm per pixel (positions in pixels; None: already µm). frame_s: the frame
    interval, s (needed when the times are frames, `time_unit="frame"`, and to find gaps; else the median step of
    the times). options: assemble's (max_gap_frames, max_speed_um_per_min, min_points)."""
    if pixel_um is not None and not pixel_um > 0:
        raise TracksError(f"pixel size {pixel_um!r} µm: expected a positive number, e.g. 0.065")
    if frame_s is not None and not frame_s > 0:
        raise TracksError(f"frame interval {frame_s!r} s: expected a positive number, e.g. 30")
    if time_unit not in ("s", "min", "frame"):
        raise TracksError(f"time unit {time_unit!r}: expected s, min or frame")
    if str(path).lower().endswith(".xml"):
        kind, ids, ts, xy, untracked, xml_frame_s = read_xml(path)
        frame_s = frame_s or xml_frame_s
    else:
        kind, ids, ts, xy, untracked = read_table(path)
    if time_unit == "frame":
        if frame_s is None:
            raise TracksError(f"{path}: times given in frames need the frame interval (frame_s, e.g. 30 s)")
        ts = ts * frame_s
    elif time_unit == "min":
        ts = ts * 60.0
    if pixel_um is not None:
        xy = xy * pixel_um
    if frame_s is None:
        steps = np.concatenate([np.diff(np.sort(ts[ids == k])) for k in np.unique(ids)])
        steps = steps[steps > 0]
        if not len(steps):
            raise TracksError(f"{path}: no track has two times; give the frame interval")
        frame_s = float(np.median(steps))
    return assemble(ids, ts, xy, frame_s, source=f"{path} ({kind})", extra_counts={"spots_without_track": untracked},
                    **options)


def from_frames(frames, every_s: float | None = None) -> Tracks:
    """A simulation's cells as centroid tracks (one point per cell and frame, chains unwrapped across the periodic
    box), so measured and simulated tracks go through the same measures."""
    ids, ts, xy = [], [], []
    prev, shift, box = None, None, None
    for fr in frames:
        box = np.asarray(fr.box, float)
        c = np.asarray(fr.positions, float).mean(axis=1)
        if prev is not None:                     # undo the periodic wrap of the centroids
            d = c + shift - prev
            shift = shift - box * np.round(d / box)
        else:
            shift = np.zeros_like(c)
        prev = c + shift
        ids.append(np.arange(len(c)))
        ts.append(np.full(len(c), fr.time_s))
        xy.append(prev.copy())
    if not ids:
        raise TracksError("from_frames: no frames")
    ids, ts, xy = np.concatenate(ids), np.concatenate(ts), np.concatenate(xy)
    frame_s = every_s or float(np.median(np.diff(np.unique(ts))))
    return assemble(ids, ts, xy, frame_s, source="simulation", min_points=2, box=box)
