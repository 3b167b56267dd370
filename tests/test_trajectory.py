"""The trajectory is a file other tools can trust.

- Every frame carries the cell bonds (stored once in frame 0 and inherited, as the HOOMD schema defines; never an
  explicit zero later), read back with the `gsd` reader at the last frame and with freud.
- The trajectory interval is set apart from the movie's (output.trajectory_interval_min).
- `render` and `analyze` refuse, in one line with exit status 2, a file that is not a trajectory of cells, and
  `render --color strain` a trajectory without logged strain, before writing anything."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simtools import build_small_scene
from taichimyxo.io.frame import Frame
from taichimyxo.io.trajectory import TrajectoryWriter

REPO = Path(__file__).resolve().parent.parent

try:
    from taichimyxo.render import verify_video
except ImportError:                                  # the renderer is optional for these tests
    verify_video = None


def cli(*args, cwd=None):
    env = dict(os.environ, TAICHIMYXO_THREADS="2")
    return subprocess.run([sys.executable, "-m", "taichimyxo", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or REPO, env=env, timeout=600)


def assert_one_line_error(p, *expect):
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 2, (p.returncode, p.stderr, p.stdout)
    assert "Traceback" not in p.stderr + p.stdout, p.stderr
    assert len(lines) == 1 and lines[0].startswith("taichimyxo: error: "), p.stderr
    for e in expect:
        assert e in lines[0], (e, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def run_with_movie(tmp_path_factory):
    """6 cells, 7200 steps of 1 ms: a movie frame every 600 steps, a trajectory frame every 1200."""
    from taichimyxo.runtime import backend
    backend.init("cpu", int(os.environ["TAICHIMYXO_THREADS"]))
    from taichimyxo.runtime.scene_run import run_scene
    movie = verify_video is not None
    sc = build_small_scene(6, run={"hours": 0.002, "dt_ms": 1.0, "seed": 3},
                           output={"movie": movie, "frame_interval_min": 0.01, "trajectory_interval_min": 0.02,
                                   "video_width": 128, "video_height": 96})
    assert (sc.steps, sc.frame_every_steps, sc.trajectory_every_steps) == (7200, 600, 1200)
    out = tmp_path_factory.mktemp("run")
    summary = run_scene(sc, out_dir=out, progress=False)
    assert summary["completed"] and summary["started_from"] == "placement"
    return sc, out, summary


def test_velocities_are_stored_and_their_norms_are_the_speeds(run_with_movie):
    """particles/velocity (µm/min, HOOMD schema) in every frame after the first: the displacement over the speed
    window, whose norm is log/particles/speed_um_per_min, and what the frames read back carry."""
    import gsd.hoomd

    from taichimyxo.io.trajectory import read_frames
    sc, out, _ = run_with_movie
    path = out / f"{sc.name}.gsd"
    frames = list(read_frames(str(path)))
    assert frames[0].particle_velocity is None                     # frame 0: the window is empty
    with gsd.hoomd.open(str(path), "r") as t:
        for i in range(1, len(t)):
            v = np.asarray(t[i].particles.velocity)
            speed = np.asarray(t[i].log["particles/speed_um_per_min"])
            assert np.all(v[:, 2] == 0) and np.abs(v).max() > 0
            np.testing.assert_allclose(np.linalg.norm(v[:, :2], axis=1), speed, rtol=1e-5, atol=1e-6)
            fr = frames[i]
            np.testing.assert_array_equal(fr.particle_velocity.reshape(-1, 2), v[:, :2])
            # the direction is the cells' motion: mostly along their engine direction
            head_to_tail = fr.positions[:, -1] - fr.positions[:, 0]
            along = -np.sum(fr.particle_velocity.mean(1) * head_to_tail, axis=1) * fr.engine_direction
            assert np.mean(along > 0) > 0.5


def test_every_frame_has_the_bonds(run_with_movie):
    import gsd.fl
    import gsd.hoomd
    sc, out, _ = run_with_movie
    path = out / f"{sc.name}.gsd"
    n_cells, N = sc.n_cells, sc.N
    nb = n_cells * (N - 1)
    base = (np.arange(n_cells) * N)[:, None] + np.arange(N - 1)[None, :]
    expected = np.stack([base.reshape(-1), base.reshape(-1) + 1], axis=1)
    with gsd.hoomd.open(str(path), "r") as t:
        assert len(t) == 7
        for i in (0, len(t) // 2, len(t) - 1):
            f = t[i]
            assert f.bonds.N == nb, i
            assert f.bonds.types == ["segment"]
            assert np.array_equal(np.asarray(f.bonds.group), expected), i
    # no later frame stores a bond count of its own that differs from frame 0's (an explicit 0 hid them before)
    with gsd.fl.open(str(path), "r") as f:
        for i in range(f.nframes):
            if f.chunk_exists(frame=i, name="bonds/N"):
                assert int(f.read_chunk(frame=i, name="bonds/N")[0]) == nb, i


@pytest.mark.filterwarnings("ignore:Specifying z-dimensions")
def test_freud_reads_the_trajectory(run_with_movie):
    """freud takes the box, wraps and unwraps with the stored images: every bond of the last frame then joins two
    particles one rest length apart, and freud's neighbour query finds every bonded pair."""
    freud = pytest.importorskip("freud")
    import gsd.hoomd
    sc, out, _ = run_with_movie
    with gsd.hoomd.open(str(out / f"{sc.name}.gsd"), "r") as t:
        f = t[-1]
        box = freud.box.Box.from_box(f.configuration.box, dimensions=2)
        pos = np.asarray(f.particles.position, np.float32)
        img = np.asarray(f.particles.image)
        group = np.asarray(f.bonds.group)
    assert box.Lx == pytest.approx(sc.box[0]) and box.is2D
    assert np.allclose(box.wrap(pos), pos, atol=1e-4)                  # inside [-L/2, L/2)
    unwrapped = box.unwrap(pos, img)
    d = np.linalg.norm(unwrapped[group[:, 1]] - unwrapped[group[:, 0]], axis=1)
    assert np.allclose(d, sc.rest_length, rtol=0.2), (d.min(), d.max())
    nl = freud.locality.AABBQuery(box, pos).query(pos, {"r_max": 1.5 * sc.rest_length,
                                                        "exclude_ii": True}).toNeighborList()
    pairs = {(int(i), int(j)) for i, j in zip(nl.query_point_indices, nl.point_indices)}
    assert all((int(a), int(b)) in pairs for a, b in group)


