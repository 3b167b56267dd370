"""Off-screen rasteriser: a Frame → an RGB image (numpy uint8, shape (H, W, 3)). No display, no GPU, no Taichi.

Picture (as the paper's Fig 2–4 and supplementary videos): the periodic box, fitted into the image keeping its
aspect ratio, on a white background (``background="black"`` for a dark one); every cell a capsule of diameter
``frame.width_um`` drawn along its particle chain, each SEGMENT in the colour of its own speed (linear 0–16 µm/min)
or strain energy (log10 1e-21–1e-17 J), see :mod:`taichimyxo.render.colors` for the scales (colormap ``turbo``,
a perceptually smoothed ``jet``). Below the box: the colour bar with ticks and a label with units, the simulated
time as ``t = h:mm h``, and a scale bar of a round length of about a quarter of the box width.

How a frame is drawn (all numpy, no per-segment Python loop):

1. Segments whose capsule crosses the box edge are also drawn shifted by ±Lx, ±Ly ("wrapped copies"), so a cell
   across the periodic edge appears on both sides; everything is clipped to the box.
2. Every segment's pixel bounding box is enumerated (ragged, batched with ``np.repeat``); for each candidate pixel
   centre the distance d to the segment (the capsule's axis) is computed.
3. A pixel belongs to the capsule whose axis is nearest (an order-independent, deterministic rule: one
   ``np.minimum.at`` on a 64-bit key ``(d quantised) << 32 | segment``). Its coverage is ``clip(r + ½ − d, 0, 1)``
   pixels (a one-pixel antialiasing ramp), blended with the background. Pixels well inside a capsule therefore hold
   exactly the colour-map colour of their segment.
4. The decorations (colour bar, labels, scale bar, box outline) are rendered once per (size, box, scale) with
   matplotlib's Agg backend and reused; the time is composed each frame from a pre-rendered monospace glyph atlas.

Coordinates: data in µm, origin at the lower left, y up. Image: pixel (row, col) covers the square
[col, col+1) × [row, row+1) of continuous image coordinates (u = column axis, v = row axis, v down). Use
:class:`Viewport` (``Renderer.viewport``) to go from µm to pixels.
"""
from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from .colors import make_scale

BACKGROUNDS = {
    "white": ((255, 255, 255), (0, 0, 0), (170, 170, 170)),   # background, text, box outline
    "black": ((0, 0, 0), (255, 255, 255), (90, 90, 90)),
}

_KEY_EMPTY = np.iinfo(np.int64).max
_D_QUANT = 1 << 16          # distance quantum in the per-pixel key: 1/65536 px
_CHUNK = 1 << 21            # candidate pixels per batch (bounds memory, keeps arrays in cache-friendly sizes)


# --------------------------------------------------------------------------------------------------- geometry

