"""Colour scales of the movies and figure panels.

Five colourings (``color=``), see docs/model.md, "What is measured and shown", for the measured quantities:

- ``speed``: segment speed in µm/min, **linear** scale, by default from 0 to 16 µm/min (4 v_b, the predicted
  maximum edge speed of an actively guided aggregate); ``vmin``/``vmax`` set other ends. Values outside are clipped
  to the end colours. The first frame (t = 0) has no measured speed yet (the displayed speed is a displacement
  over a window that ends at the frame): the renderer shows it at the cells' free speed v_b instead, see
  :class:`taichimyxo.render.raster.Renderer` (``t0_free_speed``).
- ``strain``: segment strain energy in J, **logarithmic** scale, log10(E) from 1e-21 J to 1e-17 J by default
  (``vmin``/``vmax`` in J, or ``strain_range``). A contact of a cell pushed by its own engine (overlap
  F_e/k_c = 0.01 µm at k_c = 0.01 N/m) stores ½ k_c δ² = 5e-19 J, half on each of the two segments: 2.5e-19 J, in
  the upper half of the bar (a 0.1 h S3 preview gave a median of 1e-21 J over overlapping segments and a maximum
  of 3e-19 J). Yellow to red are left for the many-cell pushing of aggregate cores (overlaps 0.03–0.06 µm:
  2e-18–1e-17 J per segment). Segments with zero strain (no overlap), or strain below the lower end, are shown in
  the bottom colour; above the upper end, in the top colour.
- ``identity``: one stable categorical colour per cell (cell index i → a fixed colour, the same in every frame and
  every run): hues stepped by the golden angle, three lightness levels, so that cells with nearby indices differ.
- ``polarity``: the cell's engine direction (``Frame.engine_direction``): +1 (the head is particle 0) blue, −1 (the
  head is particle N−1) orange (Okabe–Ito colours, safe for colour-blind viewers). A reversal flips the colour.
- ``orientation``: the angle of the cell's axis (tail pole → head pole, taken modulo 180°: nematic, head and tail
  not distinguished) in degrees from the +x axis, counter-clockwise, on a **cyclic** colour map (0° and 180° have
  the same colour): a hue circle of constant lightness and chroma in CIE L*C*h (L* = 62, C* = 48), so no
  direction looks brighter than another. The whole cell has one colour.

Continuous colour map for speed and strain: matplotlib's ``turbo`` (Google's perceptually smoothed replacement of
MATLAB's ``jet``, the kind of rainbow scale of the paper's figures: dark blue → cyan → green → yellow → red). It is
sampled as a 256-entry uint8 lookup table, indexed exactly as matplotlib indexes a float in [0, 1]
(``floor(x * 256)``, 1.0 → 255), so ``ColorScale.rgb(v)`` equals ``matplotlib.colormaps["turbo"](x, bytes=True)[:3]``
with ``x`` the normalised value.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

N_COLORS = 256
DEFAULT_COLORMAP = "turbo"
CYCLIC_COLORMAP = "cyclic"              # the built-in L*C*h hue circle (not a matplotlib name)
SPEED_MAX_UM_PER_MIN = 16.0            # 4 v_b
STRAIN_RANGE_J = (1e-21, 1e-17)         # log10 scale ends
COLORINGS = ("speed", "strain", "identity", "polarity", "orientation")
POLARITY_RGB = {1: (0, 114, 178), -1: (230, 159, 0)}      # Okabe–Ito blue / orange
IDENTITY_LEGEND_SWATCHES = 12


# --------------------------------------------------------------------------------------------------- colours

def _lch_to_linear_rgb(L, C, h_rad) -> np.ndarray:
    a, b = C * np.cos(h_rad), C * np.sin(h_rad)
    fy = (L + 16.0) / 116.0
    fx, fz = fy + a / 500.0, fy - b / 200.0
    d = 6.0 / 29.0

    def finv(t):
        return np.where(t > d, t ** 3, 3 * d * d * (t - 4.0 / 29.0))

    xyz = np.stack([0.95047 * finv(fx), 1.0 * finv(fy), 1.08883 * finv(fz)], axis=-1)
    m = np.array([[3.2404542, -1.5371385, -0.4985314],
                  [-0.9692660, 1.8760108, 0.0415560],
                  [0.0556434, -0.2040259, 1.0572252]])
    return xyz @ m.T


def lch_to_srgb(L, C, h_deg) -> np.ndarray:
    """CIE L*C*h(ab) (D65) → sRGB uint8, shape (..., 3); arrays broadcast. Colours outside the sRGB gamut keep
    their lightness and hue and lose chroma (the largest chroma ≤ C that fits)."""
    L, C, h = np.broadcast_arrays(np.asarray(L, float), np.asarray(C, float), np.radians(np.asarray(h_deg, float)))
    L, h = np.clip(L, 0.0, 100.0), h.copy()

    def inside(c):
        lin = _lch_to_linear_rgb(L, c, h)
        return np.all((lin >= -1e-6) & (lin <= 1.0 + 1e-6), axis=-1)

    ok = inside(C)
    c_eff = C.copy()
    if not ok.all():
        lo, hi = np.zeros_like(C), C.copy()
        for _ in range(30):                     # bisection on the chroma of the out-of-gamut colours
            mid = 0.5 * (lo + hi)
            good = inside(mid)
            lo, hi = np.where(good, mid, lo), np.where(good, hi, mid)
        c_eff = np.where(ok, C, lo)
    lin = np.clip(_lch_to_linear_rgb(L, c_eff, h), 0.0, 1.0)
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    return np.clip(np.round(srgb * 255.0), 0, 255).astype(np.uint8)


def cyclic_lut(n: int = N_COLORS) -> np.ndarray:
    """(n, 3) uint8 hue circle at constant L* = 62, C* = 48: entry k has hue 360°·k/n (entry n would be entry 0)."""
    return np.ascontiguousarray(lch_to_srgb(62.0, 48.0, 360.0 * np.arange(n) / n + 30.0))


def colormap_lut(name: str = DEFAULT_COLORMAP) -> np.ndarray:
    """(256, 3) uint8 RGB lookup table of a matplotlib colormap, as ``cmap(x, bytes=True)`` would give
    (``"cyclic"``: the built-in hue circle of :func:`cyclic_lut`)."""
    if name == CYCLIC_COLORMAP:
        return cyclic_lut(N_COLORS)
    import matplotlib

    try:
        cmap = matplotlib.colormaps[name].resampled(N_COLORS)
    except KeyError:
        raise ValueError(f"colormap={name!r} is not a matplotlib colormap name") from None
    return np.ascontiguousarray(cmap(np.arange(N_COLORS), bytes=True)[:, :3])


def identity_colors(cell_index) -> np.ndarray:
    """Stable categorical colour (uint8 RGB, shape (..., 3)) of cells by index: hue 137.5°·i (the golden angle),
    lightness cycling over 52 / 66 / 78, chroma 55. The same index always gets the same colour."""
    i = np.asarray(cell_index, dtype=np.int64)
    hue = np.mod(i * 137.50776405003785 + 20.0, 360.0)
    L = np.array([52.0, 66.0, 78.0])[np.mod(i, 3)]
    return lch_to_srgb(L, 55.0, hue)


# --------------------------------------------------------------------------------------------------- scales

@dataclass(frozen=True)
class ColorScale:
    """Maps a per-segment quantity to a colour index 0..255 (and RGB through ``lut``).

    ``log``: False → x = (v − vmin)/(vmax − vmin); True → x = (log10 v − log10 vmin)/(log10 vmax − log10 vmin), with
    v ≤ 0 mapped to x = 0. x is clipped to [0, 1]; NaN is treated as 0. ``cyclic``: x = ((v − vmin) mod (vmax −
    vmin)) / (vmax − vmin), never clipped, and the colour bar's ends have the same colour."""
    name: str                      # "speed", "strain" or "orientation"
    label: str                     # colour bar label, with units (matplotlib mathtext)
    vmin: float
    vmax: float
    log: bool
    ticks: tuple[float, ...]        # tick values in data units
    tick_labels: tuple[str, ...]
    colormap: str = DEFAULT_COLORMAP
    cyclic: bool = False
    categorical = False

    @property
    def lut(self) -> np.ndarray:
        return _lut_cached(self.colormap)

    def normalise(self, values) -> np.ndarray:
        v = np.asarray(values, dtype=np.float64)
        if self.log:
            lo, hi = np.log10(self.vmin), np.log10(self.vmax)
            with np.errstate(divide="ignore", invalid="ignore"):
                x = (np.log10(np.where(v > 0, v, self.vmin)) - lo) / (hi - lo)
        elif self.cyclic:
            x = np.mod(v - self.vmin, self.vmax - self.vmin) / (self.vmax - self.vmin)
            x = np.where(x >= 1.0, 0.0, x)
        else:
            x = (v - self.vmin) / (self.vmax - self.vmin)
        x = np.nan_to_num(x, nan=0.0, posinf=1.0, neginf=0.0)
        return np.clip(x, 0.0, 1.0)

    def index(self, values) -> np.ndarray:
        """Colour index (uint8) of each value: floor(x·256) clipped to 255, matplotlib's rule."""
        x = self.normalise(values)
        return np.minimum((x * N_COLORS).astype(np.int64), N_COLORS - 1).astype(np.uint8)

    def rgb(self, values) -> np.ndarray:
        """uint8 RGB of each value, shape values.shape + (3,)."""
        return self.lut[self.index(values)]

    def bar_rgb(self, x) -> np.ndarray:
        """Colour bar colours at normalised positions x ∈ [0, 1) along the bar."""
        idx = np.minimum((np.asarray(x, float) * N_COLORS).astype(np.int64), N_COLORS - 1)
        return self.lut[np.clip(idx, 0, N_COLORS - 1)]

    def tick_positions(self) -> np.ndarray:
        """Positions of the ticks along the colour bar, normalised to [0, 1]."""
        lo, hi = self.axis_limits()
        return (self.tick_axis_values() - lo) / (hi - lo)

    def axis_value(self, x: np.ndarray) -> np.ndarray:
        """Position along the colour bar axis (data units, log10 for log scales) of normalised x."""
        lo, hi = self.axis_limits()
        return lo + np.asarray(x) * (hi - lo)

    def tick_axis_values(self) -> np.ndarray:
        t = np.asarray(self.ticks, dtype=np.float64)
        return np.log10(t) if self.log else t

    def axis_limits(self) -> tuple[float, float]:
        if self.log:
            return float(np.log10(self.vmin)), float(np.log10(self.vmax))
        return float(self.vmin), float(self.vmax)