def test_trajectory_interval_apart_from_the_movie(run_with_movie):
    from taichimyxo.io.trajectory import read_frames
    sc, out, summary = run_with_movie
    steps = [fr.step for fr in read_frames(str(out / f"{sc.name}.gsd"))]
    assert steps == list(range(0, 7201, 1200))
    assert summary["trajectory_interval_s"] == pytest.approx(1.2)
    assert summary["frame_interval_s"] == pytest.approx(0.6)
    if verify_video is not None:
        assert verify_video(out / f"{sc.name}.mp4") == 13                # 0, 600, ..., 7200


# ------------------------------------------------------------------------------------------------ files render and
# analyze cannot use
def _synthetic_trajectory(path, strain: bool):
    rng = np.random.default_rng(0)
    n, N = 3, 4
    pos = np.cumsum(np.full((n, N, 2), [0.5, 0.0]), axis=1) + rng.uniform(2, 8, (n, 1, 2))
    with TrajectoryWriter(str(path), {"cell": {"particles": N, "width_um": 0.5}}) as w:
        for k in range(2):
            w.append(Frame(time_s=60.0 * k, step=k, box=(10.0, 10.0), width_um=0.5, positions=pos,
                           engine_direction=np.ones(n, np.int8), particle_speed=np.ones((n, N), np.float32),
                           segment_strain=np.full((n, N - 1), 1e-19) if strain else None))
    return path


