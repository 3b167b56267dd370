"""The paper's proposed test as a report: which guiding mechanism a lab's tracks match, judged by the speeds of cells
in circular aggregates ("distribution of cell speeds in circular aggregates", the paper's abstract;
docs/lab-tracks.md).

Measured tracks and each mechanism's simulated runs go through one code path: the simulations' centroids
(``from_frames``) resampled to the measured frame interval, groups found from the motion (track_groups), speeds in
units of the speed outside the groups. The distance between the measured and a mechanism's distribution of in-group
speeds is the Wasserstein-1 distance (the mean shift a distribution needs to become the other, in units of v_ref).
Its uncertainty is a bootstrap over tracks, both sides (a track's points are not independent). The verdict:

- the mechanism nearest in a fraction p of the bootstrap replicates is *strongly* preferred when p >= 0.95, and its
  distance's upper bound is below every other mechanism's lower bound; *preferred* when p >= 0.80;
- else the data *cannot tell* the nearest two apart; and they cannot tell anything without enough points in groups
  (``min_points`` measured, and each mechanism's).

Nearest is not the same as alike: the report also gives each mechanism's own spread (how far one of its runs lies
from its other runs) and says when the nearest mechanism is more than ``FIT_FACTOR`` times that far from the
measurement (the data match none of the simulated mechanisms well).
"""
from __future__ import annotations

import numpy as np
from scipy.stats import wasserstein_distance

from .track_groups import DEFAULTS, find_groups, group_speeds, resample

MIN_POINTS = 100
FIT_FACTOR = 2.0          # the nearest mechanism fits when the distance is at most this many times its runs' own


def in_group_speeds(tracks, frame_s: float | None = None, v_b: float | None = None, **params) -> dict:
    """The group measures of tracks at frame interval frame_s (resampled when longer than theirs)."""
    if frame_s:
        tracks = resample(tracks, frame_s)
    pts, groups = find_groups(tracks, **params)
    res = group_speeds(pts, groups, v_b=v_b)
    res["groups"] = groups
    res["_points"] = pts
    return res


def _self_distance(runs: list[dict]) -> float:
    """How far one run of a mechanism lies from its other runs (mean over runs, leave one out): the distance a
    measurement made by that mechanism can be expected at; NaN with one run."""
    d = [wasserstein_distance(r["_in"], np.concatenate([o["_in"] for j, o in enumerate(runs) if j != i]))
         for i, r in enumerate(runs) if len(r["_in"]) and any(len(o["_in"]) for j, o in enumerate(runs) if j != i)]
    return float(np.mean(d)) if d else np.nan


def _by_track(speeds: np.ndarray, track: np.ndarray) -> list[np.ndarray]:
    order = np.argsort(track, kind="stable")
    cut = np.flatnonzero(np.diff(track[order])) + 1
    return np.split(speeds[order], cut)


def _resampled(parts: list[np.ndarray], rng) -> np.ndarray:
    pick = rng.integers(0, len(parts), len(parts))
    return np.concatenate([parts[i] for i in pick])


def compare(measured: dict, references: dict[str, list[dict]], n_boot: int = 500, seed: int = 0,
            min_points: int = MIN_POINTS) -> dict:
    """The report's numbers from in_group_speeds results: measured, and per mechanism its runs' (pooled)."""
    rng = np.random.default_rng(seed)
    meas = measured["_in"]
    ref = {m: (np.concatenate([r["_in"] for r in runs]),
               np.concatenate([r["_in_track"] + 1_000_000 * i for i, r in enumerate(runs)])) for m, runs in
           references.items()}
    rows = {}
    for m, (s, tr) in ref.items():
        rows[m] = {"points": int(len(s)), "runs": len(references[m]),
                   "median_vref": float(np.median(s)) if len(s) else np.nan,
                   "edge_median_vref": float(np.nanmedian([r["edge_speed_median_vref"] for r in references[m]])),
                   "distance": float(wasserstein_distance(meas, s)) if len(s) and len(meas) else np.nan,
                   "self_distance": _self_distance(references[m])}
    enough = len(meas) >= min_points and all(len(s) >= min_points for s, _ in ref.values())
    out = {"measured_points": int(len(meas)), "mechanisms": rows, "n_boot": n_boot}
    if not enough:
        few = [m for m, (s, _) in ref.items() if len(s) < min_points]
        why = (f"only {len(meas)} measured points in rotating groups (need {min_points})" if len(meas) < min_points
               else f"too few points in groups in the runs of {', '.join(few)}")
        out.update(verdict="cannot tell", strength="none", nearest=None, why=why)
        return out
    mparts = _by_track(meas, measured["_in_track"])
    rparts = {m: _by_track(s, tr) for m, (s, tr) in ref.items()}
    names = list(ref)
    boot = np.empty((n_boot, len(names)))
    for b in range(n_boot):
        mb = _resampled(mparts, rng)
        for j, m in enumerate(names):
            boot[b, j] = wasserstein_distance(mb, _resampled(rparts[m], rng))
    near = np.bincount(np.argmin(boot, 1), minlength=len(names)) / n_boot
    lo, hi = np.percentile(boot, [2.5, 97.5], axis=0)
    for j, m in enumerate(names):
        rows[m].update(ci95=[float(lo[j]), float(hi[j])], p_nearest=float(near[j]))
    best = int(np.argmax(near))
    others = [j for j in range(len(names)) if j != best]
    separated = all(hi[best] < lo[j] for j in others)
    if near[best] >= 0.95 and separated:
        strength = "strong"
    elif near[best] >= 0.80:
        strength = "moderate"
    else:
        strength = "none"
    if strength == "none":
        second = names[others[int(np.argmax(near[others]))]] if others else None
        verdict = f"cannot tell {names[best]} from {second}"
    else:
        verdict = names[best]
    own = rows[names[best]]["self_distance"]
    fits = not np.isfinite(own) or rows[names[best]]["distance"] <= FIT_FACTOR * own
    out.update(verdict=verdict, strength=strength, nearest=names[best], fits=bool(fits),
               why=f"{names[best]} is nearest in {near[best]:.0%} of {n_boot} bootstrap replicates"
                   + ("; its interval is apart from every other" if separated else ""))
    return out


