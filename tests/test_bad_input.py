"""Bad input through the command line is one clear line and exit 2 before any simulation starts,
and leaves the files already in the output folder as they were."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from taichimyxo.io.scene import available_scenes

REPO = Path(__file__).resolve().parent.parent
SMALL = ["--set", "domain.width_um=20", "--set", "domain.height_um=20"]


def cli(*args, cwd=None, timeout=120):
    env = dict(os.environ, TAICHIMYXO_THREADS="2")
    return subprocess.run([sys.executable, "-m", "taichimyxo", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or REPO, env=env, timeout=timeout)


def assert_one_line_error(p, *expect):
    err = p.stderr
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert p.returncode == 2, (p.returncode, err, p.stdout)
    assert "Traceback" not in err and "Traceback" not in p.stdout, err
    assert len(lines) == 1, err
    assert lines[0].startswith("taichimyxo: error: "), err
    for e in expect:
        assert e in lines[0], (e, lines[0])
    assert "[Taichi]" not in p.stdout, "Taichi started: the error came after setup"
    return lines[0]


@pytest.fixture
def out_with_files(tmp_path):
    """An output folder that already holds a run's files (and another file): a bad-input run must not touch them."""
    out = tmp_path / "out"
    out.mkdir()
    files = {"S1.gsd": b"old trajectory", "S1.json": b'{"old": true}', "S1.mp4": b"old movie",
             "S1.png": b"old panel", "S1.ckpt.npz": b"old checkpoint", "notes.txt": b"keep me"}
    for name, data in files.items():
        (out / name).write_bytes(data)
    stamp = {name: (out / name).stat().st_mtime_ns for name in files}
    yield out
    assert sorted(p.name for p in out.iterdir()) == sorted(files), "files appeared or vanished"
    for name, data in files.items():
        assert (out / name).read_bytes() == data, name
        assert (out / name).stat().st_mtime_ns == stamp[name], name


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


# ------------------------------------------------------------------------------------------------ scene names
def test_unknown_scene_lists_the_available_ones(out_with_files):
    line = assert_one_line_error(cli("scene", "S99", "--out", out_with_files), "unknown scene 'S99'", "available:")
    for name in available_scenes():
        assert name in line


def test_missing_scene_file(out_with_files, tmp_path):
    assert_one_line_error(cli("scene", tmp_path / "nope.toml", "--out", out_with_files), "nope.toml", "not found")


def test_malformed_toml_gives_line_and_column(out_with_files, tmp_path):
    p = _write(tmp_path, "bad.toml", '[scene]\ntitle = "x"\n[domain]\nwidth_um = 20\nheight_um = = 3\n')
    assert_one_line_error(cli("scene", p, "--out", out_with_files), "bad.toml", "malformed TOML", "line 5",
                          "column")


# ------------------------------------------------------------------------------------------------ keys and values
@pytest.mark.parametrize("body,expect", [
    ("[domain]\nwidth_um = 20\nfoo = 1\n", ["unknown key domain.foo", "width_um, height_um"]),
    ("[bogus]\nx = 1\n", ["unknown section [bogus]"]),
    ('[domain]\nwidth_um = "wide"\n', ["domain.width_um", "expected a number"]),
    ("[population]\ncells = 2.5\n", ["population.cells", "expected an integer"]),
    ('[slime]\nenabled = "yes"\n', ["slime.enabled", "expected true or false"]),
    ('[guiding]\nkind = "fast"\n', ["guiding.kind", "none, passive, active, adhesion"]),
    ("[cell]\nk_a_N_m = 0\n", ["cell.k_a_N_m", "must be positive"]),
    ("[collisions]\nk_c_N_per_m = -0.01\n", ["collisions.k_c_N_per_m", "must be positive"]),
    ("[run]\nhours = 0\n", ["run.hours", "must be positive"]),
    ("[run]\nseed = -1\n", ["run.seed", "zero or positive"]),
    ("[cell]\nparticles = 2\n", ["cell.particles", "between 3 and 64"]),
    ("[domain]\nwidth_um = 9.99\nheight_um = 50\n", ["domain.width_um", "two cell lengths"]),
    ("[population]\ndensity_cells_per_cm2 = 3e7\n", ["population.density_cells_per_cm2", "'random' start",
                                                      "at most 0.40"]),
    ('[population]\nstart = "aligned"\ndensity_cells_per_cm2 = 5e7\n', ["population.density_cells_per_cm2",
                                                                        "'aligned' start"]),
], ids=["unknown-key", "unknown-section", "wrong-type", "not-an-integer", "not-a-bool", "not-allowed", "zero",
        "negative", "zero-hours", "negative-seed", "out-of-range", "domain-too-small", "density-random",
        "density-aligned"])
def test_bad_scene_file(out_with_files, tmp_path, body, expect):
    p = _write(tmp_path, "bad.toml", body)
    assert_one_line_error(cli("scene", p, "--out", out_with_files, "--no-movie"), *expect)


