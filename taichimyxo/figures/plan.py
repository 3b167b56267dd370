"""A figure's runs: its sweep file at the chosen scale and seeds, their points and folders, and what they cost.

`figures --scale` and `--seeds` write a copy of the figure's sweep file (sweeps/figures/NAME.toml) with `scale` and
`seeds` set into OUT/NAME/sweep.toml, and the runs are that sweep's: `python -m taichimyxo sweep OUT/NAME/sweep.toml`
runs the same folders, so a figure's runs can be finished either way, and a rerun skips the finished ones."""
from __future__ import annotations

import csv
import json
import math
import re
import statistics
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..io.scene import SceneError
from ..sweep.rundir import state, write_text_atomic
from ..sweep.spec import load_sweep
from .specs import MIN_CELLS, SCALES, Figure

THROUGHPUT_CSV = Path(__file__).resolve().parents[2] / "benchmarks" / "results" / "throughput.csv"
# a step once aggregates have formed costs this many times the benchmark's step at the start (paper-scale S3 at its
# state after 1 simulated hour against its start; docs/performance.md)
FORMED_STATE_FACTOR = 3.3
THREADS_CSV = THROUGHPUT_CSV.with_name("threads.csv")
TOP_KEYS = ("seeds", "scale", "box_um", "hours")
FINISHED = ("done", "recorded", "shared")   # completed here, or elsewhere (its record), or another figure's run


class FigureError(SceneError):
    """Bad input to `figures`: one line, exit 2, nothing written."""


@dataclass
class FigureRuns:
    figure: Figure
    scale_name: str
    root: Path                   # OUT/NAME: the copy of the sweep file and runs/
    text: str                    # the copy of the sweep file
    sweep: object                # taichimyxo.sweep.Sweep
    points: list                 # taichimyxo.sweep.Point, in the sweep's order
    records: Path | None = None  # where finished runs are kept as records (taichimyxo.figures.records)

    def run_dir(self, point) -> Path:
        return point.run_dir(self.root)

    def trajectory(self, point) -> Path:
        return self.run_dir(point) / f"{point.scene.name}.gsd"

    def run_state(self, point) -> str:
        return state(self.run_dir(point))

    def fraction_done(self, point) -> float:
        """The share of the run's steps its checkpoint holds (0 without one, or one of other parameters)."""
        import numpy as np

        from ..io.outdir import outputs
        path = outputs(self.run_dir(point), point.scene.name)["ckpt"]
        try:
            with np.load(path, allow_pickle=False) as z:
                if str(z["fingerprint"]) != point.scene.fingerprint():
                    return 0.0
                return min(1.0, int(z["step"]) / max(1, point.scene.steps))
        except (OSError, KeyError, ValueError):
            return 0.0

    def record_file(self, point) -> Path | None:
        """The run's record file (taichimyxo.figures.records) where there is one: its own, else another figure's
        record of the same run (records.shared_record)."""
        from .records import record_path, shared_record
        if self.records is None:
            return None
        path = record_path(self.records, self, point)
        return path if path.is_file() else shared_record(self.records, point, self.shows_start(point))

    def shows_start(self, point) -> bool:
        """A panel of this figure shows the point's first frame."""
        return any(p.frame == "first" and self.first_seed_point(p.match) is point for p in self.figure.panels)

    def record(self, point):
        """The run's record read back (taichimyxo.figures.records.Record), or None."""
        from .records import Record
        path = self.record_file(point)
        return Record(path) if path is not None else None

    def states(self) -> list[str]:
        """Each run's state (taichimyxo.sweep.rundir.state), "recorded" where only its record is left, "shared"
        where another figure's record of the same run stands for it."""
        from .records import record_dir
        out = []
        for p in self.points:
            st = self.run_state(p)
            rec = self.record_file(p) if st != "done" else None
            if rec is not None:
                st = "recorded" if rec.parent == record_dir(self.records, self) else "shared"
            out.append(st)
        return out

    def frame(self, point, which: str):
        """The first or last Frame of the run: from its trajectory, else from its record (None: neither)."""
        from .records import panel_frame
        fr = panel_frame(self.trajectory(point), which)
        if fr is None:
            rec = self.record(point)
            fr = rec.frame(which) if rec is not None else None
        return fr

    def analysis(self, point) -> dict | None:
        """The run's analysis summary: the JSON beside its trajectory, else its record's."""
        path = self.trajectory(point).with_suffix(".analysis.json")
        if self.run_state(point) == "done" and path.is_file():
            return json.loads(path.read_text())
        rec = self.record(point)
        return rec.analysis if rec is not None else None

    def first_seed_point(self, match: dict):
        """The point of the figure's first seed whose swept values include `match`."""
        seed = self.sweep.seeds[0]
        return next((p for p in self.points if p.seed == seed and all(
            _same(p.overrides.get(k, _scene_value(p.scene, k)), v) for k, v in match.items())), None)


