"""Off-screen rasteriser: a Frame → an RGB image (numpy uint8, shape (H, W, 3)). No display, no GPU, no Taichi.

Picture (as the paper's Fig 2–4 and supplementary videos): the periodic box on a white background
(``background="black"`` for a dark one); every cell a capsule of diameter ``frame.width_um`` drawn along its
particle chain with a thin dark outline, so that touching cells stay distinct. Colourings (``color=``, see
:mod:`taichimyxo.render.colors`): each SEGMENT by its speed (linear 0–16 µm/min) or strain energy (log10
1e-21–1e-17 J), colormap ``turbo``; or each CELL by identity, polarity (engine direction) or axis orientation.
Below the box: the legend (colour bar with ticks and a label with units), the simulated time (``t = 45 min``,
``t = 1 h 05 min``), a scale bar of a round length of about a quarter of the box width, and the title (scene name).

Frame size (``fit=True``, the default): ``size`` is the largest frame wanted, and the frame takes the domain's
aspect ratio: the box is scaled to fill ``size`` less the margins and the legend strip, and the frame is cut down to
the box plus margins (both sides even), so a square domain in 1920 x 1080 gives a 1080-high frame about 930 px wide,
not a 16:9 picture half blank; a wide domain keeps the width and gets a lower frame. ``fit=False``: exactly
``size``, the box centred in it. Text scales with the requested size: the tick labels are 28 px at 1080 px
(``min(width, height)`` of the request), never smaller than 14 px (unless the image is under 224 px high), and the
legend strip grows with the text; when the frame is too narrow for legend, time and scale bar side by side, the
time and scale bar move to a second row.

How a frame is drawn (all numpy, no per-segment Python loop):

1. Segments whose capsule crosses the box edge are also drawn shifted by ±Lx, ±Ly ("wrapped copies"), so a cell
   across the periodic edge appears on both sides; everything is clipped to the box.
2. Every segment's pixel bounding box is enumerated (ragged, batched with ``np.repeat``); for each candidate pixel
   centre the distance d to the segment (the capsule's axis) is computed.
3. A pixel belongs to the capsule whose axis is nearest (an order-independent, deterministic rule: one
   ``np.minimum.at`` on a 64-bit key ``(d quantised) << 32 | segment``). Its coverage is ``clip(r + ½ − d, 0, 1)``
   pixels (a one-pixel antialiasing ramp), blended with the background. The outline: the outer ``outline_px`` of
   each capsule is darkened, and where a pixel's neighbour (right or below) belongs to another cell, the one of the
   two farther from its own axis is darkened too: a one-pixel line between touching cells. Pixels well inside a
   capsule hold exactly the colour-map colour of their segment.
4. The decorations (legend, labels, scale bar, title, box outline) are rendered once per (size, box, scale) with
   matplotlib's Agg backend and reused; the time is composed each frame from a pre-rendered monospace glyph atlas.

Coordinates: data in µm, origin at the lower left, y up. Image: pixel (row, col) covers the square
[col, col+1) × [row, row+1) of continuous image coordinates (u = column axis, v = row axis, v down). Use
:class:`Viewport` (``Renderer.viewport``) to go from µm to pixels.
"""
from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np

# the layout and the capsules live in their own modules; their names stay importable from here
from .capsules import OUTLINE_RGB, auto_outline, draw_capsules, periodic_copies  # noqa: F401
from .colors import SPEED_MAX_UM_PER_MIN, make_scale
from .layout import (  # noqa: F401
    FONT_PX_AT_1080,
    LONGEST_TIME,
    MIN_FONT_PX,
    TIME_FONT,
    FrameLayout,
    Viewport,
    compute_layout,
    font_size_px,
    glyph_width,
    legend_metrics,
    nice_scalebar_length,
    text_extent,
)

BACKGROUNDS = {
    "white": ((255, 255, 255), (0, 0, 0), (170, 170, 170)),   # background, text, box outline
    "black": ((0, 0, 0), (255, 255, 255), (90, 90, 90)),
}
TIME_CHARS = "0123456789t=hmin -"


# --------------------------------------------------------------------------------------------------- text

