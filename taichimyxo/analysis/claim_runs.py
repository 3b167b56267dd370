"""The runs a claims table is measured on: each trajectory analysed and sorted by the guiding its scene stored, and
the small statistics the claims and their plots share (claims.py says how each claim is measured)."""
from __future__ import annotations

import math
import os

import numpy as np

from .stats import series_mean_se
from .summary import analyze_frames

MIN_RIGID_CELLS = 20

KINDS = {  # kind -> (label, the scene to run for it)
    "non-guided": ("non-guided", "S1 (guiding.kind = none, slime off)"),
    "passive": ("passive following", "S2 (guiding.kind = passive)"),
    "active": ("active following", "S3 (guiding.kind = active)"),
    "adhesion": ("adhesion", "S4 (guiding.kind = adhesion)"),
    "slime": ("slime trails", "S16 or S17 (slime.enabled = true)"),
    "spiral": ("spiral start", "S9 or S10 (population.start = spiral)"),
    "dense": ("high-density aligned start", "S11-S14 (population.start = aligned)"),
}


def run_kind(scene: dict) -> str:
    """The guiding of a stored scene: slime (slime trails on), else guiding.kind (none -> non-guided); a run that
    started as a prearranged spiral (S6 Fig) or from the dense aligned packing (Fig 3) is its own experiment, not a
    random low-density start's."""
    start = (scene.get("population") or {}).get("start")
    if start == "spiral":
        return "spiral"
    if start == "aligned":
        return "dense"
    if (scene.get("slime") or {}).get("enabled"):
        return "slime"
    k = str((scene.get("guiding") or {}).get("kind", "none"))
    return "non-guided" if k == "none" else k


def needs(*kinds: str) -> str:
    art = lambda w: "an" if w[0] in "aeiou" else "a"       # noqa: E731
    return "needs " + " and ".join(f"{art(KINDS[k][0])} {KINDS[k][0]} run ({KINDS[k][1]})" for k in kinds)


def mean_se(x):
    """(mean, standard error, n) of the finite values of x."""
    x = np.asarray([v for v in x if v is not None], float)
    x = x[np.isfinite(x)]
    n = len(x)
    if n == 0:
        return float("nan"), float("nan"), 0
    return float(x.mean()), float(x.std(ddof=1) / math.sqrt(n)) if n > 1 else float("nan"), n


def plus_minus(m, se, spec=".2f"):
    if not math.isfinite(m):
        return "n/a"
    return f"{m:{spec}} ± {se:{spec}}" if math.isfinite(se) else f"{m:{spec}}"


def load_runs(paths, every: int = 1, v_b: float | None = None, progress=None, **params) -> list[dict]:
    """Analyse each trajectory. Every path is checked first (a missing or unreadable file is a TrajectoryError before
    any analysis). Returns dicts(label, path, kind, v_b, summary, scene)."""
    from ..trajectory import check_trajectory, read_frames, read_scene
    paths = [os.fspath(p) for p in paths]
    if not paths:
        raise ValueError("claims needs at least one trajectory")
    scenes = []
    for p in paths:
        check_trajectory(p)
        scenes.append(read_scene(p))
    labels = [os.path.splitext(os.path.basename(p))[0] for p in paths]
    runs = []
    for p, sc, lab in zip(paths, scenes, labels):
        if progress:
            progress(f"analysing {p}")
        vb = v_b if v_b is not None else float((sc.get("cell") or {}).get("speed_um_per_min", 4.0) or 4.0)
        s = analyze_frames(read_frames(p, every=every), v_b=vb, **params)
        label = lab if labels.count(lab) == 1 else p
        runs.append(dict(label=label, path=os.path.abspath(p), kind=run_kind(sc), v_b=vb, summary=s, scene=sc))
    return runs


def runs_of(runs, *kinds):
    return [r for r in runs if r["kind"] in kinds]


def stable_tracks(r):
    return [t for t in r["summary"]["tracks"] if t["stable"]]


def speed_span_min(r) -> float:
    """Minutes from a run's first analysed frame with speeds to its last (the first frame of a run has none)."""
    m = r["summary"]["meta"]
    t0, t1 = m["time_range_min"]
    without = set(m.get("frames_without_speed_min") or [])
    first = min((t for t in r["summary"]["timeseries"]["time_min"] if t not in without), default=t1)
    return float(t1 - max(t0, first))


def free_speed(r):
    ts = r["summary"]["timeseries"]
    return series_mean_se(np.asarray(ts["free_cell_speed_um_per_min"], float) / r["v_b"])
