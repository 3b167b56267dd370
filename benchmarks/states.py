"""The benchmark states: the configurations users' runs spend their time in, beside the scenes' starts.

    python benchmarks/states.py [--runs DIR]      # (re)makes benchmarks/states/S3-1h.npz
    python benchmarks/states.py --late           # (re)makes benchmarks/states/S3-6h.npz from the figures' record
    python benchmarks/states.py --measure --states "S3 6 h" --threads 2 [--profile]   # ms per step (+ per kernel)

- "S3 6 h": the paper-scale S3 (200 x 200 µm, 2000 cells, active following) as its 6 h run ends, the state the late
  hours of a run are spent in (about 145 rotating aggregates of ~10 cells; docs/figures.md, "S3 at the paper's
  scale"): the last frame of the figures' paper-scale run, kept in its record
  (docs/figures/records/Fig2.paper/), so the command needs no simulation and gives the same file every time.

- "S3 1 h": S3 at paper scale (200 x 200 µm, 2000 cells) with the structure it has after one simulated hour:
  rotating aggregates fed by streams. Made from the last frames of two half-scale S3 runs of one hour
  (sweeps/bench_states.toml; run here when DIR lacks them, about an hour on one core each), tiled 2 x 2 in the
  paper's box (seed 1 on the diagonal, seed 2 off it). Shipped as a small file, so every benchmark measures the same
  state without the hours of simulation; the command remakes it bit for bit (runs are bit-identical).
- "S13 dense": S13 (60 x 60 µm, 1440 cells aligned at 4e7 cells/cm², area fraction ~1, flexible cells, active
  following, k_c = 0.002 N/m) after DENSE_WARM_STEPS steps of its 2 ms from its start, placed from the scene's seed
  with population.aligned_tilt_deg = 0: the start is a lattice at exactly W (almost no pair in contact), which
  jams within that 0.6 s into real contacts everywhere, what the high-density scenes cost
  (benchmarks/results/dense_step.md). Its aligned rows hold no other count near S3's 2000 cells at that density.

`load(name)` gives (scene name, area multiple, start) for taichimyxo.interface.bench.measure: start is (positions,
engine_direction). `STATE_RUN[name]`: the run values a state is defined and
measured with, where they differ from its scene's defaults (S13 itself now runs imex-explicit at 20 ms).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from benchlib import HERE

STATE_DIR = HERE / "states"
S3_1H = STATE_DIR / "S3-1h.npz"
S3_6H = STATE_DIR / "S3-6h.npz"
S3_6H_RECORD = HERE.parent / "docs" / "figures" / "records" / "Fig2.paper" / "scene=S3_seed=1-b78ba39f18.npz"
SWEEP = HERE.parent / "sweeps" / "bench_states.toml"
STATES = ("S3 6 h", "S3 1 h", "S13 dense")
# the aligned start the dense states were defined with: rows at exactly W (the scenes' own start tilts each cell)
EXACT_ROWS = {"population": {"aligned_tilt_deg": 0.0}}
DENSE_WARM_STEPS = 300
# the explicit 2 ms step the dense state was defined with, so its rows compare with the earlier ones and with LAMMPS
STATE_RUN = {"S13 dense": {"integrator": "explicit", "dt_ms": 2.0}}


def load(name: str):
    """(scene, area multiple, start) of a benchmark state; start is None for a scene's own start."""
    if name == "S3 6 h":
        if not S3_6H.is_file():
            raise SystemExit(f"states: {S3_6H} is missing; make it with `python benchmarks/states.py --late`")
        z = np.load(S3_6H)
        return "S3", 1.0, (z["positions"], z["engine_direction"])
    if name == "S3 1 h":
        if not S3_1H.is_file():
            raise SystemExit(f"states: {S3_1H} is missing; make it with `python benchmarks/states.py`")
        z = np.load(S3_1H)
        return "S3", 1.0, (z["positions"], z["engine_direction"])
    if name == "S13 dense":
        from taichimyxo.io.scene import Scene
        from taichimyxo.physics.placement import initial_configuration
        return "S13", 1.0, initial_configuration(Scene.load("S13", EXACT_ROWS))
    raise SystemExit(f"states: unknown state {name!r}; known: {', '.join(STATES)}")


def local_area_fraction(positions: np.ndarray, box, cell_area_um2: float, radius_um: float = 5.0) -> float:
    """The area fraction a cell sees around it: the cells' area within radius_um of each cell's centre (each particle
    carrying an equal share of its cell's area), averaged over cells; periodic box."""
    from scipy.spatial import cKDTree
    box = np.asarray(box, float)
    n_cells, N = positions.shape[:2]
    pts = np.mod(positions.reshape(-1, 2), box)
    centres = np.mod(positions.mean(axis=1), box)
    counts = cKDTree(pts, boxsize=box).query_ball_point(centres, radius_um, return_length=True)
    return float(np.mean(counts) * cell_area_um2 / N / (np.pi * radius_um ** 2))


def last_frame(run_dir: Path):
    from taichimyxo.io.trajectory import count_frames, read_frames
    gsd = next(run_dir.glob("*.gsd"))
    fr = next(read_frames(str(gsd), start=count_frames(str(gsd)) - 1))
    return fr


def tile(frames) -> tuple[np.ndarray, np.ndarray]:
    """Two half-scale frames tiled 2 x 2 into a box twice as wide: a b / b a."""
    a, b = frames
    side = np.array(a.box, float)
    pos, ke = [], []
    for (i, j), fr in (((0, 0), a), ((1, 0), b), ((0, 1), b), ((1, 1), a)):
        pos.append(np.asarray(fr.positions, np.float64) + side * np.array([i, j]))
        ke.append(np.asarray(fr.engine_direction, np.int8))
    return np.concatenate(pos), np.concatenate(ke)


