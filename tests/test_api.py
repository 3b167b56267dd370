"""The Python API: the README's example runs as written; triggers, writers and the driver
behave as the README says (a continued run writes what one run writes; a trajectory written again appends)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent

def readme_example() -> str:
    text = (REPO / "README.md").read_text()
    m = re.search(r"^## Python API\n.*?```python\n(.*?)```", text, re.S | re.M)
    assert m, "README.md has no ```python block in its 'Python API' section"
    return m.group(1)


def test_readme_example_runs_as_written(ti_cpu, tmp_path, monkeypatch, capsys):
    from taichimyxo.io.trajectory import read_frames
    from taichimyxo.render import verify_video
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(readme_example(), "README.md (Python API)", "exec"), ns)
    sim = ns["sim"]
    try:
        assert ns["result"].status == "completed" and sim.time == pytest.approx(3.0)
        assert capsys.readouterr().out.startswith("completed 3.0")
        steps = [fr.step for fr in read_frames(str(tmp_path / "out/S3.gsd"))]
        assert steps == [0, 250, 500, 750]                          # S3's 4 ms steps, a frame every second
        assert verify_video(tmp_path / "out/S3.mp4") == 4
        frame, image = ns["frame"], ns["image"]
        assert frame.positions.shape == (ns["scene"].n_cells, ns["scene"].N, 2)
        assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
        assert image.shape[0] <= 480 and image.shape[1] <= 640
    finally:
        sim.close()


def test_import_is_light_and_names_resolve():
    code = ("import sys, taichimyxo as tm; tm.Periodic(minutes=1); tm.writers.Trajectory; tm.load_scene; "
            "from taichimyxo.runtime.scene_run import run_scene; assert callable(tm.run) and "
            "tm.run.__module__ == 'taichimyxo.interface.api', tm.run; print('taichi' in sys.modules)")
    p = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "False"


def test_triggers():
    from taichimyxo.runtime.triggers import Periodic, WallClock, is_step_trigger
    t = Periodic(minutes=0.5).bind(0.002)
    assert t.period == 15000 and t(0) and t(30000) and not t(29999)
    assert t.next_after(0) == 15000 and t.next_after(15000) == 30000 and t.prev_before(15000) == 0
    assert Periodic(seconds=0.0001).bind(0.002).period == 1                  # at least one step
    assert Periodic(steps=7).period == 7 and is_step_trigger(Periodic(steps=7))
    for bad in (dict(), dict(seconds=1, minutes=1), dict(seconds=-1), dict(steps=0)):
        with pytest.raises(ValueError):
            Periodic(**bad)
    w = WallClock(seconds=3600)
    assert not w(10) and not is_step_trigger(w)
    w.seconds = 0.0
    assert w(10)


def test_load_scene_overrides():
    import taichimyxo as tm
    sc = tm.load_scene("S3", set={"domain.width_um": 30, "domain.height_um": 30}, seed=2)
    assert sc.box == (30.0, 30.0) and sc.seed == 2
    nested = tm.load_scene("S3", set={"domain": {"width_um": 30, "height_um": 30}}, seed=2)
    assert nested.fingerprint() == sc.fingerprint()
    assert tm.load_scene("S3", preview=True).name == "S3-preview"
    with pytest.raises(tm.SceneError, match="unknown key"):
        tm.load_scene("S3", set={"domain.wdth_um": 30})


def _frames(path):
    from taichimyxo.io.trajectory import read_frames
    return [(fr.step, fr.positions.copy(), fr.particle_speed.copy()) for fr in read_frames(str(path))]


def test_continued_run_writes_what_one_run_writes(ti_cpu, tmp_path, small_scene):
    """Two calls (the first ending between frames, inside the next frame's speed window) write the same frames,
    speeds included, as one call; the trajectory written again appends; final=True adds the last step."""
    import taichimyxo as tm
    sc = small_scene(6, run={"dt_ms": 1.0, "seed": 4})
    one, two = tm.Simulation(sc), tm.Simulation(sc)
    try:
        a = tm.writers.Trajectory(tmp_path / "one.gsd", trigger=tm.Periodic(seconds=0.5))
        assert tm.run(one, seconds=3, writers=[a]).completed
        b = tm.writers.Trajectory(tmp_path / "two.gsd", trigger=tm.Periodic(seconds=0.5))
        first = tm.run(two, seconds=1.3, writers=[b])
        assert first.status == "completed" and first.steps_done == 1300
        tm.run(two, steps=1700, writers=[b])
        fa, fb = _frames(tmp_path / "one.gsd"), _frames(tmp_path / "two.gsd")
        assert [f[0] for f in fa] == [f[0] for f in fb] == list(range(0, 3001, 500))
        for x, y in zip(fa, fb):
            assert np.array_equal(x[1], y[1]) and np.array_equal(x[2], y[2]), x[0]
        c = tm.writers.Trajectory(tmp_path / "final.gsd", trigger=tm.Periodic(seconds=1), final=True)
        tm.run(one, seconds=0.7, writers=[c])
        assert [f[0] for f in _frames(tmp_path / "final.gsd")] == [3700]
    finally:
        one.close()
        two.close()


def test_attached_writers_stay_open_across_runs(ti_cpu, tmp_path, small_scene):
    """sim.attach keeps a writer across run calls (closed by sim.close); a writer passed to one call is closed
    after it; advance(n, dt) honours dt and the simulated time follows it. tm.Simulation is the class; run takes
    keywords only, so a step count meant for advance cannot be read as seconds."""
    import taichimyxo as tm
    from taichimyxo.runtime.simulation import Simulation
    sim = tm.Simulation(small_scene(4, run={"dt_ms": 1.0}))
    try:
        assert tm.Simulation is Simulation and isinstance(sim, tm.Simulation)
        with pytest.raises(TypeError):
            sim.run(10)
        sim.attach(tm.writers.Trajectory(tmp_path / "a.gsd", trigger=tm.Periodic(seconds=0.5)))
        once = tm.writers.Trajectory(tmp_path / "b.gsd", trigger=tm.Periodic(seconds=0.5))
        assert sim.run(seconds=1.2, writers=[once]).completed and sim.step_count == 1200
        assert sim.run(steps=800).completed and sim.time == pytest.approx(2.0)
        sim.advance(4, 0.25e-3)
        assert sim.step_count == 2004 and sim.time == pytest.approx(2.001)
    finally:
        sim.close()
    assert [f[0] for f in _frames(tmp_path / "a.gsd")] == [0, 500, 1000, 1500, 2000]
    assert [f[0] for f in _frames(tmp_path / "b.gsd")] == [0, 500, 1000]


def test_checkpoint_and_summary_writers(ti_cpu, tmp_path, small_scene):
    """An interrupted run writes its checkpoint and a summary saying so; a Simulation built from the checkpoint
    continues where it stopped."""
    import json

    import taichimyxo as tm
    from taichimyxo.io.writers import Checkpoint, Summary
    sc = small_scene(4, run={"dt_ms": 1.0})
    sim = tm.Simulation(sc)
    ck = tmp_path / "s.ckpt.npz"
    try:
        run = tm.run(sim, seconds=2, writers=[Checkpoint(ck), Summary(tmp_path / "s.json", checkpoint=ck)],
                     stop_after_steps=700)
        assert run.status == "interrupted" and sim.step_count == 700 and ck.is_file()
        d = json.loads((tmp_path / "s.json").read_text())
        assert d["status"] == "interrupted" and d["steps"] == 700 and d["files"]["checkpoint"] == ck.name
        again = tm.Simulation.from_checkpoint(sc, ck)
        try:
            assert again.step_count == 700 and np.array_equal(again.positions(), sim.positions())
        finally:
            again.close()
        assert tm.run(sim, steps=10, writers=[Checkpoint(ck)]).completed and not ck.exists()
    finally:
        sim.close()


def test_a_misplaced_argument_to_simulation_names_the_call_that_takes_it():
    """Refused before Taichi starts, in one sentence naming the argument and the call or value to use."""
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime.simulation import Simulation
    sc = Scene.load("S1")
    with pytest.raises(TypeError, match=r"positions=.*Simulation\.from_positions\(scene, positions, engine_dir"):
        Simulation(sc, positions=np.zeros((1, 8, 2)), engine_direction=np.ones(1))
    with pytest.raises(TypeError, match=r"checkpoint=.*Simulation\.from_checkpoint"):
        Simulation(sc, checkpoint="run.ckpt")
    with pytest.raises(TypeError, match=r"tolerance=.*unknown option.*contacts, tol, max_iter"):
        Simulation(sc, tolerance=1e-6)
    with pytest.raises(TypeError, match=r"contacts=.*run.integrator = 'imex'.*'explicit'"):
        Simulation(sc, contacts="coupled")


BAD_CALLS = [
    ("load_scene", lambda tm: tm.load_scene("S99"), "unknown scene 'S99'.*available: S1"),
    ("load_scene", lambda tm: tm.load_scene("S1", set={"cell.k_a_N_m": -1}), r"cell.k_a_N_m = -1.0: must be positive"),
    ("load_scene", lambda tm: tm.load_scene("S1", set={"cell.foo": 1}), r"'cell.foo': unknown key"),
    ("load_scene", lambda tm: tm.load_scene("S1", set=["x"]), r"load_scene\(set=...\): expected a dict.*got list"),
    ("load_scene", lambda tm: tm.load_scene("S1", seed=-1), r"run.seed = -1: must be zero or positive"),
    ("Simulation", lambda tm: tm.Simulation("S1"), r"Simulation\(scene\): expected a Scene.*load_scene.*got str"),
    ("run", lambda tm: tm.run(None, minutes=1), r"run\(sim, ...\): expected a Simulation"),
    ("render_frame", lambda tm: tm.render_frame(None), r"render_frame\(frame\): expected a Frame, e.g. sim.frame\(\)"),
    ("render_movie", lambda tm: tm.render_movie("/nonexistent/x.gsd"), r"/nonexistent/x.gsd not found"),
    ("analyze", lambda tm: tm.analyze("x.gsd", every=0), r"analyze\(every\) = 0: expected a whole number >= 1"),
    ("claims", lambda tm: tm.claims([]), r"claims needs at least one trajectory"),
    ("claims", lambda tm: tm.claims(["a.gsd"], every=-2), r"claims\(every\) = -2: expected a whole number"),
    ("Periodic", lambda tm: tm.Periodic(minutes=-1), r"Periodic: the period must be positive"),
    ("WallClock", lambda tm: tm.WallClock(seconds=-1), r"WallClock: the interval must be zero or positive, e.g."),
    ("load_sweep", lambda tm: tm.load_sweep("/nonexistent.toml"), r"sweep file /nonexistent.toml not found"),
    ("run_scene", lambda tm: tm.run_scene("S1"), r"run_scene\(scene\): expected a Scene, e.g. tm.load_scene"),
    ("run_sweep", lambda tm: tm.run_sweep("/nonexistent.toml"), r"sweep file /nonexistent.toml not found"),
    ("drive", lambda tm: tm.drive(None, 5), r"drive\(sim, n_steps\): expected a Simulation"),
    ("read_tracks", lambda tm: tm.read_tracks("/nonexistent.csv"), r"tracks file /nonexistent.csv not found"),
    ("read_tracks", lambda tm: tm.read_tracks("x.csv", pixel_um=-1), r"pixel size -1 µm: expected a positive"),
    ("tracks_report", lambda tm: tm.tracks_report("x.csv", v_b=-1), r"v_b \(--v-b\) = -1: expected the free"),
    ("tracks_report", lambda tm: tm.tracks_report("x.csv", against=["/nonexistent"]), r"/nonexistent: no such"),
]


@pytest.mark.parametrize("name,call,message", BAD_CALLS, ids=[f"{b[0]}-{i}" for i, b in enumerate(BAD_CALLS)])
def test_every_public_function_refuses_bad_input_in_one_sentence_naming_it(name, call, message):
    """Each public function of `import taichimyxo as tm`, given a wrong value: one line that names the input and
    says what is valid, raised before any work (no Taichi, no file written)."""
    import taichimyxo as tm
    assert name in tm.__all__
    with pytest.raises((ValueError, TypeError)) as e:
        call(tm)
    text = str(e.value)
    assert "\n" not in text and re.search(message, text), text


def test_every_public_function_is_in_the_table_of_bad_calls():
    import taichimyxo as tm
    callables = {n for n in tm._LAZY if n[0].islower() or n in ("Simulation", "Periodic", "WallClock")}
    checked = {b[0] for b in BAD_CALLS}
    assert callables <= checked, callables - checked