@dataclass(frozen=True)
class CategoricalScale:
    """A colour per cell, not a quantity: ``identity`` (colour of the cell index) or ``polarity`` (colour of the
    engine direction). The legend is a bar of ``swatches`` (equal blocks) with ``tick_labels`` under their centres
    (empty for identity) and ``label`` underneath."""
    name: str
    label: str
    swatches: tuple[tuple[int, int, int], ...]
    tick_labels: tuple[str, ...]
    categorical = True
    log = False
    cyclic = False

    def cell_colors(self, frame) -> np.ndarray:
        """(n_cells, 3) uint8 colour of each cell of ``frame``."""
        if self.name == "identity":
            return identity_colors(np.arange(frame.n_cells))
        ke = np.asarray(frame.engine_direction).reshape(-1)
        out = np.empty((len(ke), 3), np.uint8)
        out[:] = POLARITY_RGB[1]
        out[ke < 0] = POLARITY_RGB[-1]
        return out

    def bar_rgb(self, x) -> np.ndarray:
        k = len(self.swatches)
        idx = np.clip((np.asarray(x, float) * k).astype(np.int64), 0, k - 1)
        return np.asarray(self.swatches, np.uint8)[idx]

    def tick_positions(self) -> np.ndarray:
        if not self.tick_labels:
            return np.zeros(0)
        k = len(self.swatches)
        return (np.arange(k) + 0.5) / k


