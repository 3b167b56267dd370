"""MP4 (H.264, yuv420p) movies and PNG figure panels from Frames, through imageio-ffmpeg. No display needed.

    with VideoWriter("videos/S3.mp4", fps=30) as vw:
        for frame in frames:
            vw.append(frame)
    write_png(last_frame, "videos/S3.png", title="S3")

The video is encoded by the ffmpeg binary shipped with imageio-ffmpeg (libx264, ``-crf 18 -preset veryfast``,
``yuv420p`` so every player can show it), fed from a background thread. The MP4 is **fragmented**
(``-movflags frag_keyframe+empty_moov+default_base_moof``, a keyframe every ``keyframe_interval`` frames, one
second of movie by default): the header is written first and every keyframe closes a fragment, so the file is a
playable movie of everything up to the last closed fragment while the run is still going, and an interrupted or
killed run leaves a readable movie too (the frames after the last keyframe are lost only in the killed case).
Frame size: ``size`` is the largest frame; by default the frame takes the domain's aspect ratio (see
:mod:`taichimyxo.render.raster`); ``fit=False`` keeps exactly ``size``. Width and height must be even for yuv420p:
an odd size is rounded UP to the next even number (the frame is rendered at that size, never rescaled). After
``close()`` the file is checked: it must exist, be non-empty, and ffmpeg must count exactly the frames that were
appended; otherwise ``VideoWriteError``.

Figure panels: :func:`write_png` is the one function both ``scene`` (the last frame, NAME.png) and ``render``
(``--out``'s .png) use: the same panel size (``PNG_SIZE``, fitted to the box), colours and labels (title = the
scene name).
"""
from __future__ import annotations

import atexit
import os
import queue
import threading
import weakref

import numpy as np

from .raster import Renderer, get_renderer, scene_name

DEFAULT_SIZE = (1920, 1080)
DEFAULT_FPS = 30
PNG_SIZE = (1600, 1200)      # a figure panel, fitted to the box: a square box gives 1032 x 1200 px
FRAGMENT_MOVFLAGS = "frag_keyframe+empty_moov+default_base_moof"


class VideoWriteError(RuntimeError):
    """ffmpeg did not produce the expected movie."""


def even_size(size) -> tuple[int, int]:
    """(width, height) rounded up to even numbers (yuv420p needs them)."""
    w, h = int(size[0]), int(size[1])
    return w + (w & 1), h + (h & 1)


