"""Aggregates followed across frames by the cells they share, their events and lifetimes, and the
size-independence regression.

Linking. An aggregate is a set of cells (its members), and cells keep their index through a trajectory, so two
aggregates of successive analysed frames are the same aggregate, or parts of one, when they share cells: a link
needs at least ``link_min_shared`` (2) shared cells and at least ``link_overlap`` (30 %) of the smaller aggregate's
members. A track whose aggregate is missing for up to ``max_gap_frames`` analysed frames (detection flickers) is
still linked when it reappears. Links are taken oldest track first, then largest overlap (so when two aggregates
merge the elder continues, and an aggregate found as two pieces for a frame keeps its identity); each track continues
into at most one aggregate and each aggregate continues at most one track; the remaining links are events:

- birth: an aggregate linked to no earlier one starts a track;
- merge (two -> one): a track whose aggregate shares cells with an aggregate that continues another track ends there
  (``end: "merge"``, ``merged_into``: that track);
- split (one -> two): an aggregate that shares cells with a track that continues into another aggregate starts a new
  track (``start: "split"``, ``split_from``: that track);
- dispersal: a track with no successor for more than ``max_gap_frames`` frames ends (``end: "dispersal"``); one still
  present in the last analysed frame ends with the run (``end: "end of run"``, its lifetime censored), and one present
  in the first analysed frame started before it (``start: "start of run"``).

Lifetime of a track = time of its last frame - time of its first frame (min; 0 for an aggregate seen once). "Stable"
has a number: the fraction of aggregate-frames that belong to tracks living >= ``stable_lifetime_min`` (10 min).

The regression: each track seen in >= ``min_track_frames`` frames gives one point (time means of radius and edge
speed); the ordinary least-squares slope of edge speed against radius, its standard error and t = slope / SE;
"consistent with 0" when |t| < 2. Also the exponent of edge speed ~ R^a on log-log axes (0: size-independent edge
speed, 1: common angular speed) and the same regression on the aggregates of the last frame with aggregates."""
from __future__ import annotations

import math

import numpy as np

from .stats import ols


def public(a: dict) -> dict:
    """An aggregate dict without its private ('_') entries, the arrays kept for the plots."""
    return {k: v for k, v in a.items() if not k.startswith("_")}


def _shared(a: np.ndarray, b: np.ndarray) -> int:
    return int(len(np.intersect1d(a, b, assume_unique=True)))


def _link(a: np.ndarray, b: np.ndarray, link_overlap: float, link_min_shared: int) -> int:
    """The cells two aggregates share when that makes a link (module docstring), else 0."""
    s = _shared(a, b)
    return s if s >= link_min_shared and s >= link_overlap * min(len(a), len(b)) else 0


def confirmed(aggs: list[dict], neighbours: list[list[dict]], link_overlap: float = 0.3,
              link_min_shared: int = 2) -> list[dict]:
    """The aggregates of one frame that are also seen in a neighbouring analysed frame (linked as tracks are: shared
    cells, module docstring); all of them when there is no neighbouring frame to ask (a single frame).

    A group of cells that circulates in one frame only is a transient curl, not an aggregate: on the labelled frames
    (tests/data) the passive-following S2 at 60 min has 5 circulating groups of 4-16 cells inside jammed clusters, of
    which 1 is seen again a minute earlier (41 min: 3, of which 2), and S17 (slime trails) 3 of which none; of S3's
    25 at 60 min, 22 (all labelled by eye) are, and every labelled aggregate of S4 and S10. Asking for both
    neighbours instead loses real ones (S3 at 32 min: 11 of 14 labelled found instead of 13; S13: 0 of 2)."""
    if not neighbours:
        return list(aggs)
    others = [b["_members"] for fa in neighbours for b in fa]
    return [a for a in aggs if any(_link(a["_members"], b, link_overlap, link_min_shared) for b in others)]