def _scene_value(scene, key: str):
    sec, k = key.split(".")
    return scene.raw[sec][k]


def _same(a, b) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        return math.isclose(float(a), float(b), rel_tol=1e-9)
    return a == b


def sweep_text(figure: Figure, scale: float, seeds: int | None, hours: float | None = None,
               extra_set: dict | None = None) -> str:
    """The figure's sweep file with `scale` (and `seeds`, `hours` where given) set; `extra_set` adds [set] keys."""
    try:
        text = figure.sweep_path.read_text()
    except OSError as e:
        raise FigureError(f"figures {figure.name}: sweep file {figure.sweep_path}: {e.strerror or e}") from None
    head, sep, tail = text.partition("\n[")
    pat = re.compile(rf"^\s*({'|'.join(TOP_KEYS)})\s*=.*$", re.M)
    kept = {k: m.group(0) for m in pat.finditer(head) for k in [m.group(1)]}
    head = pat.sub("", head).rstrip("\n")
    lines = [f"scale = {scale:g}" if scale != 1.0 else "",
             f"seeds = {seeds}" if seeds else kept.get("seeds", ""),
             f"hours = {hours:g}" if hours else kept.get("hours", "")]
    body = head + "\n" + "\n".join(x.strip() for x in lines if x) + "\n" + sep + tail
    if extra_set:
        add = "".join(f"{k} = {_toml(v)}\n" for k, v in extra_set.items())
        body = body.replace("\n[set]\n", "\n[set]\n" + add) if "\n[set]\n" in body else body + "\n[set]\n" + add
    return f"# written by `python -m taichimyxo figures {figure.name}` from {figure.sweep_path.name}\n" + body


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    return f'"{v}"' if isinstance(v, str) else repr(v)


def plan_figure(figure: Figure, scale_name: str, out: Path, seeds: int | None = None, *, scale: float | None = None,
                hours: float | None = None, extra_set: dict | None = None,
                min_cells: int = MIN_CELLS) -> FigureRuns:
    """The figure's runs at --scale `scale_name` (or a bare `scale` factor, for tests), validated, nothing written.
    A scale that leaves any run fewer than `min_cells` cells is a FigureError."""
    factor = SCALES[scale_name] if scale is None else float(scale)
    text = sweep_text(figure, factor, seeds, hours, extra_set)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{figure.name}.toml"
        path.write_text(text)
        try:
            sweep = load_sweep(path)
            points = sweep.points()
        except SceneError as e:
            raise FigureError(f"figures {figure.name} --scale {scale_name}: {str(e).replace(str(path) + ': ', '')}"
                              ) from None
    few = min(points, key=lambda p: p.scene.n_cells)
    if few.scene.n_cells < min_cells:
        w, h = few.scene.box
        raise FigureError(f"figures {figure.name} --scale {scale_name}: {few.scene.n_cells} cells in a {w:g} x {h:g} "
                          f"µm box, fewer than the {min_cells} a panel needs; use a larger --scale")
    return FigureRuns(figure, scale_name, Path(out) / figure.name, text, sweep, points)


def write_sweep_file(runs: FigureRuns) -> Path:
    """OUT/NAME/sweep.toml, the sweep whose runs the figure shows (the orchestrator reads it back from there)."""
    runs.root.mkdir(parents=True, exist_ok=True)
    path = runs.root / "sweep.toml"
    write_text_atomic(path, runs.text)
    return path