class _Encoder(threading.Thread):
    """Feeds frames to ffmpeg (imageio_ffmpeg.write_frames) from a background thread.

    Signals are delivered to the main thread only, so a Ctrl-C can never interrupt a frame half-way into ffmpeg's
    pipe; and rendering the next frame overlaps with encoding this one. The thread is a daemon closed by ``stop()``
    (or, for writers never closed, at interpreter exit by an atexit hook)."""

    def __init__(self, path, size, fps, output_params, log_level):
        super().__init__(name=f"taichimyxo-video:{os.path.basename(path)}", daemon=True)
        self.path, self.size, self.fps = path, size, fps
        self.output_params, self.log_level = output_params, log_level
        self.queue: queue.Queue = queue.Queue(maxsize=3)
        self.stopping = False           # plain flag: set without taking any lock (signal-handler safe)
        self.sent = 0                   # frames handed to ffmpeg
        self.error: BaseException | None = None

    def run(self):
        import imageio_ffmpeg

        gen = None
        try:
            gen = imageio_ffmpeg.write_frames(
                self.path, self.size, pix_fmt_in="rgb24", pix_fmt_out="yuv420p", fps=self.fps, quality=None,
                codec="libx264", macro_block_size=2, ffmpeg_log_level=self.log_level,
                output_params=list(self.output_params))
            gen.send(None)
            while True:
                try:
                    img = self.queue.get(timeout=0.05)
                except queue.Empty:
                    if self.stopping:
                        break
                    continue
                if self.error is None:
                    gen.send(img)
                    self.sent += 1
        except BaseException as err:  # noqa: BLE001 - reported to the writer
            self.error = err
            while not self.stopping:    # keep draining so that a producer never blocks
                try:
                    self.queue.get(timeout=0.05)
                except queue.Empty:
                    pass
        finally:
            if gen is not None:
                try:
                    gen.close()         # closes ffmpeg's stdin and waits for it to finish the file
                except BaseException as err:  # noqa: BLE001
                    self.error = self.error or err

    def put(self, img: np.ndarray) -> bool:
        while not self.stopping:
            try:
                self.queue.put(img, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def stop(self):
        self.stopping = True
        self.join()


_OPEN_WRITERS: "weakref.WeakSet[VideoWriter]" = weakref.WeakSet()


@atexit.register
def _close_open_writers():
    for w in list(_OPEN_WRITERS):
        try:
            w.close()
        except Exception:  # noqa: BLE001 - best effort at exit
            pass


class VideoWriter:
    """Append Frames to an MP4 movie (H.264, yuv420p).

    Parameters
    ----------
    path: output file (``.mp4``); its folder is created if missing.
    size: (width, height) px wanted, rounded up to even numbers. By default (``fit=True`` in render_options) the
        largest frame: the movie takes the domain's aspect ratio within it, and ``size`` becomes the actual frame
        size at the first ``append``.
    fps: frames per second of the movie (not of the simulation).
    color: ``"speed"`` (linear 0–16 µm/min), ``"strain"`` (log10 J), ``"identity"``, ``"polarity"`` or
        ``"orientation"``; see :mod:`taichimyxo.render.colors`.
    crf, preset: libx264 quality (lower crf = better; 18 is visually lossless) and speed preset ("veryfast" by
        default: at 1080p about 3x cheaper than "medium" for the same size on our frames, leaving the CPU to the
        simulation).
    keyframe_interval: frames between keyframes, i.e. the length of one fragment of the fragmented MP4 (default:
        one second of movie, ``round(fps)``). The file is readable up to the last finished fragment while it is
        being written.
    check: after closing, verify the file (exists, non-empty, frame count) and raise ``VideoWriteError`` if not.
    render_options: passed to :class:`taichimyxo.render.raster.Renderer` (fit, vmin, vmax, background,
        decorations, title, free_speed, …). The title defaults to the first frame's scene name (``title=None``:
        none).

    ffmpeg starts lazily at the first ``append`` (the box is taken from the first frame) and is fed from a
    background thread. ``close()`` is idempotent and safe on an interrupt path (``except KeyboardInterrupt:
    vw.close()``, or from a signal handler): it takes no lock, waits for the queued frames, and lets ffmpeg finish
    the file (ffmpeg runs in its own process group, so Ctrl-C does not kill it). Writers never closed are closed at
    interpreter exit. With no frame appended, close() writes nothing.
    """

    def __init__(self, path, size=DEFAULT_SIZE, fps=DEFAULT_FPS, color="speed", *, crf: int = 18,
                 preset: str = "veryfast", keyframe_interval: int | None = None, check: bool = True,
                 ffmpeg_log_level: str = "error", **render_options):
        self.path = os.fspath(path)
        self.request = even_size(size)
        self.size = self.request
        if not fps or fps <= 0:
            raise ValueError(f"fps={fps!r} must be > 0")
        self.fps = fps
        self.keyframe_interval = max(1, int(round(fps)) if keyframe_interval is None else int(keyframe_interval))
        self.color = color
        self.crf = int(crf)
        self.preset = preset
        self.check = check
        self.ffmpeg_log_level = ffmpeg_log_level
        self.render_options = render_options
        self.renderer: Renderer | None = None
        self._enc: _Encoder | None = None
        self._appended = 0
        self._closed = False
        self._closing = False

    @property
    def frames_written(self) -> int:
        """Frames accepted so far (after close(): frames that reached ffmpeg)."""
        return self._enc.sent if (self._closed and self._enc is not None) else self._appended

    @property
    def closed(self) -> bool:
        return self._closed

    def append(self, frame) -> np.ndarray:
        """Render ``frame`` and add it to the movie. Returns the rendered image (H, W, 3) uint8."""
        self._check_open()
        if self.renderer is None:
            if self._enc is not None:
                raise ValueError("append(frame) after append_image(): use one or the other in a movie")
            opts = dict(self.render_options)
            if "title" not in opts:
                opts["title"] = scene_name(frame)
            self.renderer = get_renderer(frame.box, self.request, self.color, **opts)
            self.size = even_size(self.renderer.size)
        img = self.renderer.render(frame)
        self.append_image(img)
        return img

    def append_image(self, img: np.ndarray) -> None:
        """Add an already rendered RGB image of exactly ``size`` (the frame size; before the first frame, the
        requested size) to the movie (the writer keeps a reference: don't modify the array afterwards)."""
        self._check_open()
        w, h = self.size
        if img.shape != (h, w, 3) or img.dtype != np.uint8:
            raise ValueError(f"image of shape {img.shape} {img.dtype}; expected ({h}, {w}, 3) uint8")
        if self._enc is None:
            os.makedirs(os.path.dirname(os.path.abspath(self.path)), exist_ok=True)
            # fragmented MP4, a fragment per keyframe, each written out at once: readable while being written
            params = ["-crf", str(self.crf), "-preset", self.preset, "-g", str(self.keyframe_interval),
                      "-movflags", FRAGMENT_MOVFLAGS, "-flush_packets", "1"]
            self._enc = _Encoder(self.path, self.size, self.fps, params, self.ffmpeg_log_level)
            self._enc.start()
            _OPEN_WRITERS.add(self)
        if self._enc.error is not None:
            raise VideoWriteError(f"ffmpeg failed while writing {self.path}: {_first_line(self._enc.error)}")
        if self._enc.put(np.ascontiguousarray(img)):
            self._appended += 1

    def _check_open(self):
        if self._closed or self._closing:
            raise ValueError(f"VideoWriter({self.path!r}) is closed")

    def close(self) -> None:
        """Finish the movie (idempotent). Then, if ``check``, verify it; raise ``VideoWriteError`` on failure."""
        if self._closed or self._closing:
            return
        self._closing = True
        enc = self._enc
        try:
            if enc is not None:
                enc.stop()
        finally:
            self._closed = True
            _OPEN_WRITERS.discard(self)
        if enc is None:
            return
        if enc.error is not None:
            raise VideoWriteError(f"ffmpeg failed while writing {self.path}: {_first_line(enc.error)}")
        if self.check:
            verify_video(self.path, enc.sent)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:                       # don't hide the original error behind a check failure
            try:
                self.close()
            except VideoWriteError:
                pass


def _first_line(err: BaseException) -> str:
    s = str(err).strip()
    return s.splitlines()[0] if s else type(err).__name__


def verify_video(path, expected_frames: int | None = None) -> int:
    """Check that ``path`` is a readable movie (with ``expected_frames`` frames); return its frame count."""
    import imageio_ffmpeg

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise VideoWriteError(f"{path}: ffmpeg wrote no file")
    if os.path.getsize(path) == 0:
        raise VideoWriteError(f"{path}: ffmpeg wrote an empty file")
    try:
        n, _secs = imageio_ffmpeg.count_frames_and_secs(path)
    except Exception as err:  # noqa: BLE001 - any ffmpeg failure means an unreadable movie
        raise VideoWriteError(f"{path}: not a readable movie ({str(err).splitlines()[0] if str(err) else err!r})") \
            from err
    if expected_frames is not None and n != expected_frames:
        raise VideoWriteError(f"{path}: ffmpeg counts {n} frames, {expected_frames} were written")
    return int(n)


def write_png(frame, path, size=PNG_SIZE, color="speed", **render_options) -> np.ndarray:
    """Write ``frame`` as a PNG figure panel (like the paper's Fig 2B–F: box, legend with units at the bottom,
    time, scale bar, title). Returns the image.

    The one panel style of the project: ``scene`` (NAME.png, the last frame) and ``render`` (next to the movie)
    both call this with the default ``size`` (PNG_SIZE, fitted to the box's aspect ratio) and the title taken from
    the frame's scene name (pass ``title=`` to override, ``title=None`` for none)."""
    import imageio.v3 as iio

    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    if "title" not in render_options:
        render_options["title"] = scene_name(frame)
    img = get_renderer(frame.box, size, color, **render_options).render(frame)
    iio.imwrite(path, img, extension=".png")
    return img
