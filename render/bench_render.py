"""Rendering throughput: ``python -m taichimyxo.render.bench_render [--frames 20] [--size 1920x1080] [--encode]``.

Times render_frame on 2000 random cells of 8 particles (16 000 particles, 14 000 segments; and the brief's
"16 000 segments" case of 2000 cells x 9 particles) in a 200 x 200 µm periodic box with random speeds and strain,
and prints frames per second. With ``--encode``, also the cost of H.264 encoding (VideoWriter) per frame.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

from taichimyxo.io.frame import Frame, unwrap_chains

from .raster import render_frame


def random_frame(n_cells=2000, particles=8, box=(200.0, 200.0), seed=0, time_s=3 * 3600 + 45 * 60,
                 width_um=0.5, length_um=5.0) -> Frame:
    """Straight-ish random cells (slightly bent chains), random speeds 0–18 µm/min and strain 0 or 1e-21–1e-15 J."""
    rng = np.random.default_rng(seed)
    L = np.asarray(box, dtype=np.float64)
    centre = rng.uniform(0.0, 1.0, (n_cells, 2)) * L
    l0 = (length_um - width_um) / (particles - 1)
    ang = rng.uniform(0, 2 * np.pi, (n_cells, 1)) + np.cumsum(rng.normal(0, 0.08, (n_cells, particles - 1)), axis=1)
    steps = np.stack([np.cos(ang), np.sin(ang)], axis=-1) * l0
    p = np.concatenate([np.zeros((n_cells, 1, 2)), np.cumsum(steps, axis=1)], axis=1)
    p = unwrap_chains(p - p.mean(axis=1, keepdims=True) + centre[:, None], box)
    speed = rng.uniform(0, 18, (n_cells, 1)) + rng.normal(0, 0.5, (n_cells, particles))
    strain = np.where(rng.uniform(size=(n_cells, particles - 1)) < 0.5, 0.0,
                      10.0 ** rng.uniform(-21, -15, (n_cells, particles - 1)))
    return Frame(time_s=time_s, step=0, box=tuple(box), width_um=width_um, positions=p,
                 engine_direction=rng.choice(np.array([-1, 1], np.int8), n_cells),
                 particle_speed=speed.astype(np.float32), segment_strain=strain)


def bench(frame, size, color, n_frames) -> tuple[float, float]:
    """(frames per second of wall time, CPU seconds per frame). Rendering is single-threaded numpy, so on a busy
    machine the CPU time is the better estimate of the uncontended cost."""
    render_frame(frame, size=size, color=color)            # builds the decorations once
    t, c = time.perf_counter(), time.process_time()
    for _ in range(n_frames):
        render_frame(frame, size=size, color=color)
    return n_frames / (time.perf_counter() - t), (time.process_time() - c) / n_frames


def bench_encode(frames, size) -> float:
    from .video import VideoWriter

    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "bench.mp4")
        t = time.perf_counter()
        with VideoWriter(path, size=size) as vw:
            for fr in frames:
                vw.append(fr)
        return len(frames) / (time.perf_counter() - t)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--encode", action="store_true", help="also time render + H.264 encoding through VideoWriter")
    a = ap.parse_args(argv)
    size = tuple(int(v) for v in a.size.lower().split("x"))
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"render_frame at {size[0]}x{size[1]}, 200 x 200 µm box, {os.cpu_count()} CPU(s), load {load:.1f}")
    for particles in (8, 9):
        fr = random_frame(2000, particles)
        nseg = fr.n_cells * (particles - 1)
        for color in ("speed", "strain"):
            fps, cpu = bench(fr, size, color, a.frames)
            print(f"  2000 cells x {particles} particles = {nseg:6d} segments, color={color:6s}: "
                  f"{fps:6.1f} frames/s ({1000.0 / fps:5.1f} ms/frame wall, {1000.0 * cpu:5.1f} ms CPU)")
    if a.encode:
        frames = [random_frame(2000, 8, seed=i, time_s=60.0 * i) for i in range(a.frames)]
        fps = bench_encode(frames, size)
        print(f"  render + H.264 encode (VideoWriter, random frames): {fps:6.1f} frames/s "
              f"({1000.0 / fps:5.1f} ms/frame)")


if __name__ == "__main__":
    main()
