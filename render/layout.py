"""Layout of a rendered frame: where the box, the legend strip, the time, the scale bar and the title go for a
size and a box (:func:`compute_layout`), and the :class:`Viewport` from µm to pixels. See
:mod:`taichimyxo.render.raster` for the picture."""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .colors import make_scale

FONT_PX_AT_1080 = 28.0      # tick-label size at a 1080 px request (min(width, height)); other text is relative
MIN_FONT_PX = 14.0          # never smaller (unless the request is under 16·14 = 224 px high)
TIME_FONT = 1.25            # time text size / tick-label size
LONGEST_TIME = "t = 10 h 05 min"



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
class FrameLayout:
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


def glyph_width(font_px: float) -> int:
    return int(math.ceil(0.62 * font_px))


def legend_metrics(scale, f: float):
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
                   scale=None, title: str | None = None) -> FrameLayout:
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
        return FrameLayout(fsize, vp, g, None, None, 0.0, None, None, f, 0, "center", (W, H))

    scale = make_scale("speed") if scale is None else scale
    cb_min, ov_l, ov_r, leg_h, cb_h = legend_metrics(scale, f)
    gap_top = round(0.5 * f)
    time_w = len(LONGEST_TIME) * glyph_width(TIME_FONT * f)
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
        return FrameLayout((Wf, Hf), vp, g, colorbar, scalebar, sb_um, time_center, title_center, f, 1, "center",
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
    return FrameLayout((Wf, Hf), vp, g, colorbar, scalebar, sb_um, time_center, title_center, f, 2, "left", (W, H))