_LUTS: dict[str, np.ndarray] = {}


def _lut_cached(name: str) -> np.ndarray:
    if name not in _LUTS:
        _LUTS[name] = colormap_lut(name)
    return _LUTS[name]


def _fmt(v: float) -> str:
    s = f"{v:.3g}"
    return "−" + s[1:] if s.startswith("-") else s


def speed_scale(vmax: float = SPEED_MAX_UM_PER_MIN, colormap: str = DEFAULT_COLORMAP,
                vmin: float = 0.0) -> ColorScale:
    """Linear vmin..vmax µm/min (default 0..16 = 4 v_b), five evenly spaced ticks (0, 4, 8, 12, 16 by default)."""
    vmin, vmax = float(vmin), float(vmax)
    if not np.isfinite(vmin) or not np.isfinite(vmax) or not vmax > vmin:
        raise ValueError(f"speed colour scale: vmin={vmin!r}, vmax={vmax!r} µm/min must satisfy vmin < vmax")
    if vmin == 0.0 and not vmax > 0:
        raise ValueError(f"speed colour scale: vmax={vmax!r} must be > 0 µm/min")
    ticks = tuple(float(t) for t in np.linspace(vmin, vmax, 5))
    labels = tuple(_fmt(t) for t in ticks)
    return ColorScale("speed", "speed, µm·min⁻¹", vmin, vmax, False, ticks, labels, colormap)


