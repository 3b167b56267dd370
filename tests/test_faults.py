"""Faults a user meets, survived: a disk that fills mid-run, a checkpoint or trajectory cut short or corrupted, two runs
started into one folder at once, and malformed scene values (property-based)."""
import hashlib
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from simtools import REPO, cli, error_line
from taichimyxo.io.scene import SCHEMA, Scene, SceneError

PREVIEW = ("S1", "--preview", "--hours", "0.05", "--no-movie", "--quiet")

# a run whose files may not grow past LIMIT bytes: a write past it fails as on a full disk (EFBIG, which the run
# treats as ENOSPC), and the process is not killed for it (SIGXFSZ ignored)
LIMITED = textwrap.dedent("""
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    limit = int(sys.argv[1])
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    if sys.argv[2] == "api":            # checkpoints after every chunk, so the run has one to resume from
        from taichimyxo.interface.api import run_scene
        from taichimyxo.io.scene import Scene
        sc = Scene.load("S1", {"run": {"hours": 0.05}, "output": {"movie": False}}, preview=True)
        print(run_scene(sc, out_dir=sys.argv[3], progress=False, checkpoint_every_s=0.0)["status"])
    else:
        from taichimyxo.interface.cli import main
        sys.exit(main(sys.argv[2:]))
""")


def limited(limit, *args):
    env = dict(os.environ, TAICHIMYXO_THREADS="2")
    return subprocess.run([sys.executable, "-c", LIMITED, str(limit), *map(str, args)], capture_output=True,
                          text=True, cwd=REPO, env=env, timeout=600)


def frames(path):
    import gsd.hoomd
    with gsd.hoomd.open(str(path), "r") as t:
        return [int(f.configuration.step) for f in t], t[-1].particles.position.copy()


def digest(folder):
    return {p.name: hashlib.sha1(p.read_bytes()).hexdigest() for p in sorted(Path(folder).iterdir()) if p.is_file()}


def test_a_disk_that_fills_stops_the_run_in_one_line_and_resume_continues_it(tmp_path):
    # without a checkpoint yet: one line naming the folder, the trajectory readable to its last frame
    out = tmp_path / "full"
    p = limited(200_000, "scene", *PREVIEW, "--out", out)
    line = error_line(p, code=1)
    assert f"files in {out} keep what was written" in line and "File too large" in line and "--overwrite" in line
    steps, _ = frames(out / "S1-preview.gsd")
    assert len(steps) >= 3 and steps == sorted(steps)
    # with a checkpoint: space freed, --resume finishes the run, its frames evenly spaced and its last frame the one
    # of a run that never stopped
    out = tmp_path / "resumed"
    p = limited(200_000, "api", out)
    assert p.stdout.split()[-1] == "no_space", p.stderr
    assert (out / "S1-preview.ckpt.npz").is_file()
    assert cli("scene", *PREVIEW, "--out", out, "--resume").returncode == 0
    steps, last = frames(out / "S1-preview.gsd")
    assert np.all(np.diff(steps) == steps[1] - steps[0]) and steps[-1] == 45000
    assert cli("scene", *PREVIEW, "--out", tmp_path / "whole").returncode == 0
    _, ref = frames(tmp_path / "whole" / "S1-preview.gsd")
    np.testing.assert_array_equal(last, ref)


def test_resume_drops_the_frames_and_events_written_past_the_checkpoint(tmp_path):
    """A run killed (or its disk filled) after its last checkpoint wrote frames past it; --resume makes them again, so
    they go first (trajectory.trim_after), the file readable all along."""
    from taichimyxo.io.event_table import events_path
    from taichimyxo.io.frame import Frame
    from taichimyxo.io.trajectory import TrajectoryWriter, read_frames, read_scene, trim_after
    path = str(tmp_path / "t.gsd")
    pos = np.zeros((2, 8, 2)) + np.arange(8)[None, :, None]
    with TrajectoryWriter(path, {"scene": {"name": "t"}}) as w:
        for k in range(6):
            w.append(Frame(time_s=k, step=100 * k, box=(20.0, 20.0), width_um=0.5, positions=pos + k,
                           engine_direction=np.ones(2, np.int8), particle_speed=np.zeros((2, 8), np.float32)))
    Path(events_path(path)).write_text("time_s,step,cell,kind,partner\n" +
                                       "".join(f"{k}.0,{100 * k},0,reversal,-1\n" for k in range(6)))
    assert trim_after(path, 250) == 3
    kept = list(read_frames(path))
    assert [f.step for f in kept] == [0, 100, 200] and kept[-1].positions[0, 0, 0] == pytest.approx(2.0)
    assert read_scene(path)["scene"]["name"] == "t"                          # frame 0's metadata kept
    assert Path(events_path(path)).read_text().count("reversal") == 3
    assert trim_after(path, 250) == 0