def link_tracks(per_frame: list[list[dict]], times: list[float] | None = None, max_gap: int = 2,
                link_overlap: float = 0.3, link_min_shared: int = 2) -> tuple[list[dict], list[dict]]:
    """Link the aggregates of successive analysed frames by shared member cells (module docstring).

    per_frame: per analysed frame, its aggregates (dicts with "_members", the member cell indices, and "time_min"),
    or None for a frame whose aggregates could not be measured (no speeds yet; before the first measured frame,
    an aggregate present there starts with the run).
    Returns (tracks, events): tracks as dicts(id, frames: [(frame index, aggregate)], start, end, split_from,
    merged_into); events as dicts(type in birth/merge/split/dispersal, time_min, frame, tracks, ...)."""
    n_fr = len(per_frame)
    if times is None:
        times = [fa[0]["time_min"] if fa else float("nan") for fa in per_frame]
    # frames not analysed for aggregates (None: no speeds yet) before the first one that is
    first = next((i for i, fa in enumerate(per_frame) if fa is not None), n_fr)
    per_frame = [fa or [] for fa in per_frame]
    tracks: list[dict] = []
    events: list[dict] = []
    open_: list[int] = []                       # ids of tracks that may still continue
    members = [[np.unique(np.asarray(a["_members"], np.int64)) for a in fa] for fa in per_frame]
    for fi, aggs in enumerate(per_frame):
        # tracks past the gap end by dispersal (at the time of their last frame)
        still = []
        for tid in open_:
            if fi - tracks[tid]["frames"][-1][0] > max_gap + 1:
                _end(tracks[tid], "dispersal", events)
            else:
                still.append(tid)
        open_ = still
        links = []                               # (shared, track, aggregate)
        for tid in open_:
            lf, _ = tracks[tid]["frames"][-1]
            mt = tracks[tid]["_members"]
            for ai, ma in enumerate(members[fi]):
                k = _link(mt, ma, link_overlap, link_min_shared)
                if k:
                    links.append((k, tid, ai))
        # the older track first (when two merge, the elder continues: a one-frame split of an aggregate into two
        # pieces and back keeps its identity), then its largest overlap
        links.sort(key=lambda x: (tracks[x[1]]["frames"][0][0], -x[0], x[1], x[2]))
        cont_t, cont_a = {}, {}
        for k, tid, ai in links:
            if tid not in cont_t and ai not in cont_a:
                cont_t[tid], cont_a[ai] = ai, tid
        # merges: an open track linked only to aggregates that continue other tracks
        linked_t: dict[int, list[int]] = {}
        linked_a: dict[int, list[int]] = {}
        for k, tid, ai in links:
            linked_t.setdefault(tid, []).append(ai)
            linked_a.setdefault(ai, []).append(tid)
        for tid, ais in linked_t.items():
            if tid in cont_t:
                continue
            ai = max(ais, key=lambda a_: next(k for k, t_, b_ in links if t_ == tid and b_ == a_))
            into = cont_a.get(ai)
            if into is not None:
                tracks[tid]["merged_into"] = into
                _end(tracks[tid], "merge", events, time_min=times[fi], frame=fi,
                     extra=dict(tracks=[into, tid], into=into))
        # continue tracks
        for tid, ai in cont_t.items():
            tracks[tid]["frames"].append((fi, aggs[ai]))
            tracks[tid]["_members"] = members[fi][ai]
        # new tracks: births and splits
        for ai, a in enumerate(aggs):
            if ai in cont_a:
                continue
            tid = len(tracks)
            parents = [t for t in linked_a.get(ai, []) if t in cont_t]
            tr = dict(id=tid, frames=[(fi, a)], _members=members[fi][ai], start="birth", split_from=None,
                      merged_into=None, end=None)
            if fi == first:
                tr["start"] = "start of run"
            elif parents:
                tr["start"], tr["split_from"] = "split", parents[0]
                events.append(dict(type="split", time_min=times[fi], frame=fi, tracks=[parents[0], tid],
                                   split_from=parents[0]))
            else:
                events.append(dict(type="birth", time_min=times[fi], frame=fi, tracks=[tid]))
            tracks.append(tr)
            open_.append(tid)
        open_ = [t for t in open_ if tracks[t]["end"] is None]
    for tid in open_:
        last = tracks[tid]["frames"][-1][0]
        if n_fr - 1 - last > max_gap:
            _end(tracks[tid], "dispersal", events)
        else:
            tracks[tid]["end"] = "end of run"
    for tr in tracks:
        tr.pop("_members", None)
    events.sort(key=lambda e: (e["frame"], e["type"]))
    return tracks, events


def _end(tr: dict, how: str, events: list, time_min=None, frame=None, extra=None) -> None:
    tr["end"] = how
    fi, a = tr["frames"][-1]
    ev = dict(type=how, time_min=a["time_min"] if time_min is None else time_min,
              frame=fi if frame is None else frame, tracks=[tr["id"]])
    if extra:
        ev.update(extra)
    events.append(ev)


