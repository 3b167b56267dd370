"""What ``python -m taichimyxo tracks`` does: a lab's cell tracks (or a simulated run's centroids) measured, and,
given simulated runs of the guiding mechanisms, the paper's proposed test as a report (docs/lab-tracks.md).

    import taichimyxo as tm
    res = tm.tracks_report("spots.csv", pixel_um=0.13, frame_s=30, against=["REFS"], out_dir="report")
    print(res["report"]["verdict"])

Every input is checked before any is measured: a missing file, a folder with no run, a run whose mechanism is none
of the paper's gives one line (SceneError) and nothing is written.
"""
from __future__ import annotations

import glob
import json
import os

import numpy as np

from ..io.scene import SceneError

# a run's mechanism, from the scene it stores: its guiding kind, or slime trails where slime is on
MECHANISMS = {"active": "active following", "adhesion": "adhesion", "passive": "passive following"}


def mechanism_of(scene: dict) -> str | None:
    """The guiding mechanism a resolved scene simulates (None for a scene with neither guiding nor slime)."""
    kind = scene.get("guiding", {}).get("kind", "none")
    if kind in MECHANISMS:
        return MECHANISMS[kind]
    if scene.get("slime", {}).get("enabled", False):
        return "slime trails"
    return None


def find_runs(paths) -> list[tuple[str, str]]:
    """(mechanism, trajectory) for each simulated run in paths: .gsd files, or folders searched for them (a sweep's
    --out, or a run's folder)."""
    from ..io.trajectory import read_scene
    found = []
    for p in paths:
        if os.path.isdir(p):
            files = sorted(glob.glob(os.path.join(p, "**", "*.gsd"), recursive=True))
            if not files:
                raise SceneError(f"--against {p}: no simulated run (.gsd) in this folder; make the references with "
                                 f"`python -m taichimyxo sweep sweeps/mechanisms.toml --out {p}`")
        elif os.path.isfile(p):
            files = [p]
        else:
            raise SceneError(f"--against {p}: no such file or folder")
        for f in files:
            try:
                scene = read_scene(f)
            except Exception as e:                              # noqa: BLE001 - a foreign or broken file: say which
                raise SceneError(f"--against {f}: not a taichimyxo trajectory ({type(e).__name__})") from None
            m = mechanism_of(scene)
            if m is None:
                raise SceneError(f"--against {f}: its scene has no guiding and no slime; give runs of active "
                                 f"following, adhesion or slime trails (sweeps/mechanisms.toml)")
            found.append((m, f))
    return found


def tracks_from_run(path: str):
    """A simulated run's cells as centroid tracks (taichimyxo.io.tracks.from_frames)."""
    from ..io.tracks import from_frames
    from ..io.trajectory import read_frames
    return from_frames(read_frames(path))


def load_tracks(path, **reading):
    """Tracks from a lab's file (taichimyxo.io.tracks.read_tracks) or a simulated run (.gsd)."""
    from ..io.tracks import read_tracks
    if str(path).endswith(".gsd"):
        if not os.path.isfile(path):
            raise SceneError(f"tracks {path}: no such file")
        return tracks_from_run(str(path))
    return read_tracks(path, **reading)


def measure(tracks, v_b: float | None = None, **params) -> dict:
    """Every centroid measure: the speed distribution, rotating groups and the speeds inside and outside them with
    the speed against distance from a group's centre, and direction reversals with run durations."""
    from ..analysis.lab_tracks import reversals, speed_distribution
    from ..analysis.mechanism_report import in_group_speeds
    g = in_group_speeds(tracks, v_b=v_b, **params)
    v_ref = g["v_ref_um_per_min"]
    scale = v_ref if np.isfinite(v_ref) else 4.0
    rev = reversals(tracks, v_b=scale)
    return {"source": tracks.source, "frame_s": tracks.frame_s, "counts": tracks.counts,
            "speed_distribution_vref": speed_distribution(tracks, v_b=scale),
            "groups": {k: v for k, v in g.items() if not k.startswith("_") and k != "groups"},
            "group_list": g["groups"],
            "reversals": {k: v for k, v in rev.items() if k != "times_s"},
            "not_measurable": "which pole leads, head-to-tail contacts and cell bending need cell outlines or "
                              "poles; centroid tracks do not carry them"}


