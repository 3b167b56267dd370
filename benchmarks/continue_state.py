"""Continue a benchmark state as a run: a trajectory of the state's own scene, with particle velocities, from the
state's positions on (benchmarks/states.py), for the measurements a state's single frame cannot give.

    python benchmarks/continue_state.py --state "S3 6 h" --minutes 20 --frame-seconds 30 --out DIR [--resume]
    python benchmarks/aggregate_balance.py DIR/S3.gsd --start-fraction 0.05 --out DIR/aggregate_balance.md

The S3 6 h state is the last frame of the figures' paper-scale S3 (its record keeps positions, not velocities), so
its aggregates' torque balance (docs/measures.md) needs the motion a continuation gives: the cells go on from where
the 6 h run ended, at the scene's own step, under the same physics (the state's positions are stored in f32, so the
continuation is a new sample of the same late state, not the original run's next hour). Times in the trajectory
count from the state (0 at its frame), and the first frame has no velocities (its speed window is empty), hence
the balance's --start-fraction. The run is a scene run like any other (checkpoints, --resume, invariants).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from states import load

# the states stored as files (a run's frame); S13 dense is its scene's own start, with nothing to continue
CONTINUABLE = ("S3 6 h", "S3 1 h")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--state", default="S3 6 h", choices=CONTINUABLE, help="benchmark state")
    ap.add_argument("--minutes", type=float, required=True, help="simulated minutes to continue")
    ap.add_argument("--frame-seconds", type=float, default=30.0, help="simulated seconds between trajectory frames")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--resume", action="store_true", help="continue an unfinished continuation in --out")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    if a.minutes <= 0 or a.frame_seconds <= 0:
        print("continue_state: --minutes and --frame-seconds must be positive", file=sys.stderr)
        return 2
    scene_name, _, start = load(a.state)
    from taichimyxo.io.scene import Scene, SceneError
    from taichimyxo.runtime.scene_run import run_scene
    frame_min = a.frame_seconds / 60.0
    try:
        scene = Scene.load(scene_name, {"run": {"hours": a.minutes / 60.0},
                                        "output": {"movie": False, "frame_interval_min": frame_min,
                                                   "trajectory_interval_min": frame_min}})
        summary = run_scene(scene, str(a.out), resume=a.resume, threads=a.threads, start_state=start)
    except SceneError as e:
        print(f"continue_state: {e}", file=sys.stderr)
        return 2
    print(f"continue_state: {a.state} continued {a.minutes:g} min into {a.out} "
          f"({summary.get('status', 'done')}, {summary.get('wall_seconds', 0.0):.0f} s of wall time)")
    return 0 if summary.get("completed") else 1


if __name__ == "__main__":
    sys.exit(main())
