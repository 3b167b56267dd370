"""Two runs compared at one simulated time: the measures of benchmarks/compare_runs.py and both frames side by side.

    python benchmarks/results/contact_fix/compare_at.py MINUTES BEFORE.gsd AFTER.gsd OUT.png

Aggregates are detected twice where a run stores velocities: from the velocities, and from speed x forward tangent
(the only input a trajectory without velocities offers), so runs with and without velocities compare like for like.
"""
import copy
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))          # benchmarks/, for compare_runs
from compare_runs import frame_stats  # noqa: E402

from taichimyxo.io.trajectory import read_frames  # noqa: E402
from taichimyxo.render import render_frame  # noqa: E402


def frame_at(path: str, minutes: float):
    for fr in read_frames(path):
        if abs(fr.time_s / 60.0 - minutes) < 0.01:
            return fr
    raise SystemExit(f"{path}: no frame at {minutes:g} min")


def main() -> None:
    if len(sys.argv) != 5:
        raise SystemExit(__doc__.strip().splitlines()[2].strip())
    minutes = float(sys.argv[1])
    frames = {"before": frame_at(sys.argv[2], minutes), "after": frame_at(sys.argv[3], minutes)}
    stats = {}
    for name, fr in frames.items():
        no_vel = copy.copy(fr)
        no_vel.particle_velocity = None
        stats[f"{name} (speed x tangent)"] = frame_stats(no_vel)
        if fr.particle_velocity is not None:
            stats[f"{name} (velocities)"] = frame_stats(fr)
    cols = list(stats)
    print(f"{'':28s}" + "".join(f"{c:>26s}" for c in cols))
    for key in stats[cols[0]]:
        vals = [stats[c][key] for c in cols]
        print(f"{key:28s}" + "".join(f"{(round(v, 4) if isinstance(v, float) else str(v))!s:>26s}" for v in vals))
    iio.imwrite(sys.argv[4], np.concatenate([render_frame(frames[n], size=(900, 900)) for n in ("before", "after")],
                                            axis=1))


if __name__ == "__main__":
    main()
