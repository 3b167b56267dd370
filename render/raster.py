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

import functools
import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from .colors import SPEED_MAX_UM_PER_MIN, make_scale

BACKGROUNDS = {
    "white": ((255, 255, 255), (0, 0, 0), (170, 170, 170)),   # background, text, box outline
    "black": ((0, 0, 0), (255, 255, 255), (90, 90, 90)),
}
OUTLINE_RGB = (25, 25, 25)  # cell outlines

_KEY_EMPTY = np.iinfo(np.int64).max
_D_QUANT = 1 << 16          # distance quantum in the per-pixel key: 1/65536 px
_CHUNK = 1 << 21            # candidate pixels per batch (bounds memory, keeps arrays in cache-friendly sizes)

FONT_PX_AT_1080 = 28.0      # tick-label size at a 1080 px request (min(width, height)); other text is relative
MIN_FONT_PX = 14.0          # never smaller (unless the request is under 16·14 = 224 px high)
TIME_FONT = 1.25            # time text size / tick-label size
TIME_CHARS = "0123456789t=hmin -"
LONGEST_TIME = "t = 10 h 05 min"

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
    size: tuple[int, int]                       # (width, height) px of the frame (the fitted size when fit=True)
    viewport: Viewport
    unit: float                                 # decoration scale: font_px / 28 (1 at a 1080 px request)
    colorbar: tuple[int, int, int, int] | None  # the legend bar itself (gradient or colour swatches)
    scalebar: tuple[int, int, int, int] | None  # the bar itself
    scalebar_um: float
    time_center: tuple[int, int] | None         # (row, col) of the time text: its centre, or with time_align
    title_center: tuple[int, int] | None        # (row, col) of the centre of the title (scene name)
    font_px: float                              # tick label size, px (all legend text is this size; time 1.25x)
    rows: int = 1                               # legend strip: 1 (legend | time, scale bar, title) or 2 rows
    time_align: str = "center"                  # "center": time_center is the text's centre; "left": left middle
    request: tuple[int, int] | None = None      # the size asked for


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


@functools.lru_cache(maxsize=512)
def text_extent(text: str, px: float) -> tuple[float, float]:
    """(width, height) in px of ``text`` (matplotlib mathtext allowed) at font size ``px`` in DejaVu Sans."""
    if not text:
        return 0.0, 0.0
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    e = TextPath((0, 0), text, size=px, prop=FontProperties(family="DejaVu Sans")).get_extents()
    return float(e.width), float(e.height)


def font_size_px(size) -> float:
    """Tick-label font size for a requested (width, height): 28 px at 1080, ≥ 14 px unless the image is tiny."""
    W, H = int(size[0]), int(size[1])
    return max(FONT_PX_AT_1080 * min(W, H) / 1080.0, min(MIN_FONT_PX, H / 16.0))


def _glyph_width(font_px: float) -> int:
    return int(math.ceil(0.62 * font_px))


def _legend_metrics(scale, f: float):
    """(minimum bar width, left overhang, right overhang, block height) of the legend for tick font f px."""
    labels = list(scale.tick_labels)
    pos = np.asarray(scale.tick_positions(), float) if labels else np.zeros(0)
    widths = [text_extent(t, f)[0] for t in labels]
    heights = [text_extent(t, f)[1] for t in labels] or [0.0]
    lw = text_extent(scale.label, f)[0]
    need = max(6.0 * f, lw + 0.2 * f)              # the label fits under the bar
    for i in range(len(labels) - 1):
        gap = pos[i + 1] - pos[i]
        if gap > 1e-9:
            need = max(need, (0.5 * (widths[i] + widths[i + 1]) + 0.8 * f) / gap)
    ov_l = max([0.0] + [0.5 * w - p * need for w, p in zip(widths, pos)])
    ov_r = max([0.0] + [0.5 * w - (1.0 - p) * need for w, p in zip(widths, pos)])
    cb_h = max(3, round(0.8 * f))
    tick_block = (0.45 * f + max(heights) + 0.2 * f) if labels else 0.25 * f
    height = cb_h + tick_block + 0.25 * f + 1.3 * f
    return need, ov_l, ov_r, height, cb_h