@dataclass(frozen=True)
class Viewport:
    """Where the periodic box lies in the image.

    ``scale`` px per µm; the box occupies columns ``col0 … col0+width−1`` and rows ``row0 … row0+height−1``;
    data x = 0 is at image u = col0 and data y = Ly at image v = row0 (y up, rows down)."""
    box: tuple[float, float]
    scale: float
    col0: int
    row0: int
    width: int
    height: int

    def to_image(self, xy) -> np.ndarray:
        """Continuous image coordinates (u, v) = (column, row axis) of data points xy (..., 2) µm."""
        xy = np.asarray(xy, dtype=np.float64)
        u = self.col0 + xy[..., 0] * self.scale
        v = self.row0 + (self.box[1] - xy[..., 1]) * self.scale
        return np.stack([u, v], axis=-1)

    def to_pixel(self, xy) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) integer indices of the pixels containing data points xy (..., 2) µm: ``img[row, col]``."""
        uv = self.to_image(xy)
        return np.floor(uv[..., 1]).astype(np.int64), np.floor(uv[..., 0]).astype(np.int64)

    def to_data(self, row, col) -> np.ndarray:
        """Data coordinates (µm) of the centres of pixels (row, col)."""
        row = np.asarray(row, dtype=np.float64)
        col = np.asarray(col, dtype=np.float64)
        x = (col + 0.5 - self.col0) / self.scale
        y = self.box[1] - (row + 0.5 - self.row0) / self.scale
        return np.stack([x, y], axis=-1)

    @property
    def slices(self) -> tuple[slice, slice]:
        """``img[viewport.slices]`` is the box region of the image."""
        return slice(self.row0, self.row0 + self.height), slice(self.col0, self.col0 + self.width)


@dataclass(frozen=True)
class Layout:
    """Pixel layout of a frame. Rectangles are half-open (row0, row1, col0, col1)."""
    size: tuple[int, int]                       # (width, height) px
    viewport: Viewport
    unit: float                                 # decoration scale: 1 at 1080 px (the smaller image side)
    colorbar: tuple[int, int, int, int] | None  # the gradient itself
    scalebar: tuple[int, int, int, int] | None  # the bar itself
    scalebar_um: float
    time_center: tuple[int, int] | None         # (row, col) of the centre of the time text
    title_center: tuple[int, int] | None        # (row, col) of the centre of the title (scene name), under the time
    font_px: float                              # tick label size, px


def nice_scalebar_length(box_width_um: float, fraction: float = 0.25) -> float:
    """Largest round length (1, 2, 2.5, 5 × 10^k µm) not longer than ``fraction`` of the box width."""
    target = box_width_um * fraction
    best = None
    for k in range(-3, 7):
        for m in (1.0, 2.0, 2.5, 5.0):
            v = m * 10.0 ** k
            if v <= target * (1 + 1e-9):
                best = v
    return float(best if best is not None else target)


def compute_layout(size: tuple[int, int], box: tuple[float, float], decorations: bool = True) -> Layout:
    """Fit the box into the image keeping its aspect ratio, leaving a strip at the bottom for the decorations."""
    W, H = int(size[0]), int(size[1])
    Lx, Ly = float(box[0]), float(box[1])
    if W < 16 or H < 16:
        raise ValueError(f"size={size!r}: the image must be at least 16 x 16 px")
    if not (Lx > 0 and Ly > 0):
        raise ValueError(f"box={box!r}: both sides must be > 0 µm")
    u = min(W, H) / 1080.0
    margin = max(2, round(16 * u))
    strip = round(104 * u) if decorations else 0
    avail_w, avail_h = W - 2 * margin, H - 2 * margin - strip
    s = min(avail_w / Lx, avail_h / Ly)
    bw, bh = max(1, int(math.floor(Lx * s + 1e-6))), max(1, int(math.floor(Ly * s + 1e-6)))
    col0 = (W - bw) // 2
    row0 = margin + (avail_h - bh) // 2
    vp = Viewport((Lx, Ly), s, col0, row0, bw, bh)
    if not decorations:
        return Layout((W, H), vp, u, None, None, 0.0, None, None, 18 * u)
    # the bottom strip spans at least the box, at least ~900 px (if the image is that wide), centred on the box
    sw = min(W - 2 * margin, max(bw, round(900 * u)))
    sx0 = max(margin, min(W - margin - sw, col0 + bw // 2 - sw // 2))
    top = row0 + bh + round(14 * u)
    cb_x0 = max(sx0, margin + round(36 * u))        # room for the first tick label (e.g. 10^-20) left of the bar
    cb_w, cb_h = round(0.40 * sw) - (cb_x0 - sx0), max(4, round(22 * u))
    colorbar = (top, top + cb_h, cb_x0, cb_x0 + cb_w)
    sb_um = nice_scalebar_length(Lx)
    sb_len = max(1, round(sb_um * s))
    sb_h = max(2, round(6 * u))
    sb_row = top + round(34 * u)
    scalebar = (sb_row, sb_row + sb_h, sx0 + sw - sb_len, sx0 + sw)
    time_center = (top + round(30 * u), sx0 + round(0.40 * sw) + (sw - round(0.40 * sw) - sb_len) // 2)
    title_center = (top + round(66 * u), time_center[1])
    return Layout((W, H), vp, u, colorbar, scalebar, sb_um, time_center, title_center, 18 * u)


# --------------------------------------------------------------------------------------------------- capsules

def periodic_copies(a: np.ndarray, b: np.ndarray, box, margin: float):
    """Segments (a → b, µm) and their shifted images whose capsule (reach ``margin``) meets the box [0,Lx]×[0,Ly].

    Returns (index into the original segments, a', b')."""
    Lx, Ly = float(box[0]), float(box[1])
    lo = np.minimum(a, b) - margin
    hi = np.maximum(a, b) + margin
    ok = np.isfinite(lo).all(axis=1) & np.isfinite(hi).all(axis=1)
    if not ok.any():
        return np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 2))
    sx_min = int(math.floor(-hi[ok, 0].max() / Lx)) + 1
    sx_max = int(math.ceil((Lx - lo[ok, 0].min()) / Lx)) - 1
    sy_min = int(math.floor(-hi[ok, 1].max() / Ly)) + 1
    sy_max = int(math.ceil((Ly - lo[ok, 1].min()) / Ly)) - 1
    idx, A, B = [], [], []
    for sx in range(sx_min, sx_max + 1):
        mx = ok & (lo[:, 0] + sx * Lx < Lx) & (hi[:, 0] + sx * Lx > 0)
        for sy in range(sy_min, sy_max + 1):
            m = mx & (lo[:, 1] + sy * Ly < Ly) & (hi[:, 1] + sy * Ly > 0)
            sel = np.flatnonzero(m)
            if len(sel):
                shift = np.array([sx * Lx, sy * Ly])
                idx.append(sel)
                A.append(a[sel] + shift)
                B.append(b[sel] + shift)
    if not idx:
        return np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 2))
    return np.concatenate(idx), np.concatenate(A), np.concatenate(B)


def draw_capsules(img: np.ndarray, a: np.ndarray, b: np.ndarray, colors: np.ndarray, radius: float,
                  background=None) -> None:
    """Draw capsules (segments a → b with round caps, radius px) into ``img`` (h, w, 3) uint8, in place.

    a, b: (n, 2) continuous image coordinates (u = column, v = row) relative to img's top-left corner.
    colors: (n, 3) uint8. A pixel takes the colour of the capsule whose axis is nearest to its centre (ties: the
    lower index), with coverage alpha = clip(radius + ½ − d, 0, 1) blended over ``background`` (RGB, default: the
    pixel's current value). Vectorised over segments and pixels."""
    h, w = img.shape[:2]
    n = len(a)
    if n == 0:
        return
    reach = float(radius) + 0.5
    lo = np.minimum(a, b) - reach
    hi = np.maximum(a, b) + reach
    x0 = np.clip(np.floor(lo[:, 0]), 0, w).astype(np.int64)
    x1 = np.clip(np.ceil(hi[:, 0]), 0, w).astype(np.int64)
    y0 = np.clip(np.floor(lo[:, 1]), 0, h).astype(np.int64)
    y1 = np.clip(np.ceil(hi[:, 1]), 0, h).astype(np.int64)
    bw, bh = x1 - x0, y1 - y0
    keep = np.flatnonzero((bw > 0) & (bh > 0))
    if len(keep) == 0:
        return
    a, b, colors = a[keep], b[keep], colors[keep]
    x0, y0, bw, bh = x0[keep], y0[keep], bw[keep], bh[keep]
    n = len(keep)
    # per-segment parameters, float32, relative to the centre of the bbox's first pixel
    ox = (x0 + 0.5 - a[:, 0]).astype(np.float32)
    oy = (y0 + 0.5 - a[:, 1]).astype(np.float32)
    dx = (b[:, 0] - a[:, 0]).astype(np.float32)
    dy = (b[:, 1] - a[:, 1]).astype(np.float32)
    inv = (1.0 / np.maximum(dx.astype(np.float64) ** 2 + dy.astype(np.float64) ** 2, 1e-12)).astype(np.float32)
    inv[(dx == 0) & (dy == 0)] = 0.0
    base = (y0 * w + x0).astype(np.int64)
    bw32 = bw.astype(np.int32)
    counts = bw * bh
    keybuf = np.full(h * w, _KEY_EMPTY, dtype=np.int64)
    reach2 = np.float32(reach * reach)
    # batches of whole segments with at most ~_CHUNK candidate pixels each
    csum = np.cumsum(counts)
    cuts = np.searchsorted(csum, np.arange(_CHUNK, csum[-1], _CHUNK), side="right")
    bounds = np.unique(np.concatenate([[0], cuts, [n]]))
    for s0, s1 in zip(bounds[:-1], bounds[1:]):
        cnt = counts[s0:s1]
        total = int(cnt.sum())
        if total == 0:
            continue
        seg = np.repeat(np.arange(s0, s1, dtype=np.int32), cnt)
        start = (np.cumsum(cnt) - cnt).astype(np.int32)
        local = np.arange(total, dtype=np.int32) - np.repeat(start, cnt)
        ly, lx = np.divmod(local, bw32[seg])
        px = ox[seg] + lx
        py = oy[seg] + ly
        sdx, sdy = dx[seg], dy[seg]
        t = (px * sdx + py * sdy) * inv[seg]
        np.clip(t, 0.0, 1.0, out=t)
        px -= t * sdx
        py -= t * sdy
        d2 = px * px + py * py
        hit = np.flatnonzero(d2 < reach2)
        if len(hit) == 0:
            continue
        sh = seg[hit]
        pix = base[sh] + ly[hit].astype(np.int64) * w + lx[hit]
        dq = (np.sqrt(d2[hit]) * _D_QUANT).astype(np.int64)
        np.minimum.at(keybuf, pix, (dq << 32) | sh.astype(np.int64))
    drawn = np.flatnonzero(keybuf != _KEY_EMPTY)
    if len(drawn) == 0:
        return
    key = keybuf[drawn]
    sid = (key & 0xFFFFFFFF).astype(np.int64)
    d = (key >> 32).astype(np.float32) / _D_QUANT
    alpha = np.clip(np.float32(reach) - d, 0.0, 1.0)
    rows, cols = np.divmod(drawn, w)
    col = colors[sid]
    full = alpha >= 1.0
    img[rows[full], cols[full]] = col[full]
    part = ~full
    if part.any():
        r_, c_ = rows[part], cols[part]
        bg = img[r_, c_].astype(np.float32) if background is None else np.asarray(background, np.float32)
        al = alpha[part, None]
        img[r_, c_] = (bg * (1.0 - al) + col[part].astype(np.float32) * al + 0.5).astype(np.uint8)


# --------------------------------------------------------------------------------------------------- text

class GlyphAtlas:
    """Monospace glyphs pre-rendered once (matplotlib Agg, DejaVu Sans Mono) as coverage masks, for per-frame text."""

    def __init__(self, chars: str, font_px: float):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.font_px = font_px
        cw = int(math.ceil(0.62 * font_px))
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

    def draw(self, img: np.ndarray, text: str, center: tuple[int, int], color) -> None:
        m = self.mask(text)
        h, w = m.shape
        r0, c0 = center[0] - h // 2, center[1] - w // 2
        r1, c1 = r0 + h, c0 + w
        R0, C0 = max(r0, 0), max(c0, 0)
        R1, C1 = min(r1, img.shape[0]), min(c1, img.shape[1])
        if R1 <= R0 or C1 <= C0:
            return
        m = m[R0 - r0:R1 - r0, C0 - c0:C1 - c0, None]
        region = img[R0:R1, C0:C1].astype(np.float32)
        img[R0:R1, C0:C1] = (region * (1.0 - m) + np.asarray(color, np.float32) * m + 0.5).astype(np.uint8)


def format_time(time_s: float) -> str:
    """Simulated time as ``t = h:mm h`` (whole minutes, floor; tolerant of float drift)."""
    minutes = int(math.floor(abs(time_s) / 60.0 + 1e-6))
    sign = "-" if time_s < 0 and minutes > 0 else ""
    return f"t = {sign}{minutes // 60}:{minutes % 60:02d} h"


# --------------------------------------------------------------------------------------------------- renderer

def _rgb(c) -> tuple[int, int, int]:
    return tuple(int(v) for v in c)


class Renderer:
    """Renders Frames of one box into images of one size with one colour scale; decorations are built once.

    Parameters
    ----------
    size: (width, height) px.
    color: ``"speed"`` (linear 0–``vmax`` µm/min, default 16) or ``"strain"`` (log10, ``strain_range`` J,
        default (1e-21, 1e-17)), or a :class:`ColorScale`.
    box: (Lx, Ly) µm of the periodic domain.
    background: ``"white"`` (the paper's look) or ``"black"``.
    decorations: draw colour bar, time and scale bar (False: the box only, fitted into the whole image).
    min_radius_px: capsules are never drawn thinner than this radius, so cells stay visible when zoomed out.
    title: optional short text (e.g. the scene name) shown under the time.
    """

    def __init__(self, size=(1920, 1080), color="speed", box=(200.0, 200.0), *, background="white",
                 decorations=True, colormap=None, vmax=None, strain_range=None, min_radius_px=0.6,
                 title: str | None = None):
        if background not in BACKGROUNDS:
            raise ValueError(f"background={background!r}: allowed are {sorted(BACKGROUNDS)}")
        self.size = (int(size[0]), int(size[1]))
        self.box = (float(box[0]), float(box[1]))
        self.scale = make_scale(color, colormap=colormap, vmax=vmax, strain_range=strain_range)
        self.bg, self.fg, self.outline = (np.array(c, np.uint8) for c in BACKGROUNDS[background])
        self.decorations = decorations
        self.min_radius_px = float(min_radius_px)
        self.title = None if title is None else str(title)
        self.layout = compute_layout(self.size, self.box, decorations)
        self.viewport = self.layout.viewport
        self.lut = self.scale.lut
        self.static = self._build_static()
        self.atlas = GlyphAtlas("0123456789:-t=h ", 30 * self.layout.unit) if decorations else None

    # ---- static decorations, rendered once
    def _build_static(self) -> np.ndarray:
        W, H = self.size
        lay, vp = self.layout, self.viewport
        if not self.decorations:
            img = np.empty((H, W, 3), np.uint8)
            img[:] = self.bg
            return img
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        dpi = 100.0
        pt = 72.0 / dpi                     # points per pixel
        u = lay.unit
        fg = tuple(self.fg / 255.0)
        fig = Figure(figsize=(W / dpi, H / dpi), dpi=dpi)
        canvas = FigureCanvasAgg(fig)
        fig.patch.set_facecolor(tuple(self.bg / 255.0))
        # colour bar axis: exactly over the gradient rectangle; ticks and label below it
        r0, r1, c0, c1 = lay.colorbar
        ax = fig.add_axes([c0 / W, 1 - r1 / H, (c1 - c0) / W, (r1 - r0) / H])
        ax.set_xlim(*self.scale.axis_limits())
        ax.set_ylim(0, 1)
        ax.set_yticks([])
        ax.set_xticks(self.scale.tick_axis_values(), list(self.scale.tick_labels))
        ax.tick_params(axis="x", direction="out", length=6 * u * pt, width=max(1.0, 1.2 * u) * pt, color=fg,
                       labelcolor=fg, labelsize=lay.font_px * pt, pad=3 * u * pt)
        ax.set_xlabel(self.scale.label, fontsize=20 * u * pt, color=fg, labelpad=4 * u * pt)
        for sp in ax.spines.values():
            sp.set_visible(False)
        ax.patch.set_visible(False)
        # scale bar label, above the bar
        s0, s1, q0, q1 = lay.scalebar
        fig.text((q0 + q1) / 2 / W, 1 - (s0 - 5 * u) / H, f"{lay.scalebar_um:g} µm", ha="center", va="bottom",
                 fontsize=20 * u * pt, color=fg)
        if self.title:
            tr, tc = lay.title_center
            fig.text(tc / W, 1 - tr / H, self.title, ha="center", va="center", fontsize=18 * u * pt, color=fg)
        canvas.draw()
        img = np.ascontiguousarray(np.asarray(canvas.buffer_rgba())[:, :, :3])
        # exact colours painted over: gradient (column j ↔ value at its centre), its frame, the scale bar, the box
        x = (np.arange(c1 - c0) + 0.5) / (c1 - c0)
        idx = np.minimum((x * len(self.lut)).astype(np.int64), len(self.lut) - 1)
        img[r0:r1, c0:c1] = self.lut[idx][None, :, :]
        _frame_rect(img, r0, r1, c0, c1, self.fg)
        img[s0:s1, q0:q1] = self.fg
        rs, cs = vp.slices
        _frame_rect(img, rs.start, rs.stop, cs.start, cs.stop, self.outline)
        img[rs, cs] = self.bg
        return img

    # ---- per frame
    def segment_colors(self, frame) -> np.ndarray:
        """(n_cells·(N−1), 3) uint8 colours of the segments, in the order of ``frame.positions[:, :-1]``."""
        if self.scale.name == "strain":
            if frame.segment_strain is None:
                raise ValueError("color='strain' but this frame has no strain energy (segment_strain is None); "
                                 "render with color='speed' or run the scene with strain output on")
            vals = frame.segment_strain
        else:
            vals = frame.segment_speed
        return self.lut[self.scale.index(np.asarray(vals).reshape(-1))]

    def render(self, frame, out: np.ndarray | None = None) -> np.ndarray:
        """The image (H, W, 3) uint8 of ``frame`` (written into ``out`` when given)."""
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
                draw_capsules(img[vp.slices], A, B, colors[idx], r_px, background=self.bg)
        if self.decorations:
            self.atlas.draw(img, format_time(frame.time_s), self.layout.time_center, self.fg)
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


def render_frame(frame, size=(1920, 1080), color="speed", **options) -> np.ndarray:
    """Render one Frame to an RGB image, shape (size[1], size[0], 3), uint8.

    color="speed": each segment in the colour of its speed, linear 0–16 µm/min (turbo colormap);
    color="strain": each segment in the colour of log10 of its strain energy, 1e-21–1e-17 J (zero: bottom colour).
    options: see :class:`Renderer` (background, decorations, colormap, vmax, strain_range, min_radius_px, title)."""
    return get_renderer(frame.box, size, color, **options).render(frame)