def completed(run_dir: Path) -> bool:
    """The run's summary (the JSON beside its trajectory) says it completed."""
    import json
    return any(json.loads(f.read_text()).get("completed") for f in run_dir.glob("*.json") if f.name != "point.json")


def make(runs: Path) -> Path:
    done = sorted(runs.glob("runs/seed=*"))
    if len(done) < 2 or not all(completed(d) for d in done):
        subprocess.run([sys.executable, "-m", "taichimyxo", "sweep", str(SWEEP), "--out", str(runs)], check=True)
        done = sorted(runs.glob("runs/seed=*"))
    frames = [last_frame(d) for d in done[:2]]
    for fr in frames:
        if abs(fr.time_s - 3600.0) > 1.0:
            raise SystemExit(f"states: a run in {runs} ends at {fr.time_s:.0f} s, not at one hour")
    pos, ke = tile(frames)
    STATE_DIR.mkdir(exist_ok=True)
    np.savez_compressed(S3_1H, positions=pos, engine_direction=ke, time_s=np.array(3600.0),
                        box=np.array(frames[0].box) * 2)
    print(f"states: wrote {S3_1H.relative_to(HERE.parent)} ({len(pos)} cells, {S3_1H.stat().st_size // 1024} KB)")
    return S3_1H


def make_late(record: Path = S3_6H_RECORD) -> Path:
    """The 6 h state from the record of the figures' paper-scale S3 run (its last frame)."""
    import json
    z = np.load(record, allow_pickle=False)
    meta = json.loads(bytes(z["meta_json"]).decode())
    scalars = z["last_scalars"]
    pos = np.asarray(z["last_positions"], np.float64)
    if pos.shape != (2000, 8, 2):
        raise SystemExit(f"states: {record} holds {pos.shape[0]} cells, not the paper-scale S3's 2000")
    STATE_DIR.mkdir(exist_ok=True)
    np.savez_compressed(S3_6H, positions=pos, engine_direction=np.asarray(z["last_engine_direction"], np.int8),
                        time_s=np.array(float(scalars[0])), box=np.array([200.0, 200.0]),
                        record=np.array(record.name))
    print(f"states: wrote {S3_6H.relative_to(HERE.parent)} ({len(pos)} cells at {float(scalars[0]) / 3600:.2f} h, "
          f"{S3_6H.stat().st_size // 1024} KB; record of {meta.get('scene', {}).get('name', record.stem)})")
    return S3_6H


ROWS = (("S3 6 h", None, None, True), ("S3 start", "S3", 1.0, False), ("S3 1 h", None, None, True),
        ("S13 dense", None, None, True))


def measure(steps: int, warm: int, names=None, profile: bool = False) -> list[dict]:
    """taichimyxo.interface.bench.measure of S3's start and of each benchmark state, in its STATE_RUN or else the
    scene's own step and precision (Taichi initialised by the caller), with the wall time of a full 6 h paper-scale S3
    at each one's cost per particle-step (S3's 16 000 particles, 6 h of its steps). profile: Taichi's kernel profiler
    table (each offloaded loop's count, min, mean and max time, warm-up steps included) printed after each state."""
    from taichimyxo.interface.bench import measure as package_measure
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime import backend
    s3 = Scene.load("S3")
    s3_particle_steps = 6 * 3600.0 / s3.dt * s3.n_cells * s3.N
    rows = []
    for label, scene, area, is_state in ROWS:
        if names and label not in names:
            continue
        start = None
        if is_state:
            scene, area, start = load(label)
        backend.restart()
        w = max(warm, DENSE_WARM_STEPS) if label == "S13 dense" else warm
        r = package_measure(scene, area, steps, w, run=STATE_RUN.get(label), start=start, state=label)
        r["full_S3_6h_wall_h"] = round(s3_particle_steps / r["particle_steps_per_s"] / 3600.0, 2)
        rows.append(r)
        if profile:
            import taichi as ti
            print(f"kernel profile of {label}:", flush=True)
            ti.profiler.print_kernel_profiler_info("count")
    return rows


def main() -> None:
    import json
    import os

    from benchlib import parser
    p = parser(__doc__)
    p.add_argument("--runs", default="benchmarks-results/bench_states",
                   help="folder of the half-scale runs (made by the sweep where missing)")
    p.add_argument("--late", action="store_true", help="(re)make the 6 h state from the figures' record")
    p.add_argument("--measure", action="store_true",
                   help="measure the states instead (a JSON line per row; benchmarks/threads.py runs this)")
    p.add_argument("--threads", type=int, default=None, help="with --measure: CPU threads")
    p.add_argument("--steps", type=int, default=1000, help="with --measure: steps timed per state")
    p.add_argument("--states", default="", help="with --measure: comma-separated labels (default all)")
    p.add_argument("--profile", action="store_true",
                   help="with --measure: print Taichi's kernel profile of each state (its own cost included)")
    a = p.parse_args()
    if a.late:
        make_late()
        return
    if not a.measure:
        make(Path(a.runs))
        return
    from taichimyxo.runtime import backend
    if a.profile:
        os.environ["TI_KERNEL_PROFILER"] = "1"        # read by every ti.init, so it outlives measure's restarts
    backend.init("cpu", a.threads)
    names = [n for n in a.states.split(",") if n]
    for r in measure(a.steps, warm=100, names=names, profile=a.profile):
        r["threads"] = a.threads or os.cpu_count()
        print(json.dumps(r), flush=True)


if __name__ == "__main__":
    main()
