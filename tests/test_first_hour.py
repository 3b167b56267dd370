"""Every command takes --out alike, progress is honest from the first line, the example sweep ships and
shows something, preview movies can be watched, and the small things of a first hour with the tool.

--out, for every command: a new folder is created, an existing one is used, a file and a folder that cannot be
written are refused in one line (exit 2) before any work; `render --out` also takes a path ending in .mp4. The
commands that simulate (scene, videos, sweep, bench) are stopped right after their folder check by a stub, so
nothing here compiles a kernel."""
from __future__ import annotations

import io
import stat
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from taichimyxo.interface.cli import main
from taichimyxo.io.frame import Frame
from taichimyxo.io.scene import Scene
from taichimyxo.io.trajectory import TrajectoryWriter

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def traj(tmp_path) -> Path:
    """A small trajectory of S1's cells (4 frames 30 s apart, velocities from frame 1 on), written as runs write."""
    sc = Scene.load("S1", {"domain": {"width_um": 20.0, "height_um": 20.0}})
    rng = np.random.default_rng(1)
    path = tmp_path / "t.gsd"
    with TrajectoryWriter(str(path), {**sc.to_dict(), "_fingerprint": sc.fingerprint()}) as w:
        for i in range(4):
            pos = rng.uniform(0, 20, (6, 1, 2)) + np.arange(sc.N)[None, :, None] * np.array([sc.rest_length, 0.0])
            vel = None if i == 0 else np.tile(np.array([4.0, 0.0], np.float32), (6, sc.N, 1))
            w.append(Frame(time_s=30.0 * i, step=7500 * i, box=sc.box, width_um=sc.width, positions=pos,
                           engine_direction=np.ones(6, np.int8), particle_speed=np.full((6, sc.N), 4.0, np.float32),
                           particle_velocity=vel))
    return path


def stub_simulations(monkeypatch):
    """Stop the commands that simulate right after their output folder is checked."""
    import taichimyxo.interface.bench
    import taichimyxo.io.videos
    import taichimyxo.runtime.scene_run

    def no_scene(*a, **k):
        raise SystemExit(0)
    # scene: after the folder check
    monkeypatch.setattr(taichimyxo.runtime.scene_run, "find_reusable_trajectory", no_scene)
    monkeypatch.setattr(taichimyxo.interface.bench, "throughput", lambda *a, **k: None)
    monkeypatch.setattr(taichimyxo.io.videos.subprocess, "call", lambda *a, **k: 0)
    import taichimyxo.sweep.orchestrator as drv

    class NoExecutor:
        @staticmethod
        def execute(dirs, jobs, opts, progress):
            return {}
    monkeypatch.setattr(drv, "executor_module", lambda name: NoExecutor)


def commands(traj, sweep_file):
    return {
        "scene": lambda out: ["scene", "S1", "--no-movie", "--out", out],
        "render": lambda out: ["render", traj, "--size", "160x120", "--out", out],
        "analyze": lambda out: ["analyze", traj, "--no-plots", "--out", out],
        "claims": lambda out: ["claims", traj, "--no-plots", "--out", out],
        "videos": lambda out: ["videos", "--only", "S1", "--preview", "--out", out],
        "sweep": lambda out: ["sweep", sweep_file, "--out", out],
        "bench": lambda out: ["bench", "throughput", "--scenes", "S1", "--out", out],
    }


@pytest.mark.parametrize("case", ["new folder", "existing folder", "file", "unwritable"])
def test_every_command_takes_out_the_same_way(tmp_path, traj, case, monkeypatch, capsys):
    import taichimyxo.io.outdir
    stub_simulations(monkeypatch)
    sweep_file = tmp_path / "s.toml"
    sweep_file.write_text('scene = "S1"\nhours = 0.001\nbox_um = [20, 20]\n')
    for name, argv in commands(traj, sweep_file).items():
        out = tmp_path / name / "out"
        out.parent.mkdir()
        if case == "existing folder" or case == "unwritable":
            out.mkdir()
        if case == "file":
            out.write_text("a file")
        if case == "unwritable":
            out.chmod(stat.S_IRUSR | stat.S_IXUSR)

            def refuse(folder, real=taichimyxo.io.outdir.probe_writable):
                if Path(folder) == out:          # root writes through modes: refuse as the kernel would
                    raise PermissionError(13, "Permission denied")
                real(folder)
            monkeypatch.setattr(taichimyxo.io.outdir, "probe_writable", refuse)
        try:
            rc = main([str(a) for a in argv(out)])
        except SystemExit as e:                  # the scene stub, after the folder was accepted
            rc = e.code
        err = capsys.readouterr().err
        if case in ("new folder", "existing folder"):
            assert rc == 0, (name, err)
            assert out.is_dir(), name
        else:
            lines = [ln for ln in err.splitlines() if ln.strip()]
            assert rc == 2 and len(lines) == 1 and lines[0].startswith("taichimyxo: error: output folder"), (name, err)
            assert ("is a file" if case == "file" else "cannot be written") in lines[0], (name, lines[0])
            assert out.is_file() if case == "file" else not any(out.iterdir()), name
        if case == "unwritable":
            out.chmod(0o755)


def test_render_out_takes_an_mp4_path_and_a_folder(tmp_path, traj, capsys):
    assert main(["render", str(traj), "--size", "160x120", "--out", str(tmp_path / "a" / "movie.mp4")]) == 0
    assert (tmp_path / "a" / "movie.mp4").stat().st_size > 0 and (tmp_path / "a" / "movie.png").is_file()
    assert main(["render", str(traj), "--size", "160x120", "--color", "identity", "--out", str(tmp_path / "b")]) == 0
    assert (tmp_path / "b" / "t.identity.mp4").is_file()