def strain_scale(range_J: tuple[float, float] = STRAIN_RANGE_J, colormap: str = DEFAULT_COLORMAP) -> ColorScale:
    """Logarithmic range_J[0]..range_J[1] J (default 1e-21..1e-17), a tick at each power of ten (at the ends when
    the range holds fewer than two powers of ten)."""
    lo, hi = (float(range_J[0]), float(range_J[1]))
    if not (0 < lo < hi) or not np.isfinite(hi):
        raise ValueError(f"strain colour scale: range {range_J!r} J must satisfy 0 < vmin < vmax")
    exps = np.arange(np.ceil(np.log10(lo) - 1e-9), np.floor(np.log10(hi) + 1e-9) + 1).astype(int)
    if len(exps) >= 2:
        ticks = tuple(float(10.0 ** e) for e in exps)
        labels = tuple(f"$10^{{{e}}}$" for e in exps)
    else:
        ticks = (lo, hi)
        labels = tuple(_sci(v) for v in ticks)
    return ColorScale("strain", "strain energy, J", lo, hi, True, ticks, labels, colormap)


def _sci(v: float) -> str:
    m, e = f"{v:.1e}".split("e")
    return f"${m}\\times10^{{{int(e)}}}$"


def orientation_scale(colormap: str = CYCLIC_COLORMAP) -> ColorScale:
    """Cell axis angle modulo 180°, 0..180°, cyclic; ticks every 45°."""
    ticks = (0.0, 45.0, 90.0, 135.0, 180.0)
    return ColorScale("orientation", "cell axis angle (mod 180°), °", 0.0, 180.0, False, ticks,
                      tuple(f"{t:g}" for t in ticks), colormap, cyclic=True)


def identity_scale() -> CategoricalScale:
    sw = tuple(tuple(int(c) for c in rgb) for rgb in identity_colors(np.arange(IDENTITY_LEGEND_SWATCHES)))
    return CategoricalScale("identity", "cell identity", sw, ())


def polarity_scale() -> CategoricalScale:
    return CategoricalScale("polarity", "polarity: engine direction", (POLARITY_RGB[1], POLARITY_RGB[-1]),
                            ("+1", "−1"))


def make_scale(color, *, vmin=None, vmax=None, strain_range=None, colormap=None):
    """The scale of ``color``: one of :data:`COLORINGS` or a ready ColorScale / CategoricalScale.

    vmin, vmax: ends of the range, in the quantity's units (speed µm/min, strain J); None = default. Only speed and
    strain have a settable range. strain_range: (vmin, vmax) J, the older spelling. colormap: a matplotlib
    colormap name for speed / strain / orientation (default turbo; orientation: the built-in cyclic map)."""
    if isinstance(color, (ColorScale, CategoricalScale)):
        return color
    if color not in COLORINGS:
        raise ValueError(f"color={color!r}: allowed are {', '.join(COLORINGS)} (speed µm/min linear 0–16, strain J "
                         f"log scale, identity, polarity, orientation)")
    if color not in ("speed", "strain") and (vmin is not None or vmax is not None):
        raise ValueError(f"color={color!r} has no settable range: vmin/vmax apply to speed and strain only")
    if color == "speed":
        return speed_scale(SPEED_MAX_UM_PER_MIN if vmax is None else vmax, colormap or DEFAULT_COLORMAP,
                           0.0 if vmin is None else vmin)
    if color == "strain":
        lo, hi = strain_range or STRAIN_RANGE_J
        return strain_scale((lo if vmin is None else vmin, hi if vmax is None else vmax),
                            colormap or DEFAULT_COLORMAP)
    if color == "orientation":
        return orientation_scale(colormap or CYCLIC_COLORMAP)
    if color == "identity":
        return identity_scale()
    return polarity_scale()