def track_summaries(tracks: list[dict], min_track_frames: int, stable_lifetime_min: float = 10.0) -> list[dict]:
    """One dict per track: lifetime, how it started and ended, time means, the fraction of frames rigid, the last
    aggregate and the time series."""
    track_out = []
    for t in tracks:
        aa = [a for _, a in t["frames"]]
        mean = lambda k: float(np.nanmean([a[k] for a in aa]))            # noqa: E731
        r2v = [a["rotation_fit"]["r2"] for a in aa if a.get("rotation_fit")]
        life = aa[-1]["time_min"] - aa[0]["time_min"]
        track_out.append(dict(
            id=t["id"], n_frames=len(aa), first_time_min=aa[0]["time_min"], last_time_min=aa[-1]["time_min"],
            lifetime_min=life, start=t["start"], end=t["end"], split_from=t["split_from"],
            merged_into=t["merged_into"], lifetime_censored=t["start"] == "start of run" or t["end"] == "end of run",
            stable=len(aa) >= min_track_frames, long_lived=life >= stable_lifetime_min,
            mean_radius_um=mean("radius_um"), mean_n_cells=mean("n_cells"),
            mean_omega_rad_per_min=mean("omega_rad_per_min"), mean_edge_speed_um_per_min=mean("edge_speed_um_per_min"),
            mean_edge_speed_vb=mean("edge_speed_vb"), mean_r2_origin=mean("r2_origin"),
            mean_rotation_fit_r2=float(np.nanmean(r2v)) if r2v else None,
            fraction_rigid=float(np.mean([a["rigid"] for a in aa])),
            last=public(aa[-1]),
            series=dict(time_min=[a["time_min"] for a in aa], centre_um=[a["centre_um"] for a in aa],
                        radius_um=[a["radius_um"] for a in aa], n_cells=[a["n_cells"] for a in aa],
                        omega_rad_per_min=[a["omega_rad_per_min"] for a in aa],
                        edge_speed_um_per_min=[a["edge_speed_um_per_min"] for a in aa],
                        r2_origin=[a["r2_origin"] for a in aa],
                        rotation_fit_r2=[(a.get("rotation_fit") or {}).get("r2") for a in aa],
                        rigidity_exponent=[a.get("rigidity_exponent") for a in aa]),
        ))
    return track_out


def lifetime_stats(track_out: list[dict], events: list[dict], stable_lifetime_min: float = 10.0) -> dict:
    """Events counted by type; lifetimes (min) of the tracks; the fraction of aggregate-frames in tracks living
    >= stable_lifetime_min (the number behind "stable")."""
    counts = {k: 0 for k in ("birth", "merge", "split", "dispersal")}
    for e in events:
        counts[e["type"]] = counts.get(e["type"], 0) + 1
    life = np.array([t["lifetime_min"] for t in track_out], float)
    nfr = np.array([t["n_frames"] for t in track_out], float)
    long_ = life >= stable_lifetime_min
    return dict(
        n_tracks=len(track_out), events=counts, stable_lifetime_min=stable_lifetime_min,
        lifetimes_min=life.tolist(),
        lifetime_censored=[t["lifetime_censored"] for t in track_out],
        median_lifetime_min=float(np.median(life)) if len(life) else None,
        max_lifetime_min=float(life.max()) if len(life) else None,
        n_long_lived=int(long_.sum()),
        fraction_aggregate_frames_long_lived=float(nfr[long_].sum() / nfr.sum()) if nfr.sum() else None,
        note="lifetime = last minus first time seen; tracks present in the first or the last analysed frame are "
             "censored (lifetime_censored): they may live longer",
    )


def size_regression(R, E) -> dict:
    """Edge speed E (µm/min) against radius R (µm) over aggregates: OLS slope, its t, and the log-log exponent."""
    R, E = np.asarray(R, float), np.asarray(E, float)
    out = ols(R, E)
    out = dict(n_aggregates=len(R), slope_um_per_min_per_um=out["slope"], stderr=out["stderr"],
               intercept_um_per_min=out["intercept"], r2=out["r2"])
    t = out["slope_um_per_min_per_um"] / out["stderr"] if out["stderr"] and math.isfinite(out["stderr"]) \
        else float("nan")
    out["t"] = t
    out["consistent_with_zero"] = bool(abs(t) < 2.0) if math.isfinite(t) else None
    if len(R) >= 2 and math.isfinite(out["slope_um_per_min_per_um"]):
        out["relative_change_over_range"] = out["slope_um_per_min_per_um"] * float(R.max() - R.min()) / float(E.mean())
    good = (R > 0) & (E > 0)
    lg = ols(np.log(R[good]), np.log(E[good])) if good.sum() >= 2 else ols([], [])
    out["loglog_exponent"] = lg["slope"]
    out["loglog_exponent_stderr"] = lg["stderr"]
    return out
