"""Capsules: every segment of every cell drawn as an antialiased, outlined capsule, wrapped across the periodic
box edges, all in numpy (steps 1-3 of :mod:`taichimyxo.render.raster`)."""
from __future__ import annotations

import math

import numpy as np

OUTLINE_RGB = (25, 25, 25)  # cell outlines

_KEY_EMPTY = np.iinfo(np.int64).max
_D_QUANT = 1 << 16          # distance quantum in the per-pixel key: 1/65536 px
_CHUNK = 1 << 21            # candidate pixels per batch (bounds memory, keeps arrays in cache-friendly sizes)


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
