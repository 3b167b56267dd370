"""Colour scales of the movies and figure panels.

Two quantities can colour the cells, segment by segment (MODEL.md, "What is measured and shown"):

- ``speed``: segment speed in µm/min, **linear** scale from 0 to 16 µm/min (4 v_b, the predicted maximum edge
  speed of an actively guided aggregate). Values outside are clipped to the end colours.
- ``strain``: segment strain energy in J, **logarithmic** scale, log10(E) from 1e-21 J to 1e-17 J by default.
  A contact of a cell pushed by its own engine (overlap F_e/k_c = 0.01 µm at k_c = 0.01 N/m) stores
  ½ k_c δ² = 5e-19 J, half on each of the two segments: 2.5e-19 J, in the upper half of the bar (a 0.1 h S3 preview
  gave a median of 1e-21 J over overlapping segments and a maximum of 3e-19 J). Yellow to red are left for the
  many-cell pushing of aggregate cores (overlaps 0.03–0.06 µm: 2e-18–1e-17 J per segment). Segments with zero
  strain (no overlap), or strain below the lower end, are shown in the bottom colour; above the upper end, in the
  top colour.

The colormap is matplotlib's ``turbo`` (Google's perceptually smoothed replacement of MATLAB's ``jet``, the kind
of rainbow scale of the paper's figures: dark blue → cyan → green → yellow → red). It is sampled as a 256-entry
uint8 lookup table, indexed exactly as matplotlib indexes a float in [0, 1] (``floor(x * 256)``, 1.0 → 255), so
``ColorScale.rgb(v)`` equals ``matplotlib.colormaps["turbo"](x, bytes=True)[:3]`` with ``x`` the normalised value.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

N_COLORS = 256
DEFAULT_COLORMAP = "turbo"
SPEED_MAX_UM_PER_MIN = 16.0            # 4 v_b
STRAIN_RANGE_J = (1e-21, 1e-17)         # log10 scale ends


def colormap_lut(name: str = DEFAULT_COLORMAP) -> np.ndarray:
    """(256, 3) uint8 RGB lookup table of a matplotlib colormap, as ``cmap(x, bytes=True)`` would give."""
    import matplotlib

    cmap = matplotlib.colormaps[name].resampled(N_COLORS)
    return np.ascontiguousarray(cmap(np.arange(N_COLORS), bytes=True)[:, :3])


@dataclass(frozen=True)
class ColorScale:
    """Maps a per-segment quantity to a colour index 0..255 (and RGB through ``lut``).

    ``log``: False → x = (v − vmin)/(vmax − vmin); True → x = (log10 v − log10 vmin)/(log10 vmax − log10 vmin), with
    v ≤ 0 mapped to x = 0. x is clipped to [0, 1]; NaN is treated as 0."""
    name: str                      # "speed" or "strain"
    label: str                     # colour bar label, with units (matplotlib mathtext)
    vmin: float
    vmax: float
    log: bool
    ticks: tuple[float, ...]        # tick values in data units
    tick_labels: tuple[str, ...]
    colormap: str = DEFAULT_COLORMAP

    @property
    def lut(self) -> np.ndarray:
        return _lut_cached(self.colormap)

    def normalise(self, values) -> np.ndarray:
        v = np.asarray(values, dtype=np.float64)
        if self.log:
            lo, hi = np.log10(self.vmin), np.log10(self.vmax)
            with np.errstate(divide="ignore", invalid="ignore"):
                x = (np.log10(np.where(v > 0, v, self.vmin)) - lo) / (hi - lo)
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

    def axis_value(self, x: np.ndarray) -> np.ndarray:
        """Position along the colour bar axis (data units, log10 for log scales) of normalised x."""
        if self.log:
            lo, hi = np.log10(self.vmin), np.log10(self.vmax)
            return lo + x * (hi - lo)
        return self.vmin + x * (self.vmax - self.vmin)

    def tick_axis_values(self) -> np.ndarray:
        t = np.asarray(self.ticks, dtype=np.float64)
        return np.log10(t) if self.log else t

    def axis_limits(self) -> tuple[float, float]:
        if self.log:
            return float(np.log10(self.vmin)), float(np.log10(self.vmax))
        return float(self.vmin), float(self.vmax)


_LUTS: dict[str, np.ndarray] = {}


def _lut_cached(name: str) -> np.ndarray:
    if name not in _LUTS:
        _LUTS[name] = colormap_lut(name)
    return _LUTS[name]


def speed_scale(vmax: float = SPEED_MAX_UM_PER_MIN, colormap: str = DEFAULT_COLORMAP) -> ColorScale:
    """Linear 0..vmax µm/min (default 16 = 4 v_b), five ticks (0, 4, 8, 12, 16 by default)."""
    if not vmax > 0:
        raise ValueError(f"speed colour scale: vmax={vmax!r} must be > 0 µm/min")
    ticks = tuple(float(t) for t in np.linspace(0.0, vmax, 5))
    labels = tuple(f"{t:g}" for t in ticks)
    return ColorScale("speed", "speed, µm·min⁻¹", 0.0, float(vmax), False, ticks, labels, colormap)


def strain_scale(range_J: tuple[float, float] = STRAIN_RANGE_J, colormap: str = DEFAULT_COLORMAP) -> ColorScale:
    """Logarithmic range_J[0]..range_J[1] J (default 1e-21..1e-17), a tick at each power of ten."""
    lo, hi = (float(range_J[0]), float(range_J[1]))
    if not (0 < lo < hi):
        raise ValueError(f"strain colour scale: range_J={range_J!r} must satisfy 0 < low < high (J)")
    exps = np.arange(np.ceil(np.log10(lo) - 1e-9), np.floor(np.log10(hi) + 1e-9) + 1).astype(int)
    ticks = tuple(float(10.0 ** e) for e in exps)
    labels = tuple(f"$10^{{{e}}}$" for e in exps)
    return ColorScale("strain", "strain energy, J", lo, hi, True, ticks, labels, colormap)


def make_scale(color: str | ColorScale, **kw) -> ColorScale:
    """``"speed"`` / ``"strain"`` (kw: ``vmax`` / ``strain_range``, ``colormap``) or a ready ColorScale."""
    if isinstance(color, ColorScale):
        return color
    cmap = kw.get("colormap") or DEFAULT_COLORMAP
    if color == "speed":
        return speed_scale(kw.get("vmax") or SPEED_MAX_UM_PER_MIN, cmap)
    if color == "strain":
        return strain_scale(kw.get("strain_range") or STRAIN_RANGE_J, cmap)
    raise ValueError(f"color={color!r}: allowed are 'speed' (µm/min, linear 0–16) or 'strain' (J, log scale)")
