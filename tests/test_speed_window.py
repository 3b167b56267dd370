"""The displayed-speed window (run.speed_window_s): when frames are closer than the window, the window of the next
frame opens at the previous frame (so a frame's speed is over the last frame interval), not at step 0; checked on the
checkpoint of a run stopped between frames."""
import numpy as np


def test_displayed_speed_window_opens_at_the_previous_frame_when_frames_are_closer(tmp_path):
    """Frames every 3 s with a 10 s speed window: the window opens at the previous frame (so the speed is over the
    last 3 s), not at step 0 (the old behaviour: the net displacement since the start)."""
    from taichimyxo.io.scene import Scene
    from taichimyxo.runtime.scene_run import run_scene
    sc = Scene.from_dict({"scene": {"name": "win"}, "domain": {"width_um": 20.0, "height_um": 20.0},
                          "population": {"cells": 1},
                          "run": {"hours": 0.01, "dt_ms": 2.0, "speed_window_s": 10.0},
                          "output": {"movie": False, "frame_interval_min": 0.05}})
    every = sc.frame_every_steps
    assert every == 1500
    run_scene(sc, out_dir=str(tmp_path), progress=False, stop_after_steps=3 * every + 100)
    ck = np.load(tmp_path / "win.ckpt.npz")
    assert int(ck["step"]) == 3 * every + 100
    assert int(ck["snap_step"]) == 3 * every