class GlyphAtlas:
    """Monospace glyphs pre-rendered once (matplotlib Agg, DejaVu Sans Mono) as coverage masks, for per-frame text."""

    def __init__(self, chars: str, font_px: float):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.font_px = font_px
        cw = glyph_width(font_px)
        ch = int(math.ceil(1.25 * font_px))
        fig = Figure(figsize=(cw * len(chars) / 100.0, ch / 100.0), dpi=100)
        canvas = FigureCanvasAgg(fig)
        fig.patch.set_facecolor("white")
        for i, c in enumerate(chars):
            fig.text((i + 0.5) / len(chars), 0.24, c, ha="center", va="baseline", family="DejaVu Sans Mono",
                     fontsize=font_px * 72.0 / 100.0, color="black")
        canvas.draw()
        rgba = np.asarray(canvas.buffer_rgba())
        cov = 1.0 - rgba[:, :, 0].astype(np.float32) / 255.0
        W = rgba.shape[1]
        self.height = rgba.shape[0]
        self.glyphs = {}
        for i, c in enumerate(chars):
            c0, c1 = round(i * W / len(chars)), round((i + 1) * W / len(chars))
            self.glyphs[c] = cov[:, c0:c1]
        self.blank = np.zeros_like(next(iter(self.glyphs.values())))

    def mask(self, text: str) -> np.ndarray:
        return np.concatenate([self.glyphs.get(c, self.blank) for c in text], axis=1)

    def draw(self, img: np.ndarray, text: str, center: tuple[int, int], color, align: str = "center") -> None:
        """Draw ``text`` centred on ``center`` (row, col), or (align="left") starting at col, centred on row."""
        m = self.mask(text)
        h, w = m.shape
        r0 = center[0] - h // 2
        c0 = center[1] - (w // 2 if align == "center" else 0)
        r1, c1 = r0 + h, c0 + w
        R0, C0 = max(r0, 0), max(c0, 0)
        R1, C1 = min(r1, img.shape[0]), min(c1, img.shape[1])
        if R1 <= R0 or C1 <= C0:
            return
        m = m[R0 - r0:R1 - r0, C0 - c0:C1 - c0, None]
        region = img[R0:R1, C0:C1].astype(np.float32)
        img[R0:R1, C0:C1] = (region * (1.0 - m) + np.asarray(color, np.float32) * m + 0.5).astype(np.uint8)


def format_time(time_s: float) -> str:
    """Simulated time in whole minutes (floor; tolerant of float drift): ``t = 45 min`` below an hour,
    ``t = 1 h 05 min`` from an hour on."""
    minutes = int(math.floor(abs(time_s) / 60.0 + 1e-6))
    sign = "-" if time_s < 0 and minutes > 0 else ""
    if minutes < 60:
        return f"t = {sign}{minutes} min"
    return f"t = {sign}{minutes // 60} h {minutes % 60:02d} min"


# --------------------------------------------------------------------------------------------------- renderer

def _rgb(c) -> tuple[int, int, int]:
    return tuple(int(v) for v in c)


def cell_axis_angle_deg(positions: np.ndarray) -> np.ndarray:
    """(n_cells,) angle of each cell's end-to-end axis from +x, counter-clockwise, modulo 180° (in [0, 180))."""
    p = np.asarray(positions, np.float64)
    if p.shape[0] == 0:
        return np.zeros(0)
    d = p[:, -1] - p[:, 0]
    ang = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    ang = np.mod(ang, 180.0)
    return np.where(ang >= 180.0, 0.0, ang)


def free_speed_of(frame, default: float = 4.0) -> float:
    """The cells' free speed v_b (µm/min): the scene's ``cell.speed_um_per_min`` when the frame carries the scene
    (frames read from a trajectory do), else ``default``."""
    meta = getattr(frame, "meta", None) or {}
    cell = meta.get("cell") if isinstance(meta, dict) else None
    if isinstance(cell, dict):
        try:
            v = float(cell.get("speed_um_per_min"))
            if v > 0 and math.isfinite(v):
                return v
        except (TypeError, ValueError):
            pass
    return float(default)


def scene_name(frame) -> str | None:
    """The scene name a frame carries (``meta["scene"]``: the name in live frames, the scene dict in frames read
    from a trajectory), or None."""
    meta = getattr(frame, "meta", None) or {}
    sc = meta.get("scene") if isinstance(meta, dict) else None
    if isinstance(sc, dict):
        sc = sc.get("name")
    return str(sc) if sc else None


def is_unmeasured_first_frame(frame) -> bool:
    """True for the frame at t = 0 whose speeds are all zero (no displacement has been measured yet)."""
    return abs(float(frame.time_s)) < 1e-9 and not np.any(np.asarray(frame.particle_speed))


class Renderer:
    """Renders Frames of one box into images of one size with one colour scale; decorations are built once.

    Parameters
    ----------
    size: (width, height) px wanted; with ``fit`` (default) the largest frame, cut to the box's aspect ratio
        (``Renderer.size`` is the frame's actual size), else exactly this size.
    color: ``"speed"`` (linear ``vmin``–``vmax`` µm/min, default 0–16), ``"strain"`` (log10, ``vmin``–``vmax`` J,
        default 1e-21–1e-17), ``"identity"``, ``"polarity"``, ``"orientation"`` (see
        :mod:`taichimyxo.render.colors`), or a ready scale.
    box: (Lx, Ly) µm of the periodic domain.
    background: ``"white"`` (the paper's look) or ``"black"``.
    decorations: draw legend, time, scale bar and title (False: the box only, with margins).
    fit: see ``size``.
    vmin, vmax: ends of the colour range (speed, strain). strain_range: (vmin, vmax) J, older spelling.
    colormap: matplotlib colormap name (speed, strain, orientation).
    min_radius_px: capsules are never drawn thinner than this radius, so cells stay visible when zoomed out.
    outline: outline width in px (None: automatic, ~a fifth of the cell radius, see :func:`auto_outline`; 0: no
        outlines and no lines between touching cells).
    title: optional short text (e.g. the scene name) shown in the legend strip.
    t0_free_speed: colour the frame at t = 0, whose speeds are all zero because no displacement has been measured
        yet, as if every cell moved at its free speed v_b (``free_speed``, or the scene's
        ``cell.speed_um_per_min`` when the frame carries the scene) instead of showing every cell at 0. Only for
        ``color="speed"``; False shows the zeros.
    free_speed: v_b in µm/min for ``t0_free_speed`` when the frame doesn't carry its scene (default 4).
    """

    def __init__(self, size=(1920, 1080), color="speed", box=(200.0, 200.0), *, background="white",
                 decorations=True, fit=True, colormap=None, vmin=None, vmax=None, strain_range=None,
                 min_radius_px=0.6, outline=None, title: str | None = None, t0_free_speed: bool = True,
                 free_speed: float = SPEED_MAX_UM_PER_MIN / 4.0):
        if background not in BACKGROUNDS:
            raise ValueError(f"background={background!r}: allowed are {sorted(BACKGROUNDS)}")
        self.request = (int(size[0]), int(size[1]))
        self.box = (float(box[0]), float(box[1]))
        self.scale = make_scale(color, colormap=colormap, vmin=vmin, vmax=vmax, strain_range=strain_range)
        self.bg, self.fg, self.outline_box = (np.array(c, np.uint8) for c in BACKGROUNDS[background])
        self.decorations = decorations
        self.min_radius_px = float(min_radius_px)
        self.outline = None if outline is None else max(0.0, float(outline))
        self.title = None if title is None else str(title)
        self.t0_free_speed = bool(t0_free_speed)
        self.free_speed = float(free_speed)
        self.layout = compute_layout(self.request, self.box, decorations, fit=fit, scale=self.scale,
                                     title=self.title)
        self.size = self.layout.size
        self.viewport = self.layout.viewport
        self.lut = getattr(self.scale, "lut", None)
        self.static = self._build_static()
        self.atlas = GlyphAtlas(TIME_CHARS, TIME_FONT * self.layout.font_px) if decorations else None

    # ---- static decorations, rendered once
    def _build_static(self) -> np.ndarray:
        W, H = self.size
        lay, vp = self.layout, self.viewport
        if not self.decorations:
            img = np.empty((H, W, 3), np.uint8)
            img[:] = self.bg
            rs, cs = vp.slices
            _frame_rect(img, rs.start, rs.stop, cs.start, cs.stop, self.outline_box)
            return img
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        dpi = 100.0
        pt = 72.0 / dpi                     # points per pixel
        f = lay.font_px
        fg = tuple(self.fg / 255.0)
        fig = Figure(figsize=(W / dpi, H / dpi), dpi=dpi)
        canvas = FigureCanvasAgg(fig)
        fig.patch.set_facecolor(tuple(self.bg / 255.0))
        # legend bar axis: exactly over the bar rectangle, x from 0 to 1 along it; ticks and label below it
        r0, r1, c0, c1 = lay.colorbar
        ax = fig.add_axes([c0 / W, 1 - r1 / H, (c1 - c0) / W, (r1 - r0) / H])
        ax.set_xlim(0.0, 1.0)
        ax.set_ylim(0, 1)
        ax.set_yticks([])
        ax.set_xticks(list(self.scale.tick_positions()), list(self.scale.tick_labels))
        ax.tick_params(axis="x", direction="out", length=0.3 * f * pt, width=max(1.0, 0.05 * f) * pt, color=fg,
                       labelcolor=fg, labelsize=f * pt, pad=0.15 * f * pt)
        ax.set_xlabel(self.scale.label, fontsize=f * pt, color=fg, labelpad=0.25 * f * pt)
        for sp in ax.spines.values():
            sp.set_visible(False)
        ax.patch.set_visible(False)
        # scale bar label, above the bar
        s0, s1, q0, q1 = lay.scalebar
        fig.text((q0 + q1) / 2 / W, 1 - (s0 - 0.2 * f) / H, f"{lay.scalebar_um:g} µm", ha="center", va="bottom",
                 fontsize=f * pt, color=fg)
        if self.title and lay.title_center is not None:
            tr, tc = lay.title_center
            fig.text(tc / W, 1 - tr / H, self.title, ha="center", va="center", fontsize=f * pt, color=fg)
        canvas.draw()
        img = np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[:, :, :3])
        # exact colours painted over: the bar (column j ↔ the value at its centre), its frame, the scale bar, the box
        x = (np.arange(c1 - c0) + 0.5) / (c1 - c0)
        img[r0:r1, c0:c1] = self.scale.bar_rgb(x)[None, :, :]
        if self.scale.categorical:                       # thin separators between the swatches
            k = len(self.scale.swatches)
            for j in range(1, k):
                img[r0:r1, c0 + round(j * (c1 - c0) / k)] = self.bg
        _frame_rect(img, r0, r1, c0, c1, self.fg)
        img[s0:s1, q0:q1] = self.fg
        rs, cs = vp.slices
        _frame_rect(img, rs.start, rs.stop, cs.start, cs.stop, self.outline_box)
        img[rs, cs] = self.bg
        return img

    # ---- per frame
    def segment_colors(self, frame) -> np.ndarray:
        """(n_cells·(N−1), 3) uint8 colours of the segments, in the order of ``frame.positions[:, :-1]``."""
        name = self.scale.name
        nseg = max(frame.particles_per_cell - 1, 0)
        if self.scale.categorical:
            return np.repeat(self.scale.cell_colors(frame), nseg, axis=0)
        if name == "orientation":
            return np.repeat(self.scale.rgb(cell_axis_angle_deg(frame.positions)), nseg, axis=0)
        if name == "strain":
            if frame.segment_strain is None:
                raise ValueError("color='strain' but this frame has no strain energy (segment_strain is None); "
                                 "render with color='speed' or run the scene with strain output on")
            vals = np.asarray(frame.segment_strain)
        else:
            if self.t0_free_speed and is_unmeasured_first_frame(frame):
                vals = np.full((frame.n_cells, nseg), free_speed_of(frame, self.free_speed))
            else:
                vals = np.asarray(frame.segment_speed)
        return self.scale.rgb(vals.reshape(-1))

    def render(self, frame, out: np.ndarray | None = None) -> np.ndarray:
        """The image (H, W, 3) uint8 of ``frame`` (written into ``out`` when given), (H, W) = ``size`` reversed."""
        if not np.allclose(frame.box, self.box, rtol=1e-9, atol=0):
            raise ValueError(f"frame box {tuple(frame.box)} differs from the renderer's box {self.box}")
        img = out if out is not None else np.empty_like(self.static)
        np.copyto(img, self.static)
        vp = self.viewport
        pos = np.asarray(frame.positions, dtype=np.float64)
        if pos.shape[0] > 0 and pos.shape[1] >= 2:
            colors = self.segment_colors(frame)
            a = pos[:, :-1].reshape(-1, 2)
            b = pos[:, 1:].reshape(-1, 2)
            r_px = max(0.5 * float(frame.width_um) * vp.scale, self.min_radius_px)
            idx, A, B = periodic_copies(a, b, self.box, (r_px + 1.0) / vp.scale)
            if len(idx):
                # image coordinates relative to the box's top-left corner
                A = np.stack([A[:, 0] * vp.scale, (self.box[1] - A[:, 1]) * vp.scale], axis=1)
                B = np.stack([B[:, 0] * vp.scale, (self.box[1] - B[:, 1]) * vp.scale], axis=1)
                ow, strength = auto_outline(r_px)
                if self.outline is not None:
                    ow, strength = self.outline, (strength if self.outline > 0 else 0.0)
                groups = idx // (pos.shape[1] - 1) if strength > 0 else None
                draw_capsules(img[vp.slices], A, B, colors[idx], r_px, background=self.bg, groups=groups,
                              outline_px=ow, boundary=strength)
        if self.decorations:
            self.atlas.draw(img, format_time(frame.time_s), self.layout.time_center, self.fg,
                            align=self.layout.time_align)
        return img