# ------------------------------------------------------------------------------------------------ cost
def _bench_scene(scene) -> str:
    """The benchmark scene whose cost per particle-step stands for this scene's."""
    if scene.raw["population"]["start"] == "aligned":
        return "S11"
    if scene.raw["slime"]["enabled"]:
        return "S17"
    return {"none": "S1", "passive": "S2", "active": "S3", "adhesion": "S4"}.get(scene.guiding, "S3")


def bench_rates(path: Path = THROUGHPUT_CSV) -> dict:
    """benchmark scene -> [(particles, particle-steps/s)] from the benchmark's table (empty when it is absent)."""
    out: dict = {}
    try:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                if row.get("precision") == "mixed" and row.get("integrator") == "explicit":
                    out.setdefault(row["scene"], []).append((int(row["particles"]),
                                                             float(row["particle_steps_per_s"])))
    except (OSError, ValueError, KeyError):
        return {}
    return out


def _measured_kind(scene) -> tuple:
    """Runs whose measured cost stands for each other's: the same kind of scene and integrator (an imex step costs
    several explicit ones)."""
    return _bench_scene(scene), scene.integrator


def measured_rates(records: Path | None) -> dict:
    """(benchmark scene kind, integrator) -> [(particles, one-thread particle-steps/s)] of finished figure runs kept
    as records (taichimyxo.figures.records): whole runs, formed states included. A run on N threads counts at its
    rate / thread_speedup(N), the one-thread rate it stands for (so a paper-scale run on two cores prices the next
    one at its own size)."""
    out: dict = {}
    if records is None or not Path(records).is_dir():
        return out
    from ..io.scene import Scene
    from .records import Record
    speedup: dict = {}                      # threads -> thread_speedup, its table read once per count
    for path in sorted(Path(records).glob("*/*.npz")):
        try:
            s = Record(path).summary or {}
            threads = int(s.get("cpu_threads") or 0)
            if threads < 1 or not s.get("completed") or not s.get("wall_seconds_total"):
                continue
            scene = Scene.from_dict(s["scene_values"])
        except (OSError, ValueError, KeyError, TypeError, SceneError):
            continue
        if threads not in speedup:
            speedup[threads] = thread_speedup(threads)[0]
        out.setdefault(_measured_kind(scene), []).append(
            (int(s["particles"]), s["steps"] * s["particles"] / s["wall_seconds_total"] / speedup[threads]))
    return out


def run_seconds(scene, rates: dict, measured: dict | None = None) -> float | None:
    """Estimated wall seconds of one run on one thread: its steps x particles at the rate of finished runs of the
    same kind of scene and integrator (`measured`, measured_rates) at the nearest size (the median where several
    ran at it: runs of one kind differ by their seed and by what ran beside them), else at the benchmark's rate
    times FORMED_STATE_FACTOR; None without either."""
    particles = scene.n_cells * scene.N

    def nearest(rows):
        dist = [abs(math.log(n / max(particles, 1))) for n, _ in rows]
        best = min(dist)
        return statistics.median(r for (_, r), d in zip(rows, dist) if d == best)
    rows = (measured or {}).get(_measured_kind(scene))
    if rows:
        return scene.steps * particles / nearest(rows)
    rows = rates.get(_bench_scene(scene)) or rates.get("S3")
    if not rows:
        return None
    return scene.steps * particles / nearest(rows) * FORMED_STATE_FACTOR


def thread_speedup(threads: int, path: Path = THREADS_CSV) -> tuple[float, int]:
    """How many times faster one run goes on `threads` CPU threads than on one, and the thread count that was
    measured: the median over the benchmark's states (benchmarks/threads.py) at the largest measured count <=
    threads. (1.0, 1) for one thread or without the table."""
    by_count: dict = {}
    try:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                by_count.setdefault(int(row["threads"]), []).append(float(row["speedup_vs_first"]))
    except (OSError, ValueError, KeyError):
        return 1.0, 1
    counts = [n for n in by_count if 1 < n <= threads]
    if not counts:
        return 1.0, 1
    n = max(counts)
    return max(1.0, statistics.median(by_count[n])), n


def makespan(seconds: list[float], jobs: int) -> float:
    """Wall time of runs of these lengths, `jobs` at a time, longest first."""
    ends = [0.0] * max(1, jobs)
    for s in sorted(seconds, reverse=True):
        i = ends.index(min(ends))
        ends[i] += s
    return max(ends) if seconds else 0.0
