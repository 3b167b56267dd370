"""An interrupted run loses nothing.

SIGINT / SIGTERM (or run_scene's stop_after_steps, which takes the same path) closes the trajectory and the movie so
both stay readable, and writes a checkpoint; --resume continues it, and on the CPU the resumed run is bit for bit the
uninterrupted one (the same seed, the same frames, the same state)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from simtools import build_small_scene

REPO = Path(__file__).resolve().parent.parent

try:
    from taichimyxo.render import verify_video
except ImportError:                                  # the renderer is optional for these tests
    verify_video = None
needs_render = pytest.mark.skipif(verify_video is None, reason="taichimyxo.render is not importable yet")


def gsd_frames(path):
    """Every array of every frame, for exact comparison."""
    import gsd.hoomd
    out = []
    with gsd.hoomd.open(str(path), "r") as t:
        for f in t:
            d = {"step": f.configuration.step, "position": np.array(f.particles.position),
                 "image": np.array(f.particles.image)}
            d.update({k: np.array(v) for k, v in f.log.items() if k != "taichimyxo/scene_json"})
            out.append(d)
    return out


def assert_same_frames(a, b):
    assert len(a) == len(b), (len(a), len(b))
    for i, (fa, fb) in enumerate(zip(a, b)):
        assert fa.keys() == fb.keys(), i
        for k in fa:
            assert np.array_equal(fa[k], fb[k]), f"frame {i}: {k} differs"


def _ckpt(out, name):
    return dict(np.load(Path(out) / f"{name}.ckpt.npz", allow_pickle=False))


# ------------------------------------------------------------------------------------------------ in-process
SCENES = {
    # low density, no effects: the paper's S1 on a 20 x 20 µm box
    "plain": {},
    # every piece of state a checkpoint must carry: guiding, reversals with suppression (clocks, periods, counts),
    # slime trails (the grid)
    "all-effects": {"guiding": {"kind": "active"}, "slime": {"enabled": True},
                    "reversals": {"enabled": True, "period_min": 0.02, "suppression": True}},
    # the same under the step-size controller: its multiple and velocity history are in the checkpoint too
    "step-control": {"guiding": {"kind": "active"}, "slime": {"enabled": True},
                     "reversals": {"enabled": True, "period_min": 0.02, "suppression": True},
                     "run": {"step_control": "error", "step_max_multiple": 3}},
}
# where the split run stops: inside a speed window; under the controller at a chunk's end (the start of the window
# 2600-3600), as an interrupt does: a stop elsewhere cuts a step the uninterrupted run takes whole
STOP = {"step-control": 2600}


@pytest.mark.slow                   # 4-5 s each with warm kernel caches, up to 20 s cold
@pytest.mark.parametrize("variant", sorted(SCENES))
def test_stop_and_resume_in_process_equals_uninterrupted(ti_cpu, tmp_path, variant):
    """Reference: one pass of all 7200 steps, stopped (checkpointed) exactly at the end so its full f64 state is
    on disk. Split: stopped after 3100 steps (inside a speed window), resumed for the remaining 4100. The two final
    checkpoints (positions, speed-window start, engine directions, reversal clocks, slime grid) and every
    trajectory frame are identical."""
    from taichimyxo.io.trajectory import count_frames, read_frames
    from taichimyxo.runtime.scene_run import run_scene
    sections = dict(SCENES[variant])
    sections["run"] = {"hours": 0.002, "seed": 7, "dt_ms": 1.0, **sections.get("run", {})}     # 7200 steps
    sections["output"] = {"movie": False, "frame_interval_min": 0.02}   # a frame every 1200 steps
    sc = build_small_scene(20, **sections)
    assert sc.steps == 7200
    ref, split = tmp_path / "ref", tmp_path / "split"
    kw = dict(progress=False, checkpoint_every_s=1e9)

    full = run_scene(sc, out_dir=ref, stop_after_steps=7200, **kw)
    assert full["steps"] == 7200

    # interrupted inside a speed window (windows of 1000 steps end at each frame: 2600-3600 here)
    stop = STOP.get(variant, 3100)
    part = run_scene(sc, out_dir=split, stop_after_steps=stop, **kw)
    assert part["status"] == "interrupted" and part["steps"] == stop and not part["completed"]
    assert part["files"]["checkpoint"] == f"{sc.name}.ckpt.npz"
    js = json.loads((split / f"{sc.name}.json").read_text())
    assert js["status"] == "interrupted" and js["steps"] == stop
    gsd = split / f"{sc.name}.gsd"
    frames = list(read_frames(str(gsd)))                                # closed, readable
    assert [f.step for f in frames] == [0, 1200, 2400] and count_frames(str(gsd)) == 3
    assert int(_ckpt(split, sc.name)["step"]) == stop

    rest = run_scene(sc, out_dir=split, resume=True, stop_after_steps=7200 - stop, **kw)
    assert rest["steps"] == 7200
    a, b = _ckpt(split, sc.name), _ckpt(ref, sc.name)
    assert a.keys() == b.keys()
    if variant != "plain":
        assert {"rev_clock", "rev_period", "rev_count", "slime"} <= a.keys()
        assert a["rev_count"].sum() > 0 and np.abs(a["slime"]).sum() > 0   # reversals and trails on the way
    from taichimyxo.io.writers import SESSION_KEYS
    for k in set(a) - set(SESSION_KEYS):              # the state; the wall-time totals differ by nature
        assert np.array_equal(a[k], b[k]), f"checkpoint field {k} differs after resume"
    assert int(a["sessions"]) == 2 and int(b["sessions"]) == 1
    assert_same_frames(gsd_frames(split / f"{sc.name}.gsd"), gsd_frames(ref / f"{sc.name}.gsd"))
    assert count_frames(str(gsd)) == 7
    if variant == "step-control":
        sc_full = json.loads((ref / f"{sc.name}.json").read_text())["step_control"]
        assert {"step_v_prev", "step_control"} <= a.keys()
        assert rest["step_control"] == sc_full and sc_full["steps_taken"] < 7200 / 1.5   # long steps were taken


@needs_render
def test_interrupted_movie_is_readable_and_resumes(ti_cpu, tmp_path):
    from taichimyxo.io.trajectory import count_frames
    from taichimyxo.runtime.scene_run import run_scene
    sc = build_small_scene(20, run={"hours": 0.001, "dt_ms": 1.0}, output={"movie": True, "frame_interval_min": 0.005,
                                                             "video_width": 128, "video_height": 96})
    out = tmp_path / "out"
    part = run_scene(sc, out_dir=out, stop_after_steps=1700, progress=False)
    assert part["status"] == "interrupted"
    mp4, gsd = out / f"{sc.name}.mp4", out / f"{sc.name}.gsd"
    assert verify_video(mp4) == count_frames(str(gsd)) == 6                # steps 0, 300, ..., 1500
    done = run_scene(sc, out_dir=out, resume=True, progress=False)
    assert done["completed"]
    assert verify_video(mp4) == count_frames(str(gsd)) == 13               # 0 .. 3600 every 300
    assert (out / f"{sc.name}.png").is_file()


# ------------------------------------------------------------------------------------------------ a real signal
def _cmd(out, *extra):
    return [sys.executable, "-m", "taichimyxo", "scene", "S1", "--out", str(out), "--seed", "5",
            "--set", "domain.width_um=20", "--set", "domain.height_um=20", "--set", "run.dt_ms=1",
            "--frame-minutes", "0.02", *extra]


ENV = dict(os.environ, TAICHIMYXO_THREADS="2", PYTHONUNBUFFERED="1")


def _run(out, *extra):
    return subprocess.run(_cmd(out, *extra), cwd=REPO, env=ENV, capture_output=True, text=True, timeout=300)


class _Reader(threading.Thread):
    """Collect a pipe's bytes (the progress bar writes '\\r' updates, not lines)."""

    def __init__(self, pipe):
        super().__init__(daemon=True)
        self.pipe, self.data = pipe, bytearray()

    def run(self):
        for chunk in iter(lambda: self.pipe.read1(4096), b""):
            self.data.extend(chunk)

    def text(self):
        return self.data.decode(errors="replace")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_real_signal_closes_files_checkpoints_and_resumes_bit_for_bit(tmp_path, signum):
    out, ref = tmp_path / "out", tmp_path / "ref"
    movie = ["--size", "128x96"] if verify_video is not None else ["--no-movie"]
    p = subprocess.Popen(_cmd(out, "--hours", "1", *movie), cwd=REPO, env=ENV, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)                  # 3.6 M steps: far longer than we let it run
    err = _Reader(p.stderr)
    err.start()
    give_up = time.monotonic() + 900.0                         # a safety net sized for a loaded machine, not a timing
    while "S1:" not in err.text():                             # the progress line: signals are handled from here
        assert p.poll() is None, err.text()
        if time.monotonic() > give_up:
            p.kill()
            pytest.fail("no progress line after 15 minutes: " + err.text())
        time.sleep(0.05)
    time.sleep(1.0)
    p.send_signal(signum)
    rc = p.wait(timeout=900)                                   # a safety net for a loaded machine
    err.join(timeout=10)
    text = err.text()
    assert rc == 130, text
    assert "Traceback" not in text, text
    assert "interrupted at" in text and "--resume" in text, text
    js = json.loads((out / "S1.json").read_text())
    assert js["status"] == "interrupted"
    K = js["steps"]
    assert 0 < K < 3_600_000
    ck = _ckpt(out, "S1")
    assert int(ck["step"]) == K
    from taichimyxo.io.trajectory import count_frames
    n = count_frames(str(out / "S1.gsd"))
    assert n == K // 1200 + 1                                  # frames at 0, 1200, ... up to K
    if verify_video is not None:
        assert verify_video(out / "S1.mp4") == n
    # the same command again, without --resume, keeps every file and names the two ways on
    kept = {f.name: f.read_bytes() for f in out.iterdir()}
    r = _run(out, "--hours", "1", *movie)
    assert r.returncode == 2 and "--resume" in r.stderr and "--overwrite" in r.stderr, r.stderr
    assert {f.name: f.read_bytes() for f in out.iterdir()} == kept

    # resume to K + 2500 steps, and run the same length uninterrupted: identical trajectories
    hours = f"{(K + 2500) * 0.001 / 3600:.12g}"
    r = _run(out, "--hours", hours, "--resume", "--quiet", *movie)
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "S1.json").read_text())["steps"] == K + 2500
    assert not (out / "S1.ckpt.npz").exists()
    if signum == signal.SIGINT:
        r = _run(ref, "--hours", hours, "--quiet", "--no-movie")
        assert r.returncode == 0, r.stderr
        assert_same_frames(gsd_frames(out / "S1.gsd"), gsd_frames(ref / "S1.gsd"))
    if verify_video is not None:
        assert verify_video(out / "S1.mp4") == count_frames(str(out / "S1.gsd"))