def _json(obj, path: str) -> None:
    def clean(o):
        if isinstance(o, dict):
            return {k: clean(v) for k, v in o.items() if not str(k).startswith("_")}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if isinstance(o, (np.floating, float)):
            return None if not np.isfinite(o) else float(o)
        if isinstance(o, np.integer):
            return int(o)
        if isinstance(o, np.ndarray):
            return clean(o.tolist())
        return o
    with open(path, "w") as f:
        json.dump(clean(obj), f, indent=1)


def _markdown(res: dict) -> str:
    from ..analysis.mechanism_report import sentence
    r = res["report"]
    lines = [f"# Which guiding mechanism the tracks match: {res['measures']['source']}", "",
             sentence(r), "",
             f"Frame interval {r['frame_s']:g} s (the runs resampled to it); {r['measured_points']} measured points "
             f"in rotating groups; speeds in units of the free-cell speed (measured: "
             f"{res['measures']['groups']['v_ref_from']}; the runs: their scene's v_b).", "",
             "![report](report.png)", "",
             "| mechanism | runs | points in groups | median speed in groups | edge speed | distance | 95% CI | "
             "nearest in | own runs' spread |", "|---|---|---|---|---|---|---|---|---|"]
    for m, row in r["mechanisms"].items():
        ci = row.get("ci95")
        lines.append(f"| {m} | {row['runs']} | {row['points']} | {row['median_vref']:.2f} | "
                     f"{row['edge_median_vref']:.2f} | {row['distance']:.3f} | "
                     + (f"{ci[0]:.3f}-{ci[1]:.3f} | {row['p_nearest']:.0%} |" if ci else "- | - |")
                     + f" {row['self_distance']:.3f} |")
    g = res["measures"]["groups"]
    lines += ["", f"Measured: median speed in groups {g['speed_in_median_vref']:.2f}, edge "
              f"{g['edge_speed_median_vref']:.2f}, outside {g['speed_out_median_vref']:.2f} (v_ref = "
              f"{g['v_ref_um_per_min']:.2f} µm/min); {g['fraction_in_groups']:.0%} of points in groups.", ""]
    return "\n".join(lines)


def tracks_report(path, *, pixel_um: float | None = None, frame_s: float | None = None, time_unit: str = "s",
                  v_b: float | None = None, against=(), out_dir: str | None = None, n_boot: int = 500,
                  seed: int = 0, plots: bool = True, progress=None, **reading) -> dict:
    """Measure tracks (a lab's file or a .gsd) and, given runs of the mechanisms (`against`: folders or .gsd
    files), compare. Writes tracks.json and, with `against`, report.json, report.md, report.png in out_dir."""
    from ..analysis.mechanism_report import plot, report
    say = progress or (lambda msg: None)
    runs = find_runs(against) if against else []                 # every input checked before any work
    if v_b is not None and not v_b > 0:
        raise SceneError(f"tracks: v_b (--v-b) = {v_b!r}: expected the free-cell speed above 0 in µm/min, e.g. 4")
    if n_boot < 50:
        raise SceneError(f"tracks: n_boot (--boot) = {n_boot}: expected at least 50 bootstrap replicates")
    reading = dict(reading, pixel_um=pixel_um, frame_s=frame_s, time_unit=time_unit)
    tracks = load_tracks(path, **(reading if not str(path).endswith(".gsd") else {}))
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
    say(f"tracks: {tracks.counts.get('tracks_kept')} tracks of {tracks.source}")
    res = {"measures": measure(tracks, v_b=v_b), "files": []}
    if out_dir:
        res["files"].append(os.path.join(out_dir, "tracks.json"))
        _json(res["measures"], res["files"][-1])
    if runs:
        from ..io.trajectory import read_scene
        refs: dict[str, list] = {}
        ref_vb: dict[str, list] = {}
        for m, f in runs:
            say(f"tracks: reference {m}: {f}")
            refs.setdefault(m, []).append(tracks_from_run(f))
            ref_vb.setdefault(m, []).append(float(read_scene(f).get("cell", {}).get("speed_um_per_min", 4.0)))
        r = report(tracks, refs, v_b=v_b, n_boot=n_boot, seed=seed, reference_v_b=ref_vb)
        res["report"] = r
        if out_dir:
            for name, write in (("report.json", lambda p: _json(r, p)),
                                ("report.md", lambda p: open(p, "w").write(_markdown(res))),
                                *((("report.png", lambda p: plot(r, p, title=str(path))),) if plots else ())):
                p = os.path.join(out_dir, name)
                write(p)
                res["files"].append(p)
    return res