def compute_layout(size: tuple[int, int], box: tuple[float, float], decorations: bool = True, *, fit: bool = True,
                   scale=None, title: str | None = None) -> Layout:
    """Place the box, legend, time, scale bar and title for a request of ``size`` (width, height) px.

    fit=True: the frame takes the box's aspect ratio within ``size`` (see the module docstring); fit=False: exactly
    ``size``. scale: the colour scale (for the legend's tick labels; default: speed)."""
    W, H = int(size[0]), int(size[1])
    Lx, Ly = float(box[0]), float(box[1])
    if W < 16 or H < 16:
        raise ValueError(f"size={size!r}: the image must be at least 16 x 16 px")
    if not (Lx > 0 and Ly > 0) or not (math.isfinite(Lx) and math.isfinite(Ly)):
        raise ValueError(f"box={box!r}: both sides must be > 0 µm")
    f = font_size_px((W, H))
    g = f / FONT_PX_AT_1080
    margin = max(2, round(16 * g))

    def place(strip_h):
        avail_w, avail_h = W - 2 * margin, H - 2 * margin - strip_h
        s = max(min(avail_w / Lx, avail_h / Ly), 1e-9)
        bw = max(1, int(math.floor(Lx * s + 1e-6)))
        bh = max(1, int(math.floor(Ly * s + 1e-6)))
        return s, bw, bh

    def finish(s, bw, bh, strip_h, min_w):
        if fit:
            Wf = min(W, max(bw + 2 * margin, int(math.ceil(min_w))))
            Hf = bh + 2 * margin + strip_h
            Wf, Hf = max(16, Wf + (Wf & 1)), max(16, Hf + (Hf & 1))
        else:
            Wf, Hf = W, H
        col0 = (Wf - bw) // 2
        row0 = margin + max(0, (Hf - 2 * margin - strip_h - bh) // 2)
        return (Wf, Hf), Viewport((Lx, Ly), s, col0, row0, bw, bh)

    if not decorations:
        s, bw, bh = place(0)
        fsize, vp = finish(s, bw, bh, 0, 0)
        return Layout(fsize, vp, g, None, None, 0.0, None, None, f, 0, "center", (W, H))

    scale = make_scale("speed") if scale is None else scale
    cb_min, ov_l, ov_r, leg_h, cb_h = _legend_metrics(scale, f)
    gap_top = round(0.5 * f)
    time_w = len(LONGEST_TIME) * _glyph_width(TIME_FONT * f)
    time_h = 1.25 * TIME_FONT * f
    sb_um = nice_scalebar_length(Lx)
    sb_label = f"{sb_um:g} µm"
    sb_label_w = text_extent(sb_label, f)[0]
    title_w = text_extent(title, f)[0] if title else 0.0
    sb_h = max(2, round(0.22 * f))
    gap = 1.5 * f

    # one row: legend on the left; time, scale bar (label above it) and title stacked on the right
    sb_row_off = time_h + 0.2 * f + 1.3 * f            # scale bar top, from the strip top
    right_h = sb_row_off + sb_h + 0.3 * f + 1.3 * f    # room for a title, given or not: same frame either way
    strip1 = gap_top + int(math.ceil(max(leg_h, right_h)))
    # the right block's width, scale bar excluded (its length scales with the box)
    right_text_w = max(time_w, sb_label_w, title_w)
    s, bw, bh = place(strip1)
    sb_len = max(1, round(sb_um * s))
    right_w = max(right_text_w, sb_len)
    need1 = ov_l + cb_min + ov_r + gap + right_w
    (Wf, Hf), vp = finish(s, bw, bh, strip1, need1 + 2 * margin)
    if need1 <= Wf - 2 * margin + 1e-6:
        sw = min(Wf - 2 * margin, max(bw, int(math.ceil(need1)), round(900 * g)))
        sx0 = max(margin, min(Wf - margin - sw, vp.col0 + bw // 2 - sw // 2))
        top = vp.row0 + bh + gap_top
        cb_w = int(min(sw - ov_l - ov_r - gap - right_w, max(cb_min, min(0.45 * sw, 20 * f))))
        cb_x0 = sx0 + int(math.ceil(ov_l))
        colorbar = (top, top + cb_h, cb_x0, cb_x0 + cb_w)
        rc = sx0 + sw - int(right_w) // 2                  # centre column of the right block
        sb_row = top + round(sb_row_off)
        scalebar = (sb_row, sb_row + sb_h, rc - sb_len // 2, rc - sb_len // 2 + sb_len)
        time_center = (top + round(0.5 * time_h), rc)
        title_center = (round(sb_row + sb_h + 0.3 * f + 0.65 * f), rc) if title else None
        return Layout((Wf, Hf), vp, g, colorbar, scalebar, sb_um, time_center, title_center, f, 1, "center",
                      (W, H))

    # two rows: the legend across the strip; under it the time (left), title (middle), scale bar (right)
    row2_h = max(time_h, 1.3 * f + 0.2 * f + sb_h)

    def title_fits(width, sb_len):
        return bool(title) and time_w + title_w + max(sb_len, sb_label_w) + 2 * f <= width - 2 * margin

    title_between = title_fits(Wf, sb_len)
    for _ in range(2):
        extra = 0 if (not title or title_between) else 1.5 * f     # a third row for a title that doesn't fit
        strip2 = gap_top + int(math.ceil(leg_h + 0.3 * f + row2_h + extra))
        s, bw, bh = place(strip2)
        sb_len = max(1, round(sb_um * s))
        need2 = max(ov_l + cb_min + ov_r, time_w + gap + max(sb_len, sb_label_w))
        (Wf, Hf), vp = finish(s, bw, bh, strip2, need2 + 2 * margin)
        if not title_between or title_fits(Wf, sb_len):
            break
        title_between = False
    sw = Wf - 2 * margin
    sx0 = margin
    top = vp.row0 + bh + gap_top
    cb_w = int(max(1, min(sw - ov_l - ov_r, max(cb_min, min(0.8 * sw, 20 * f)))))
    cb_x0 = sx0 + int(round(ov_l + (sw - ov_l - ov_r - cb_w) / 2))
    colorbar = (top, top + cb_h, cb_x0, cb_x0 + cb_w)
    r2 = top + round(leg_h + 0.3 * f)
    time_center = (r2 + round(0.5 * time_h), sx0)
    sb_row = r2 + round(1.5 * f)
    sb_c = sx0 + sw - round(max(sb_len, sb_label_w) / 2)
    scalebar = (sb_row, sb_row + sb_h, sb_c - sb_len // 2, sb_c - sb_len // 2 + sb_len)
    title_center = None
    if title:
        if title_between:
            title_center = (r2 + round(0.5 * time_h), sx0 + (time_w + sw - max(sb_len, sb_label_w)) // 2)
        else:
            title_center = (r2 + round(row2_h + 0.3 * f + 0.65 * f), sx0 + sw // 2)
    return Layout((Wf, Hf), vp, g, colorbar, scalebar, sb_um, time_center, title_center, f, 2, "left", (W, H))

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




def auto_outline(radius_px: float) -> tuple[float, float]:
    """(outline width px, strength 0..1 of the line between touching cells) for capsules of this radius.

    About a fifth of the radius, between 0.35 and 1.2 px: at 1080 px a 200 µm box draws 0.5 µm wide cells
    ~2.6 px wide, where a full 1 px dark rim would hide the colour; those get a faint rim and a half-dark line
    between touching cells; a 60 µm box (~9 px wide cells) gets a 1 px rim and a full dark line."""
    r = float(radius_px)
    if r < 0.9:
        return 0.0, 0.35
    return float(np.clip(0.2 * r, 0.35, 1.2)), float(np.clip((r - 0.5) / 2.0, 0.5, 1.0))


def draw_capsules(img: np.ndarray, a: np.ndarray, b: np.ndarray, colors: np.ndarray, radius: float,
                  background=None, groups: np.ndarray | None = None, outline_px: float = 0.0,
                  boundary: float = 1.0, outline_rgb=OUTLINE_RGB) -> None:
    """Draw capsules (segments a → b with round caps, radius px) into ``img`` (h, w, 3) uint8, in place.

    a, b: (n, 2) continuous image coordinates (u = column, v = row) relative to img's top-left corner.
    colors: (n, 3) uint8. A pixel takes the colour of the capsule whose axis is nearest to its centre (ties: the
    lower index), with coverage alpha = clip(radius + ½ − d, 0, 1) blended over ``background`` (RGB, default: the
    pixel's current value). Vectorised over segments and pixels.

    Outlines: the outer ``outline_px`` of each capsule blends into ``outline_rgb``; with ``groups`` (n,) (the cell
    of each capsule), of two neighbouring pixels (4-neighbourhood) of different groups the one farther from its own
    axis is blended into ``outline_rgb`` with weight ``boundary`` (a one-pixel line between touching cells; capsules
    of one group, e.g. the segments of one cell, join without a line)."""
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
    if groups is not None:
        groups = np.asarray(groups)[keep]
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
    o = None
    if outline_px > 0:
        o = np.clip(d - np.float32(radius - outline_px - 0.5), 0.0, 1.0)
    if groups is not None and boundary > 0:
        gimg = np.full(h * w, -1, np.int64)
        gimg[drawn] = groups[sid]
        gimg = gimg.reshape(h, w)
        dimg = np.zeros(h * w, np.float32)
        dimg[drawn] = d
        dimg = dimg.reshape(h, w)
        mark = np.zeros((h, w), bool)
        for ax in (0, 1):
            p, q = (slice(None, -1), slice(1, None))
            sp = (p, slice(None)) if ax == 0 else (slice(None), p)
            sq = (q, slice(None)) if ax == 0 else (slice(None), q)
            gp, gq = gimg[sp], gimg[sq]
            edge = (gp != gq) & (gp >= 0) & (gq >= 0)
            if edge.any():
                p_far = dimg[sp] >= dimg[sq]
                mark[sp] |= edge & p_far
                mark[sq] |= edge & ~p_far
        m = mark.reshape(-1)[drawn]
        if m.any():
            ob = np.where(m, np.float32(boundary), np.float32(0.0))
            o = ob if o is None else np.maximum(o, ob)
    if o is None:
        full = alpha >= 1.0
        img[rows[full], cols[full]] = col[full]
        part = ~full
        if not part.any():
            return
        rows, cols, col, alpha = rows[part], cols[part], col[part], alpha[part]
        c = col.astype(np.float32)
    else:
        c = col.astype(np.float32) * (1.0 - o[:, None]) + np.asarray(outline_rgb, np.float32) * o[:, None]
    bg = img[rows, cols].astype(np.float32) if background is None else np.asarray(background, np.float32)
    al = alpha[:, None]
    img[rows, cols] = (bg * (1.0 - al) + c * al + 0.5).astype(np.uint8)


# --------------------------------------------------------------------------------------------------- text

class GlyphAtlas:
    """Monospace glyphs pre-rendered once (matplotlib Agg, DejaVu Sans Mono) as coverage masks, for per-frame text."""

    def __init__(self, chars: str, font_px: float):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.font_px = font_px
        cw = _glyph_width(font_px)
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
