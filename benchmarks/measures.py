"""Timing of the experimental measures (taichimyxo.analysis.measures: defects, cluster sizes with the bootstrap,
correlations, MSD) on a paper-scale trajectory: 360 frames of about 2000 cells x 8 particles in a 200 µm box
(synthetic: rotating disks, streams and a gas, written with the project's trajectory writer, with velocities).

    python benchmarks/measures.py [--quick] [--out DIR] [--keep PATH.gsd]

Reports the wall time to read the frames alone and to read them and compute every measure (the figure excluded),
with the load average at the start and the end (the machine is shared), and the CPU time of this process for the
measures (all its threads: freud uses both cores). --quick: 60 frames."""
from __future__ import annotations

import json
import os
import tempfile
import time

from benchlib import parser
from taichimyxo.analysis.measures import measure_frames
from taichimyxo.analysis.synthetic import write_synthetic
from taichimyxo.io.trajectory import read_frames


def paper_scale(path: str, n_frames: int) -> str:
    disks = [dict(centre=(30 + 45 * (k % 4), 30 + 45 * (k // 4)), radius=8 + 2 * (k % 3),
                  omega=0.4 if k % 2 else -0.4) for k in range(10)]
    streams = [dict(origin=(10, 185), angle=0.1, rows=8, per_row=30, speed=4.0),
               dict(origin=(185, 10), angle=1.6, rows=8, per_row=30, speed=4.0)]
    return write_synthetic(path, n_frames=n_frames, box=(200.0, 200.0), disks=disks, streams=streams, gas=600,
                           seed=1, speed_noise=0.1)


def main():
    p = parser(__doc__, quick_help="60 frames instead of 360")
    p.add_argument("--keep", help="write (or reuse) the synthetic trajectory here instead of a temporary file")
    a = p.parse_args()
    n = 60 if a.quick else 360
    tmp = None
    path = a.keep
    if path is None:
        tmp = tempfile.TemporaryDirectory()
        path = os.path.join(tmp.name, "paper360.gsd")
    t0 = time.perf_counter()
    if not os.path.exists(path):
        paper_scale(path, n)
    t_write = time.perf_counter() - t0
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    frames = list(read_frames(path))
    t_read = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), time.process_time()
    ms = measure_frames(frames)
    t_meas, c_meas = time.perf_counter() - t0, time.process_time() - c0
    res = dict(frames=len(frames), cells=frames[0].n_cells, particles=frames[0].n_cells * frames[0].particles_per_cell,
               write_s=round(t_write, 1), read_s=round(t_read, 1), measures_s=round(t_meas, 1),
               measures_cpu_s=round(c_meas, 1),
               total_s=round(t_read + t_meas, 1), per_frame_ms=round(1000 * t_meas / len(frames), 1),
               loadavg_start=[round(x, 2) for x in load0], loadavg_end=[round(x, 2) for x in os.getloadavg()],
               cpus=os.cpu_count(), defects_last=[ms["defects"]["n_plus_half"][-1], ms["defects"]["n_minus_half"][-1]],
               msd_exponent=ms["msd"]["exponent"], cluster_alpha=ms["cluster_sizes"]["alpha"])
    print(json.dumps(res))
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "measures_timing.json"), "w") as f:
        json.dump(res, f, indent=1)
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
