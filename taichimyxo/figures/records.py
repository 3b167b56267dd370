"""A finished figure run kept as a record: what the figure needs of it, small enough to commit.

A figure's runs last hours, and their folders (trajectory, checkpoint) are tens of megabytes; a figure needs of each
run only the frames its panels show (the last; the first for a panel of the start) and its analysis summary (the
stiffness series' measures). `figures` writes one record per finished run, ``RECORDS/NAME.SCALE/<run folder>.npz``
(60-140 KB for 500 cells), and composes from the record where the run's folder is gone, so a figure whose runs
finished on several machines, or in several sessions of one that was wiped in between, is still composed from all
of them (docs/figures.md, "Records"). The record's name carries the run folder's key, the hash of the resolved
scene: a record of other physics never stands in for a run."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..io.frame import Frame

RECORD_VERSION = 1


def record_dir(records: Path, runs) -> Path:
    return Path(records) / f"{runs.figure.name}.{runs.scale_name}"


def record_path(records: Path, runs, point) -> Path:
    return record_dir(records, runs) / f"{point.dir_name}.npz"


def panel_frame(path: Path, which: str):
    """The first or last Frame of a trajectory (None when it is missing or empty)."""
    from ..io.trajectory import count_frames, read_frames
    if not path.is_file():
        return None
    n = count_frames(str(path))
    if n == 0:
        return None
    return next(read_frames(str(path), start=0 if which == "first" else n - 1), None)


def _frame_arrays(prefix: str, fr: Frame) -> dict:
    out = {f"{prefix}_positions": fr.positions.astype(np.float32),
           f"{prefix}_engine_direction": np.asarray(fr.engine_direction, np.int8),
           f"{prefix}_speed": np.asarray(fr.particle_speed, np.float32),
           f"{prefix}_scalars": np.array([fr.time_s, fr.step, fr.box[0], fr.box[1], fr.width_um], np.float64)}
    if fr.segment_strain is not None:
        out[f"{prefix}_strain"] = np.asarray(fr.segment_strain, np.float32)
    return out


def _frame(z, prefix: str, meta: dict) -> Frame:
    t, step, lx, ly, width = (float(v) for v in z[f"{prefix}_scalars"])
    strain = z[f"{prefix}_strain"].astype(np.float64) if f"{prefix}_strain" in z else None
    return Frame(time_s=t, step=int(step), box=(lx, ly), width_um=width,
                 positions=z[f"{prefix}_positions"].astype(np.float64),
                 engine_direction=z[f"{prefix}_engine_direction"], particle_speed=z[f"{prefix}_speed"],
                 segment_strain=strain, meta=meta)


TRACK_SERIES = ("time_min", "n_cells", "rigidity_exponent")    # what the stiffness series and claims read of them


def slim_analysis(a: dict) -> dict:
    """The analysis summary as a record keeps it: everything but the per-frame series of each aggregate track beyond
    TRACK_SERIES and each track's first and last aggregate (a 6 h run's tracks are 90 % of its summary's size), the
    trajectory named without its folder."""
    tracks = [{**{k: v for k, v in tr.items() if k not in ("start", "end", "last", "series")},
               "series": {k: v for k, v in tr.get("series", {}).items() if k in TRACK_SERIES}}
              for tr in a.get("tracks", [])]
    meta = {**a.get("meta", {})}
    if meta.get("trajectory"):
        meta["trajectory"] = os.path.basename(str(meta["trajectory"]))     # a record carries no machine's paths
    return {**a, "meta": meta, "tracks": tracks}


def write_record(path: Path, trajectory: Path, analysis: Path | None, summary: Path | None,
                 first: bool) -> Path:
    """The record of one finished run: its last frame (and first, when a panel shows the start), its analysis
    summary and run summary as JSON text. Written to a temporary name and renamed: never half a record."""
    last = panel_frame(trajectory, "last")
    arrays = _frame_arrays("last", last)
    if first:
        arrays.update(_frame_arrays("first", panel_frame(trajectory, "first")))
    texts = {"meta": json.dumps(last.meta, default=str)}
    if analysis is not None and analysis.is_file():
        texts["analysis"] = json.dumps(slim_analysis(json.loads(analysis.read_text())), separators=(",", ":"))
    if summary is not None and summary.is_file():
        texts["summary"] = summary.read_text()
    for k, v in texts.items():
        arrays[f"{k}_json"] = np.frombuffer(v.encode(), np.uint8)
    arrays["version"] = np.array(RECORD_VERSION)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)
    return path


class Record:
    """A record read back: frame("first" | "last") -> Frame or None, analysis and summary dicts or None."""

    def __init__(self, path: Path):
        self.path = Path(path)
        with np.load(self.path) as z:
            self._z = {k: z[k] for k in z.files}
        self.meta = self._json("meta") or {}

    def _json(self, key: str):
        a = self._z.get(f"{key}_json")
        return None if a is None else json.loads(a.tobytes().decode())

    @property
    def analysis(self) -> dict | None:
        return self._json("analysis")

    @property
    def summary(self) -> dict | None:
        return self._json("summary")

    def frame(self, which: str) -> Frame | None:
        return _frame(self._z, which, self.meta) if f"{which}_scalars" in self._z else None


_SUMMARIES: dict = {}     # (path, mtime) -> what shared_record compares, so each record is read once


def shared_record(records: Path, point, first: bool) -> Path | None:
    """A record another figure kept of this point's run: the same physics, seed and box (the scene's fingerprint,
    which leaves out names and outputs), the same duration, completed, with the start when this figure shows it
    (first). Fig 2's S1 and S3 runs are S2 Fig B's and S3 Fig B's first seeds: each is run once."""
    want = (point.scene.fingerprint(), float(point.scene.hours))
    for path in sorted(Path(records).glob("*/*.npz")):
        key = (str(path), path.stat().st_mtime_ns)
        if key not in _SUMMARIES:
            with np.load(path) as z:
                s = json.loads(z["summary_json"].tobytes().decode()) if "summary_json" in z.files else {}
                _SUMMARIES[key] = ((s.get("fingerprint"), float(s.get("scene_values", {}).get("run", {})
                                                                  .get("hours", -1))),
                                   bool(s.get("completed")), "first_scalars" in z.files)
        found, completed, has_first = _SUMMARIES[key]
        if found == want and completed and (has_first or not first):
            return path
    return None


def save_records(runs, records: Path) -> list[Path]:
    """A record of every finished run of the figure that has none (or an older one than its trajectory)."""
    return [path for pt in runs.points if (path := save_record(runs, pt, records)) is not None]


def save_record(runs, point, records: Path) -> Path | None:
    """The record of one finished run, where it has none or an older one than its trajectory (None: nothing to
    write). The first seed's runs keep their start too: another figure sharing the run may show it."""
    traj = runs.trajectory(point)
    if runs.run_state(point) != "done" or not traj.is_file():
        return None
    path = record_path(records, runs, point)
    if path.is_file() and path.stat().st_mtime >= traj.stat().st_mtime:
        return None
    first = point.seed == runs.sweep.seeds[0]
    return write_record(path, traj, traj.with_suffix(".analysis.json"), traj.with_suffix(".json"), first)