def _frame_rect(img, r0, r1, c0, c1, color) -> None:
    """One-pixel frame just outside the half-open rectangle."""
    H, W = img.shape[:2]
    ra, rb, ca, cb = max(r0 - 1, 0), min(r1 + 1, H), max(c0 - 1, 0), min(c1 + 1, W)
    if r0 - 1 >= 0:
        img[r0 - 1, ca:cb] = color
    if r1 < H:
        img[r1, ca:cb] = color
    if c0 - 1 >= 0:
        img[ra:rb, c0 - 1] = color
    if c1 < W:
        img[ra:rb, c1] = color


_CACHE: "OrderedDict[tuple, Renderer]" = OrderedDict()


def get_renderer(box, size=(1920, 1080), color="speed", **options) -> Renderer:
    """A Renderer for these settings, reused from a small cache (decorations are built once)."""
    key = (tuple(float(v) for v in box), tuple(int(v) for v in size),
           color if isinstance(color, str) else repr(color), tuple(sorted((k, repr(v)) for k, v in options.items())))
    r = _CACHE.get(key)
    if r is None:
        r = Renderer(size, color, box, **options)
        _CACHE[key] = r
        while len(_CACHE) > 8:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return r


def frame_size(box, size=(1920, 1080), color="speed", **options) -> tuple[int, int]:
    """(width, height) of the images :func:`render_frame` makes for this box, request and options."""
    return get_renderer(box, size, color, **options).size


def render_frame(frame, size=(1920, 1080), color="speed", **options) -> np.ndarray:
    """Render one Frame to an RGB image, uint8, of shape (h, w, 3) with (w, h) = ``frame_size(frame.box, size)``
    (``size`` itself with ``fit=False``).

    color="speed": each segment in the colour of its speed, linear 0–16 µm/min (turbo colormap);
    color="strain": each segment in the colour of log10 of its strain energy, 1e-21–1e-17 J (zero: bottom colour);
    color="identity" / "polarity" / "orientation": each cell in the colour of its index / engine direction /
    axis angle mod 180°. options: see :class:`Renderer` (fit, vmin, vmax, background, decorations, colormap,
    outline, min_radius_px, title, t0_free_speed, free_speed)."""
    return get_renderer(frame.box, size, color, **options).render(frame)