def test_a_corrupted_checkpoint_or_trajectory_is_one_line_and_nothing_is_overwritten(tmp_path):
    out = tmp_path / "run"
    p = limited(200_000, "api", out)
    assert p.returncode == 0, p.stderr
    ck = out / "S1-preview.ckpt.npz"
    ck.write_bytes(ck.read_bytes()[:5000])                   # cut short
    before = digest(out)
    line = error_line(cli("scene", *PREVIEW, "--out", out, "--resume"))
    assert str(ck) in line and "cannot be read" in line and "--overwrite" in line
    assert digest(out) == before
    ck.write_bytes(b"\0" * 4096)                             # garbage
    assert "cannot be read" in error_line(cli("scene", *PREVIEW, "--out", out, "--resume"))
    # a trajectory cut short, given to render and analyze: one line, no output made
    cut = tmp_path / "cut.gsd"
    cut.write_bytes((out / "S1-preview.gsd").read_bytes()[:60_000])
    for cmd in (("render", cut, "--out", tmp_path / "r"), ("analyze", cut, "--out", tmp_path / "a")):
        assert "cut.gsd" in error_line(cli(*cmd))
    assert not (tmp_path / "r").exists() or not any((tmp_path / "r").iterdir())
    assert not (tmp_path / "a").exists() or not any((tmp_path / "a").iterdir())


def test_a_second_run_into_a_folder_a_run_is_writing_is_refused(tmp_path):
    out = tmp_path / "busy"
    env = dict(os.environ, TAICHIMYXO_THREADS="1")
    first = subprocess.Popen([sys.executable, "-m", "taichimyxo", "scene", "S1", "--preview", "--hours", "2",
                              "--no-movie", "--quiet", "--out", str(out)], cwd=REPO, env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        while not (out / "S1-preview.gsd").is_file():           # the first run is writing (or it has failed)
            assert first.poll() is None
            time.sleep(0.2)
        for extra in ((), ("--resume",), ("--overwrite",)):
            line = error_line(cli("scene", *PREVIEW, "--out", out, *extra))
            assert "being written by another run of S1-preview" in line, line
        assert first.poll() is None                              # untouched, still running
    finally:
        first.terminate()
        first.wait(timeout=120)


# ------------------------------------------------------------------------------------------------ the schema
KEYS = [(sec, key) for sec, body in SCHEMA.items() for key in body if sec not in ("scene",)]
VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10 ** 12, 10 ** 12),
                   st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
                   st.lists(st.integers(0, 3), max_size=2),
                   st.dictionaries(st.text(max_size=3), st.integers(), max_size=1))


def _same(typ, given_value, kept) -> bool:
    """The kept value is the given one: an int for a float key, or a whole float for an int key, read as the same
    number in the key's type."""
    if typ is float and isinstance(given_value, int) and not isinstance(given_value, bool):
        return kept == float(given_value) and isinstance(kept, float)
    if typ is int and isinstance(given_value, float):
        return given_value.is_integer() and kept == int(given_value) and type(kept) is int
    return type(kept) is type(given_value) and kept == given_value


@settings(max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(KEYS), VALUES)
def test_any_value_of_any_key_is_kept_as_given_or_refused_naming_the_key(where, value):
    """A value is either the scene's value exactly (the same number in the key's type), or refused with
    one line (a SceneError) that names the key; never a traceback, never a silently changed value."""
    sec, key = where
    typ = SCHEMA[sec][key][0]
    try:
        sc = Scene.load("S1", {sec: {key: value}})
    except SceneError as e:
        msg = str(e)
        assert "\n" not in msg and (f"{sec}.{key}" in msg or key in msg), msg
        return
    assert _same(typ, value, sc.raw[sec][key]), (sec, key, value, sc.raw[sec][key])


@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(max_size=40))
def test_a_malformed_set_argument_is_refused_in_one_line(text):
    from taichimyxo.io.scene import parse_set
    try:
        over = parse_set([text])
        Scene.load("S1", over)
    except SceneError as e:
        assert "\n" not in str(e)


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(st.text(max_size=80))
def test_a_malformed_scene_file_is_refused_in_one_line(tmp_path, text):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    try:
        Scene.load(str(f))
    except SceneError as e:
        assert "\n" not in str(e) and ("bad.toml" in str(e) or "." in str(e)), str(e)