def report(measured_tracks, references: dict[str, list], v_b: float | None = None, n_boot: int = 500,
           seed: int = 0, reference_v_b: dict[str, list] | None = None, **params) -> dict:
    """Measured tracks (a Tracks) against simulated runs per mechanism (``{"adhesion": [Tracks, ...], ...}``), all
    taken at the measured frame interval. Speeds are in units of the free-cell speed: the measured tracks' v_b when
    the lab gives it (an isolated-cell assay), else read from their straight gliders (track_groups.free_speed); each
    run's from its scene (``reference_v_b``, per run; else the paper's 4 µm/min), since a simulation knows it exactly
    and a dense run may have no free cell to read it from. Returns the numbers (compare) with each side's group
    measures."""
    P = {**DEFAULTS, **params}
    frame_s = measured_tracks.frame_s
    meas = in_group_speeds(measured_tracks, v_b=v_b, **P)

    def ref_vb(m, i):
        return (reference_v_b or {}).get(m, [4.0] * (i + 1))[i]

    refs = {m: [in_group_speeds(t, frame_s=frame_s, v_b=ref_vb(m, i), **P) for i, t in enumerate(runs)]
            for m, runs in references.items()}
    res = compare(meas, refs, n_boot=n_boot, seed=seed)
    res.update(frame_s=frame_s, params=P, measured=_public(meas), references={m: [_public(r) for r in rs] for m, rs in
                                                                             refs.items()},
               _measured=meas, _references=refs)
    return res


def _public(d: dict) -> dict:
    return {k: v for k, v in d.items() if not k.startswith("_") and k != "groups"}


def sentence(res: dict) -> str:
    """The verdict in one sentence a biologist reads."""
    if res["strength"] == "none":
        what = res["verdict"].replace("cannot tell ", "") if res.get("nearest") else "the mechanisms apart"
        return f"The tracks cannot tell {what}: {res['why']}."
    word = "strongly prefer" if res["strength"] == "strong" else "prefer"
    m = res["mechanisms"][res["nearest"]]
    text = (f"The tracks {word} {res['nearest']} (nearest in {m['p_nearest']:.0%} of {res['n_boot']} bootstrap "
            f"replicates; distance {m['distance']:.2f} x the free speed, 95% CI {m['ci95'][0]:.2f}-{m['ci95'][1]:.2f})")
    if not res.get("fits", True):
        text += (f", but match it less closely than its own runs match each other ({m['self_distance']:.2f}): none "
                 f"of the simulated mechanisms fits them well")
    return text + "."


def _map(ax, meas: dict) -> None:
    """The measured points, in groups (red) or not (grey), and the groups of the frame with the most."""
    from matplotlib.patches import Circle
    pts, groups = meas["_points"], meas["groups"]
    inside = pts.group >= 0
    ax.scatter(*pts.xy[~inside].T, s=0.2, c="0.75", rasterized=True)
    ax.scatter(*pts.xy[inside].T, s=0.2, c="C3", rasterized=True)
    if groups:
        frames = [g["frame"] for g in groups]
        f = max(set(frames), key=frames.count)
        for g in groups:
            if g["frame"] == f:
                ax.add_patch(Circle(g["centre_um"], g["radius_um"], fill=False, color="C0", lw=1))
        ax.set_title(f"rotating groups (red), circles at {groups[frames.index(f)]['time_min']:.0f} min", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (µm)")
    ax.set_ylabel("y (µm)")


def plot(res: dict, path: str, title: str = "") -> str:
    """Left: the measured tracks with the rotating groups found in them; middle: the measured speed distribution
    in groups beside each mechanism's; right: the distances with their bootstrap intervals; the verdict above."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (m, a, b) = plt.subplots(1, 3, figsize=(14, 4.2), gridspec_kw={"width_ratios": [3, 3, 2]})
    _map(m, res["_measured"])
    bins = np.linspace(0, 3, 31)
    a.hist(res["_measured"]["_in"], bins=bins, density=True, color="0.75", label="measured")
    for m, runs in res["_references"].items():
        s = np.concatenate([r["_in"] for r in runs]) if runs else np.zeros(0)
        if len(s):
            a.hist(s, bins=bins, density=True, histtype="step", lw=2, label=m)
    a.axvline(1.0, color="k", lw=0.8, ls=":")
    a.set_xlabel("speed in rotating groups / free-cell speed")
    a.set_ylabel("density")
    a.legend(frameon=False)
    names = list(res["mechanisms"])
    d = [res["mechanisms"][m]["distance"] for m in names]
    ci = [res["mechanisms"][m].get("ci95", [np.nan, np.nan]) for m in names]
    err = np.clip(np.array([[di - c[0], c[1] - di] for di, c in zip(d, ci)]).T, 0, None)  # a CI may miss d
    b.barh(names, d, xerr=np.nan_to_num(err), color="0.6", capsize=4)
    b.set_xlabel("distance to the measured (× free speed)")
    b.invert_yaxis()
    fig.suptitle((title + "\n" if title else "") + sentence(res), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