@pytest.fixture
def not_trajectories(tmp_path):
    import gsd.fl
    import gsd.hoomd
    text = tmp_path / "notes.gsd"
    text.write_text("not a trajectory\n")
    other = tmp_path / "other-schema.gsd"
    with gsd.fl.open(str(other), "w", application="x", schema="not-hoomd", schema_version=[1, 0]) as f:
        f.write_chunk("value", np.zeros(3))
        f.end_frame()
    empty = tmp_path / "empty.gsd"
    gsd.hoomd.open(str(empty), "w").close()
    no_chains = tmp_path / "no-chains.gsd"
    with gsd.hoomd.open(str(no_chains), "w") as t:
        g = gsd.hoomd.Frame()
        g.particles.N = 4
        g.particles.position = np.zeros((4, 3), np.float32)
        t.append(g)
    return {"text": (text, "is not a GSD trajectory"), "other-schema": (other, "is not a GSD trajectory"),
            "empty": (empty, "no frames"), "no-chains": (no_chains, "holds no cells"),
            "readme": (REPO / "README.md", "is not a GSD trajectory"),
            "missing": (tmp_path / "missing.gsd", "not found")}


@pytest.mark.parametrize("kind", ["text", "other-schema", "empty", "no-chains", "readme", "missing"])
@pytest.mark.parametrize("cmd", ["render", "analyze"])
def test_render_and_analyze_refuse_what_is_not_a_trajectory(not_trajectories, tmp_path, cmd, kind):
    path, expect = not_trajectories[kind]
    out = tmp_path / "out"
    p = cli(cmd, path, "--out", out / "x.mp4" if cmd == "render" else out)
    assert_one_line_error(p, str(path), expect)
    assert not out.exists()


def test_render_strain_without_logged_strain(tmp_path):
    traj = _synthetic_trajectory(tmp_path / "speed-only.gsd", strain=False)
    out = tmp_path / "strain.mp4"
    p = cli("render", traj, "--color", "strain", "--out", out)
    assert_one_line_error(p, "log/bonds/strain_energy_J", "--set output.strain=true")
    assert not out.exists()


def test_a_run_can_start_from_a_given_state(tmp_path):
    """run_scene(start_state=...) (benchmarks/continue_state.py): the run's first frame is the state given, not the
    scene's own start, the run goes on from it like any other (here: 6 cells moved 1 µm across the box), and its
    summary records that it started from a given state (a scene's own start records "placement")."""
    from taichimyxo.io.trajectory import read_frames
    from taichimyxo.runtime import backend
    from taichimyxo.runtime.scene_run import run_scene
    from taichimyxo.runtime.simulation import initial_state
    backend.init("cpu", int(os.environ["TAICHIMYXO_THREADS"]))
    sc = build_small_scene(6, run={"hours": 0.0002, "dt_ms": 1.0, "seed": 3},
                           output={"movie": False, "frame_interval_min": 0.006})
    positions, heads = initial_state(sc)
    moved = np.asarray(positions) + np.array([1.0, 0.0])
    summary = run_scene(sc, out_dir=tmp_path, progress=False, start_state=(moved, -np.asarray(heads)))
    assert summary["completed"] and summary["started_from"] == "given state"       # the summary says so
    frames = list(read_frames(str(tmp_path / f"{sc.name}.gsd")))
    assert len(frames) == 3                                         # 720 steps, a frame every 360
    box = np.asarray(frames[0].box)
    gap = (frames[0].positions - moved + box / 2) % box - box / 2   # the frame may hold wrapped positions
    np.testing.assert_allclose(gap, 0.0, atol=1e-4)
    np.testing.assert_array_equal(frames[0].engine_direction, -np.asarray(heads))
    assert np.abs(frames[-1].positions - frames[0].positions).max() > 0      # it moved on from there
