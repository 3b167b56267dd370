"""taichimyxo.render: off-screen movies and figure panels from Frames (no display, no GPU, no Taichi).

- :func:`render_frame` — one Frame → RGB image (H, W, 3) uint8: cells as outlined capsules, coloured by segment
  speed (linear 0–16 µm/min) or strain energy (log10, 1e-21–1e-17 J) on ``turbo`` (a perceptual ``jet``), or per
  cell by identity, polarity (engine direction) or axis orientation (cyclic map); white background, legend with
  units, time (``t = 1 h 05 min``), scale bar and title at the bottom. The frame takes the domain's aspect ratio
  within the requested size (``fit=False``: exactly the size).
- :class:`VideoWriter` — Frames → fragmented MP4 (H.264, yuv420p), readable while it is written, checked after
  close.
- :func:`write_png` — one Frame → PNG figure panel (the one panel style of ``scene`` and ``render``).
- :func:`render_trajectory` — a GSD trajectory (taichimyxo.io.trajectory) → MP4, without simulating.
"""
from __future__ import annotations

import math
import os

from .colors import COLORINGS, CategoricalScale, ColorScale, make_scale, speed_scale, strain_scale
from .raster import FrameLayout, Renderer, Viewport, compute_layout, format_time, frame_size, get_renderer, render_frame
from .video import PNG_SIZE, VideoWriteError, VideoWriter, verify_video, write_png

__all__ = ["render_frame", "VideoWriter", "write_png", "render_trajectory", "Renderer", "Viewport", "FrameLayout",
           "ColorScale", "CategoricalScale", "COLORINGS", "make_scale", "speed_scale", "strain_scale",
           "compute_layout", "format_time", "frame_size", "get_renderer", "verify_video", "VideoWriteError",
           "PNG_SIZE"]


def render_trajectory(gsd_path, out_path, color="speed", size=(1920, 1080), fps=30, every=1, png_path=None,
                      progress=True, png_size=PNG_SIZE, strain_from=None, **options) -> int:
    """Render the GSD trajectory ``gsd_path`` to the MP4 ``out_path`` (no simulation). Returns the frame count.

    color: speed, strain, identity, polarity or orientation. size: the largest frame (the movie takes the domain's
    aspect ratio within it). every: use every n-th stored frame. png_path: also write the last rendered frame as
    a PNG figure panel (:func:`write_png`, ``png_size``, same colours and labels). options: VideoWriter / Renderer
    options (crf, preset, keyframe_interval, vmin, vmax, background, fit, title, …); the title defaults to the
    scene name stored in the trajectory.
    strain_from: (W µm, k_c pN/µm) to colour by the strain energy computed from each frame's positions
    (Frame.with_strain) where the trajectory has none logged; without it, ValueError if
    ``color="strain"`` and the trajectory has no strain energy logged."""
    from taichimyxo.io.trajectory import count_frames, read_frames

    gsd_path, out_path = os.fspath(gsd_path), os.fspath(out_path)
    every = max(1, int(every))
    total = count_frames(gsd_path)
    if total == 0:
        raise ValueError(f"{gsd_path}: the trajectory has no frames")
    frames = read_frames(gsd_path, every=every)
    bar = None
    if progress:
        try:
            from tqdm import tqdm
            bar = tqdm(total=math.ceil(total / every), unit="frame", desc=f"render {os.path.basename(out_path)}")
        except ImportError:  # pragma: no cover - tqdm is a dependency, but rendering must not need it
            bar = None
    n = 0
    last = None
    png_options = {k: v for k, v in options.items()
                   if k not in ("crf", "preset", "check", "ffmpeg_log_level", "keyframe_interval", "fit")}
    make_scale(color, vmin=options.get("vmin"), vmax=options.get("vmax"))   # bad colour options: fail before work
    try:
        with VideoWriter(out_path, size=size, fps=fps, color=color, **options) as vw:
            for fr in frames:
                if color == "strain" and strain_from is not None:
                    fr = fr.with_strain(*strain_from)
                if color == "strain" and fr.segment_strain is None:
                    raise ValueError(f"{gsd_path}: color='strain' but the trajectory has no strain energy logged "
                                     f"(log/bonds/strain_energy_J); use color='speed' or rerun with strain output")
                vw.append(fr)
                last = fr
                n += 1
                if bar is not None:
                    bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        frames.close()
    if png_path is not None and last is not None:
        write_png(last, png_path, size=png_size, color=color, **png_options)
    return n
