"""Initial configurations (MODEL.md "Initial configurations"): random, aligned, spiral.

Each returns (positions (n_cells, N, 2) float64 µm, engine_direction (n_cells,) int8). All randomness comes from
counter-based streams of the scene's seed, so the start is identical whatever the thread count."""
from __future__ import annotations

import math

import numpy as np

from . import rng
from .geometry import closest_points, min_image


class PlacementError(ValueError):
    pass


def straight_cell(centre, angle, N, l0):
    u = np.array([math.cos(angle), math.sin(angle)])
    k = np.arange(N) - (N - 1) / 2.0
    return np.asarray(centre)[None, :] + k[:, None] * l0 * u[None, :]


def _polarities(scene, n):
    if scene.raw["population"]["polarity"] == "same":
        return np.ones(n, np.int8)
    u = rng.uniform(scene.seed, rng.STREAM_POLARITY, np.arange(n))
    return np.where(u < 0.5, 1, -1).astype(np.int8)


def random_start(scene, max_tries_per_cell: int = 2000):
    """Straight cells at random centres and angles, overlaps (segment distance < W, periodic) rejected."""
    n, N, l0, W = scene.n_cells, scene.N, scene.rest_length, scene.width
    Lx, Ly = scene.box
    box = np.array([Lx, Ly])
    chain = (N - 1) * l0
    draws = rng.Stream(scene.seed, rng.STREAM_PLACE)
    pos = np.zeros((n, N, 2))
    centres = np.zeros((n, 2))
    # bin placed cells on a grid of side >= chain + W so only the 3x3 neighbourhood needs checking
    nbx, nby = max(1, int(Lx // (chain + W))), max(1, int(Ly // (chain + W)))
    bins: dict[tuple[int, int], list[int]] = {}
    placed = 0
    tries = 0
    while placed < n:
        tries += 1
        if tries > max_tries_per_cell * n:
            raise PlacementError(f"could place only {placed} of {n} cells without overlap")
        r = draws.next(3)
        c = r[:2] * box
        ang = r[2] * 2 * math.pi
        cell = straight_cell(c, ang, N, l0)
        bx, by = int(c[0] / Lx * nbx) % nbx, int(c[1] / Ly * nby) % nby
        cand = []
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                cand.extend(bins.get(((bx + dx) % nbx, (by + dy) % nby), ()))
        if cand:
            cand = np.array(sorted(set(cand)))
            others = pos[cand]                                          # (m, N, 2)
            shift = min_image(centres[cand] - c, box) - (centres[cand] - c)
            others = others + shift[:, None, :]
            a0 = cell[:-1][None, :, None, :]
            a1 = cell[1:][None, :, None, :]
            b0 = others[:, None, :-1, :]
            b1 = others[:, None, 1:, :]
            d = closest_points(a0, a1, b0, b1)[4]
            if np.any(d < W):
                continue
        pos[placed] = cell
        centres[placed] = c
        bins.setdefault((bx, by), []).append(placed)
        placed += 1
    return pos, _polarities(scene, n)


def aligned_start(scene):
    """All cells parallel to x, packed in rows W apart, cell ends touching: area fraction n L W / area (1.0 at the
    paper's high density). Each row gets a random offset along x; missing cells leave random empty slots."""
    n, N, l0, W, L = scene.n_cells, scene.N, scene.rest_length, scene.width, scene.length
    Lx, Ly = scene.box
    per_row = int(math.floor(Lx / L + 1e-9))
    rows = int(math.floor(Ly / W + 1e-9))
    if per_row * rows < n:
        raise PlacementError(f"{n} cells do not fit in {rows} rows of {per_row} in {Lx:g} x {Ly:g} µm")
    pitch = Lx / per_row                      # >= L: cells fill the row, ends (almost) touching
    draws = rng.Stream(scene.seed, rng.STREAM_PLACE)
    offsets = draws.next(rows) * pitch
    slots = np.arange(per_row * rows)
    if n < len(slots):
        order = np.argsort(draws.next(len(slots)), kind="stable")
        slots = np.sort(order[:n])
    pos = np.zeros((n, N, 2))
    for k, s in enumerate(slots):
        r, i = divmod(int(s), per_row)
        c = np.array([(i + 0.5) * pitch + offsets[r], (r + 0.5) * Ly / rows])
        pos[k] = straight_cell(c, 0.0, N, l0)
    pos[:, :, 0] = np.mod(pos[:, :1, 0], Lx) + (pos[:, :, 0] - pos[:, :1, 0])
    return pos, _polarities(scene, n)


def _spiral_params(scene):
    W, L = scene.width, scene.length
    r0 = 1.5 * L / math.pi                   # innermost turn: a cell spans at most ~1/3 of it
    # turns W apart, plus the sagitta of the chords on both turns so the polyline cells do not overlap
    b = (W + scene.rest_length ** 2 / (4 * r0)) / (2 * math.pi)
    return b, r0


def _spiral_arc_to_theta(s, b, r0):
    # arc length of r = r0 + b theta is ~ integral r dtheta = r0 theta + b theta^2 / 2 (b << r)
    return (-r0 + np.sqrt(r0 * r0 + 2 * b * s)) / b


def spiral_capacity(scene) -> int:
    b, r0 = _spiral_params(scene)
    rmax = 0.5 * min(scene.box) - scene.length
    if rmax <= r0:
        return 0
    theta = (rmax - r0) / b
    arc = r0 * theta + 0.5 * b * theta * theta
    return int(arc // (scene.length + 0.05))


def spiral_start(scene, gap_um: float = 0.05):
    """Cells head to tail along an Archimedean spiral r = r0 + b theta (turns W apart, see _spiral_params), centred,
    all moving outward along the spiral (the same way round), with `gap_um` between one cell's tail cap and the
    next cell's head cap (inside the guiding range)."""
    n, N, l0, W, L = scene.n_cells, scene.N, scene.rest_length, scene.width, scene.length
    b, r0 = _spiral_params(scene)
    centre = 0.5 * np.array(scene.box)
    pitch = L + gap_um                         # arc length per cell
    pos = np.zeros((n, N, 2))
    for c in range(n):
        # particle 0 is the head (k_e = +1) and lies furthest along the spiral
        s_tail = c * pitch + W / 2
        s = s_tail + (N - 1 - np.arange(N)) * l0
        th = _spiral_arc_to_theta(s, b, r0)
        r = r0 + b * th
        pos[c, :, 0] = centre[0] + r * np.cos(th)
        pos[c, :, 1] = centre[1] + r * np.sin(th)
    # cells move outward: the cell ahead (the leader) is c + 1; fix exact segment lengths lost to the arc approx.
    for c in range(n):
        for k in range(N - 2, -1, -1):
            d = pos[c, k] - pos[c, k + 1]
            pos[c, k] = pos[c, k + 1] + d / np.linalg.norm(d) * l0
    return pos, np.ones(n, np.int8)


def initial_configuration(scene):
    fn = {"random": random_start, "aligned": aligned_start, "spiral": spiral_start}[scene.start]
    pos, ke = fn(scene)
    L = np.array(scene.box)
    shift = np.floor(pos[:, :1, :] / L) * L      # particle 0 in the box, chains unwrapped
    return pos - shift, ke
