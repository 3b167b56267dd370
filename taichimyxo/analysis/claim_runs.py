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


def is_record(path) -> bool:
    """A run kept by `figures` as a record (taichimyxo.figures.records), not a trajectory."""
    return os.fspath(path).endswith(".npz")


def check_record(path, every: int = 1, v_b: float | None = None, **params):
    """Refuse, before any work, a record claims cannot use: missing, not a record, without its scene or analysis,
    or asked to be analysed otherwise than it was (a record keeps its run's analysis, not its frames). Returns
    the Record."""
    import zipfile

    from ..figures.records import Record
    from ..io.trajectory import TrajectoryError
    if not os.path.isfile(path):
        raise TrajectoryError(f"record {path} not found")
    try:
        rec = Record(path)
        analysis = rec.analysis
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
        why = str(e).splitlines()[0] if str(e) else repr(e)
        raise TrajectoryError(f"{path} is not a run record of `figures` ({why})") from None
    if not analysis or not rec.meta:
        raise TrajectoryError(f"{path}: the record keeps no analysis summary or no scene; give its run's trajectory")
    m, kept = analysis.get("meta", {}), analysis.get("parameters", {})
    made_vb = float(m.get("v_b_um_per_min", float("nan")))
    other = [k for k, x in params.items() if kept.get(k) != x]
    if int(m.get("every", 1)) != every or (v_b is not None and not math.isclose(v_b, made_vb)) or other:
        raise TrajectoryError(f"{path}: a record keeps its run's analysis as made (every {m.get('every', 1)}, v_b "
                              f"{made_vb:g} µm/min{', ' + ', '.join(other) + ' as kept' if other else ''}) and "
                              "cannot be analysed otherwise; give its run's trajectory")
    return rec


def check_run_file(path, every: int = 1, v_b: float | None = None, **params) -> None:
    """check_trajectory for a trajectory, check_record for a record: bad input refused before any analysis."""
    from ..io.trajectory import check_trajectory
    if is_record(path):
        check_record(path, every, v_b, **params)
    else:
        check_trajectory(path)


def load_runs(paths, every: int = 1, v_b: float | None = None, progress=None, **params) -> list[dict]:
    """Analyse each trajectory; a record (`figures --records`) brings the analysis its run made when it finished.
    Every path is checked first (a missing or unreadable file is a TrajectoryError before any analysis). Returns
    dicts(label, path, kind, v_b, summary, scene, record)."""
    from ..io.trajectory import check_trajectory, read_frames, read_scene
    paths = [os.fspath(p) for p in paths]
    if not paths:
        raise ValueError("claims needs at least one trajectory")
    scenes, kept = [], {}
    for p in paths:
        if is_record(p):
            kept[p] = check_record(p, every, v_b, **params)
            scenes.append(kept[p].meta)
        else:
            check_trajectory(p)
            scenes.append(read_scene(p))
    labels = [os.path.splitext(os.path.basename(p))[0] for p in paths]
    runs = []
    for p, sc, lab in zip(paths, scenes, labels):
        if p in kept:
            s = kept[p].analysis
            vb = float(s["meta"]["v_b_um_per_min"])
        else:
            if progress:
                progress(f"analysing {p}")
            vb = v_b if v_b is not None else float((sc.get("cell") or {}).get("speed_um_per_min", 4.0) or 4.0)
            s = analyze_frames(read_frames(p, every=every), v_b=vb, **params)
        label = lab if labels.count(lab) == 1 else p
        runs.append(dict(label=label, path=os.path.abspath(p), kind=run_kind(sc), v_b=vb, summary=s, scene=sc,
                         record=is_record(p)))
    return runs


def rigidity_unkept(r) -> bool:
    """A run read from a record whose aggregate tracks keep no per-frame rigidity exponents (an older record)."""
    return bool(r.get("record")) and any("rigidity_exponent" not in t["series"] for t in r["summary"]["tracks"])


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


def free_speed(r, series: str = "free_cell_speed_um_per_min"):
    """A free-cell speed series of run r / v_b: (mean, SE, frames) over its frames."""
    ts = r["summary"]["timeseries"]
    return series_mean_se(np.asarray(ts[series], float) / r["v_b"])


def free_speed_text(r, m, se, n) -> tuple[str, dict]:
    """The free-cell row's text for run r (its free_speed m, se over n frames) and, where the analysis kept it, the
    part of that speed along each particle's forward tangent (docs/measures.md: slime turns heads sideways)."""
    if not n:
        return f"{r['label']}: no free cells", {}
    text = f"{r['label']}: {plus_minus(m, se)} v_b"
    ts = r["summary"]["timeseries"]
    if "free_cell_speed_along_um_per_min" not in ts:              # an analysis made before it was kept
        return text, {}
    am, ase, an = free_speed(r, "free_cell_speed_along_um_per_min")
    if not an:
        return text, {}
    return text + f" (along the axis {plus_minus(am, ase)})", dict(along_mean_vb=am, along_se=ase)