@pytest.mark.parametrize("sets,expect", [
    (["cell.bogus=1"], ["--set cell.bogus", "unknown key"]),
    (["nosection=1"], ["--set 'nosection'", "SECTION.KEY"]),
    (["cell.k_a_N_m=abc"], ["cell.k_a_N_m", "expected a number"]),
    (["cell.k_a_N_m=-1e-17"], ["cell.k_a_N_m", "must be positive"]),
    (["domain.width_um=0"], ["domain.width_um", "must be positive"]),
    (["domain.width_um=8", "domain.height_um=8"], ["domain.width_um", "two cell lengths"]),
], ids=["unknown-key", "not-dotted", "wrong-type", "negative", "zero", "domain-too-small"])
def test_bad_set(out_with_files, sets, expect):
    args = [a for s in sets for a in ("--set", s)]
    assert_one_line_error(cli("scene", "S1", "--out", out_with_files, "--no-movie", *args), *expect)


@pytest.mark.parametrize("args,expect", [
    (["--arch", "bogus"], ["--arch", "invalid choice"]),
    (["--threads", "0"], ["--threads", "at least 1"]),
    (["--size", "wide"], ["--size", "WIDTHxHEIGHT"]),
    (["--fps", "0"], ["output.fps", "must be positive"]),
    (["--hours", "-1"], ["run.hours", "must be positive"]),
    (["--resume"], ["--resume", "no checkpoint"]),
], ids=["arch", "threads", "size", "fps", "hours", "resume-without-checkpoint"])
def test_bad_options(tmp_path, args, expect):
    out = tmp_path / "fresh"
    assert_one_line_error(cli("scene", "S1", "--out", out, "--no-movie", *args), *expect)


def test_density_the_aligned_start_cannot_place(out_with_files):
    """Area fraction below 1 passes validation, but 14 x 14 µm holds only 2 rows of 28 cells: the placement error is
    still one line, before Taichi starts."""
    assert_one_line_error(cli("scene", "S13", "--out", out_with_files, "--no-movie", "--set", "domain.width_um=14",
                              "--set", "domain.height_um=14"),
                          "'aligned' start cannot place", "78 cells", "population.density_cells_per_cm2")


def test_output_folder_that_cannot_be_written(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("I am a file")
    assert_one_line_error(cli("scene", "S1", "--out", blocker / "sub", "--no-movie"), "output folder",
                          "cannot be written")
    assert blocker.read_text() == "I am a file"


def test_resume_with_a_checkpoint_of_other_parameters(tmp_path):
    import numpy as np
    out = tmp_path / "out"
    out.mkdir()
    np.savez(out / "S1.ckpt.npz", x=np.zeros((2, 2)), fingerprint=np.array("0123456789abcdef"))
    before = (out / "S1.ckpt.npz").read_bytes()
    assert_one_line_error(cli("scene", "S1", "--out", out, "--no-movie", "--resume"), "--resume",
                          "different scene parameters")
    assert (out / "S1.ckpt.npz").read_bytes() == before


# ------------------------------------------------------------------------------------------------ accepted input
def test_step_above_the_limit_is_refused_and_accepted_with_force(out_with_files, tmp_path):
    from taichimyxo.io.scene import Scene
    from taichimyxo.physics.stability import stable_limit_ms
    sc = Scene.load("S1", {"domain": {"width_um": 20.0, "height_um": 20.0}})
    dt = round(1.1 * stable_limit_ms(sc), 3)
    args = ["scene", "S1", "--no-movie", "--quiet", *SMALL, "--set", f"run.dt_ms={dt}", "--set", "run.hours=0.001"]
    assert_one_line_error(cli(*args, "--out", out_with_files), f"run.dt_ms = {dt:g}", "stability limit",
                          "--force")
    out = tmp_path / "forced"
    p = cli(*args, "--out", out, "--force")
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    d = json.loads((out / "S1.json").read_text())
    assert d["completed"] and d["dt_s"] == pytest.approx(dt * 1e-3) and d["steps"] == round(3.6 / (dt * 1e-3))


@pytest.mark.skipif(os.path.exists("/dev/nvidia0") or os.path.exists("/dev/nvidiactl"),
                    reason="this machine has a CUDA device: cuda is available, nothing falls back")
def test_unavailable_arch_falls_back_to_cpu_and_says_so(tmp_path):
    out = tmp_path / "out"
    p = cli("scene", "S1", "--out", out, "--no-movie", "--quiet", *SMALL, "--set", "run.hours=0.0002",
            "--arch", "cuda")
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    msg = [ln for ln in p.stderr.splitlines() if ln.startswith("taichimyxo:")]
    assert msg == ["taichimyxo: arch cuda is not available here; running on the CPU instead"], p.stderr
    assert json.loads((out / "S1.json").read_text())["arch"] == "cpu"