# ------------------------------------------------------------------------------------------------ progress
def test_progress_gives_no_time_left_until_the_rate_is_measured_after_compiling():
    from taichimyxo.runtime.status_line import Progress, starting_note
    log = io.StringIO()
    bar = Progress("S3", 1000, 0.002, 0, stream=log, interval_s=0, starting=starting_note(Scene.load("S3")))
    bar.update(0, force=True)
    bar.update(100)                    # the end of the first chunk: the kernels are compiled
    bar.update(300)
    lines = log.getvalue().splitlines()
    assert "compiling kernels (first run of this scene, ~" in lines[0] or "kernels compiled before" in lines[0]
    assert "left" not in lines[0] and "left" not in lines[1] and "measuring the step rate" in lines[1]
    assert "steps/s" in lines[2] and "left" in lines[2]


# ------------------------------------------------------------------------------------------------ example sweep
def test_the_example_sweep_is_found_by_name_and_ships_in_the_wheel(capsys):
    conf = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert (conf["package-dir"]["taichimyxo.sweeps"] == "sweeps"
            and "*.toml" in conf["package-data"]["taichimyxo.sweeps"])
    assert main(["sweep", "example", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "guiding.kind=none" in out and "guiding.kind=active" in out
    sw = tomllib.loads((REPO / "sweeps" / "example.toml").read_text())
    assert sw["scene"] == "S3" and sw["hours"] * 60 >= 10 and sw["box_um"] == [50, 50]   # the S3 preview's patch
    assert main(["sweep", "exampel", "--dry-run"]) == 2
    assert "did you mean example?" in capsys.readouterr().err


def test_sweep_panels_start_at_zero_so_noise_stays_flat(tmp_path):
    from taichimyxo.sweep.collect import OUTCOMES, plot_against
    rows = [{"k": v, **{oc: None for oc in OUTCOMES}} for v in ("none", "active")]
    rows[0]["free_cell_speed_vb"], rows[1]["free_cell_speed_vb"] = 0.999941, 0.999947
    import matplotlib.pyplot as plt
    seen = {}
    real = plt.Figure.savefig

    def keep(fig, *a, **k):
        seen["ylim"] = [ax.get_ylim() for ax in fig.axes if ax.get_title() == OUTCOMES["free_cell_speed_vb"]][0]
        return real(fig, *a, **k)
    plt.Figure.savefig = keep
    try:
        plot_against(rows, "k", [], tmp_path / "p.png")
    finally:
        plt.Figure.savefig = real
    assert seen["ylim"][0] == 0 and seen["ylim"][1] >= 1.15


# ------------------------------------------------------------------------------------------------ preview movies
def test_preview_movies_can_be_watched():
    from taichimyxo.render.raster import get_renderer
    for name in ("S1", "S3", "S13"):
        sc = Scene.load(name, preview=True)
        frames = sc.steps // sc.frame_every_steps + 1
        assert frames / sc.fps >= 10, name                                 # at least 10 s of movie
        assert sc.frame_every_steps * sc.dt <= 5.0, name                   # a few degrees of rotation a frame
        assert min(get_renderer(sc.box, sc.video_size, sc.color).size) >= 720, name


# ------------------------------------------------------------------------------------------------ small things
def test_no_command_lists_the_commands(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err
    assert all(c in err for c in ("scene", "render", "analyze", "claims", "sweep", "list", "keys"))


@pytest.mark.parametrize("argv,says", [
    (["scene", "s3", "--show"], "did you mean S3?"),
    (["scene", "S3", "--show", "--set", "guiding.knd=active"], "did you mean guiding.kind?"),
    (["scene", "S3", "--show", "--set", "guiding.kind=activ"], "did you mean active?"),
])
def test_did_you_mean(argv, says, capsys):
    assert main(argv) == 2
    assert says in capsys.readouterr().err


def test_keys_lists_allowed_values_and_show_the_resolved_cells(capsys):
    assert main(["keys"]) == 0
    out = capsys.readouterr().out
    kind = next(ln for ln in out.splitlines() if ln.startswith("guiding.kind "))
    assert "none | passive | active | adhesion" in kind and "allowed" in out.splitlines()[0]
    assert main(["scene", "S3", "--preview", "--show"]) == 0
    cells = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("cells ="))
    assert f"resolves to {Scene.load('S3', preview=True).n_cells} cells" in cells


def test_claims_refuses_the_same_file_twice(traj, tmp_path, capsys):
    assert main(["claims", str(traj), str(tmp_path / "." / traj.name), "--out", str(tmp_path / "c")]) == 2
    assert "given twice" in capsys.readouterr().err and not (tmp_path / "c").exists()


def test_trajectory_is_readable_by_all_and_opens_in_freud_and_mdanalysis_without_warnings(traj):
    import gsd.hoomd
    assert stat.S_IMODE(traj.stat().st_mode) == 0o666 & ~_umask()
    freud = pytest.importorskip("freud")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with gsd.hoomd.open(str(traj), "r") as t:
            box = freud.box.Box.from_box(t[0].configuration.box)
        assert box.is2D and box.Lx == 20
        pytest.importorskip("MDAnalysis")
        from taichimyxo.io.interop import universe
        u = universe(traj)
        times = [ts.time for ts in u.trajectory]
        assert times == [0.0, 30.0, 60.0, 90.0]                         # simulated seconds, not frame numbers
        u.trajectory[2]
        assert u.trajectory.ts.has_velocities and np.allclose(u.atoms.velocities[:, 0], 4.0)


def _umask() -> int:
    import os
    mask = os.umask(0)
    os.umask(mask)
    return mask
