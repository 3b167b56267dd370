"""Initial configurations (docs/model.md "Initial configurations"): random, aligned, spiral.

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
    if scene.polarity == "same":
        return np.ones(n, np.int8)
    u = rng.uniform(scene.seed, rng.STREAM_POLARITY, np.arange(n))
    return np.where(u < 0.5, 1, -1).astype(np.int8)


# Random sequential placement slows down sharply as the area fills (each new cell must land in the shrinking free
# space). Tries per placed cell, averaged from the first, measured on 50 x 50 and 100 x 100 µm boxes: ~23 up to area
# fraction 0.30, ~72 to 0.35, 300-350 to 0.40, 650-800 to 0.42, ~3900 to 0.44; beyond 0.44 no run placed every
# cell. Scene.validate refuses random starts above 0.40 (schema.py, RANDOM_MAX_AREA_FRACTION) before anything is
# placed, and the placement gives up after PLACEMENT_TRIES_PER_CELL tries per cell on average: about three times
# what 0.40 needs, and a bounded time whatever the input (a few seconds per thousand cells).
PLACEMENT_TRIES_PER_CELL = 1000


def _placement_bins(scene) -> tuple[int, int]:
    # bins of side >= chain + W: two cells can overlap only if their centres lie in the same or adjacent bins
    Lx, Ly = scene.box
    reach = (scene.N - 1) * scene.rest_length + scene.width
    return max(1, int(Lx // reach)), max(1, int(Ly // reach))


def placement_grid_bytes(scene) -> int:
    """Memory of random_start's bins (8 entries of 4 bytes each at first; resources.py counts it)."""
    nbx, nby = _placement_bins(scene)
    return nbx * nby * (8 * 4 + 8)


def random_start(scene, max_tries_per_cell: int = PLACEMENT_TRIES_PER_CELL, progress=None):
    """Straight cells at random centres and angles, overlaps (segment distance < W, periodic) rejected.

    Random sequential placement: try i is accepted if its cell overlaps no cell accepted before it. Tries are drawn
    and tested against the placed cells in batches (numpy, not one Python iteration per try); the batch's survivors
    are then accepted in order, each checked against those accepted before it in the same batch: the same cells as
    one try at a time, in a fraction of the time.

    progress(placed, n, tries), if given, is called after every batch (the caller decides what to show).
    Raises PlacementError once max_tries_per_cell * n tries (plus a small allowance) have not placed every cell."""
    n, N, l0, W = scene.n_cells, scene.N, scene.rest_length, scene.width
    Lx, Ly = scene.box
    box = np.array([Lx, Ly])
    chain = (N - 1) * l0
    # two straight chains whose centres are at least chain + W apart cannot come closer than W; a straight chain is
    # one segment from its first to its last particle, so one segment distance per pair decides an overlap
    reach2 = (chain + W) ** 2
    k_end = (N - 1) / 2.0                 # particle offsets along the cell, in l0, as straight_cell places them
    draws = rng.Stream(scene.seed, rng.STREAM_PLACE)
    pos = np.zeros((n, N, 2))
    centres = np.zeros((n, 2))
    nbx, nby = _placement_bins(scene)
    cap = 8
    bin_items = np.full((nbx, nby, cap), -1, np.int32)
    bin_n = np.zeros((nbx, nby), np.int64)
    off = np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)])
    placed = 0
    tries = 0
    budget = max_tries_per_cell * n + 10_000
    while placed < n:
        if tries >= budget:
            raise PlacementError(f"random placement gave up after {budget} tries with {placed} of {n} cells placed")
        K = int(min(1024, budget - tries))
        r = draws.next(3 * K).reshape(K, 3)
        c = r[:, :2] * box
        ang = r[:, 2] * 2 * math.pi
        u = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        a0, a1 = c - (k_end * l0) * u, c + (k_end * l0) * u
        bx = (c[:, 0] / Lx * nbx).astype(np.int64) % nbx
        by = (c[:, 1] / Ly * nby).astype(np.int64) % nby
        # every placed cell in the 3x3 bins around each try: (K, 9 * cap), -1 where a bin holds fewer
        cand = bin_items[(bx[:, None] + off[None, :, 0]) % nbx, (by[:, None] + off[None, :, 1]) % nby].reshape(K, -1)
        ok = np.ones(K, bool)
        ki, mi = np.nonzero(cand >= 0)
        if len(ki):
            j = cand[ki, mi]
            rel = centres[j] - c[ki]
            near = min_image(rel, box)
            close = (near * near).sum(-1) < reach2
            ki, j, shift = ki[close], j[close], (near - rel)[close]
            d = closest_points(a0[ki], a1[ki], pos[j, 0] + shift, pos[j, -1] + shift)[4]
            ok[ki[d < W]] = False
        used = K
        batch_first = placed
        for k in np.flatnonzero(ok):
            if placed > batch_first:
                # against the cells accepted earlier in this batch (the test above saw only those placed before it)
                rel = centres[batch_first:placed] - c[k]
                near = min_image(rel, box)
                close = (near * near).sum(-1) < reach2
                if np.any(close):
                    shift = (near - rel)[close]
                    e = pos[batch_first:placed][close]
                    if np.any(closest_points(a0[k], a1[k], e[:, 0] + shift, e[:, -1] + shift)[4] < W):
                        continue
            pos[placed] = straight_cell(c[k], float(ang[k]), N, l0)
            centres[placed] = c[k]
            b = (bx[k], by[k])
            if bin_n[b] == cap:                 # a crowded bin: widen every bin
                bin_items = np.concatenate([bin_items, np.full((nbx, nby, cap), -1, np.int32)], axis=2)
                cap *= 2
            bin_items[b][bin_n[b]] = placed
            bin_n[b] += 1
            placed += 1
            if placed == n:
                used = int(k) + 1
                break
        tries += used
        if progress is not None:
            progress(placed, n, tries)
    return pos, _polarities(scene, n)


def aligned_start(scene):
    """All cells along x, packed in rows W apart, cell ends touching: area fraction n L W / area (1.0 at the
    paper's high density). Each row gets a random offset along x; missing cells leave random empty slots. Each cell
    is turned about its centre by a uniform random angle within +- scene.aligned_tilt_deg: the model has no noise,
    and exactly parallel rows only ever push along their own line (docs/model.md "Initial configurations")."""
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
    tilts = np.radians(scene.aligned_tilt_deg) * (2.0 * rng.uniform(scene.seed, rng.STREAM_TILT, np.arange(n)) - 1.0)
    pos = np.zeros((n, N, 2))
    for k, s in enumerate(slots):
        r, i = divmod(int(s), per_row)
        c = np.array([(i + 0.5) * pitch + offsets[r], (r + 0.5) * Ly / rows])
        pos[k] = straight_cell(c, float(tilts[k]), N, l0)
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
    all moving the same way round with their heads inward along the spiral (docs/model.md "Initial configurations", the
    paper's S5 Fig): each trailing cell lies further from the axis than its leader, so the chain winds in, as a
    stream that closes on itself traps its leading cells at the centre. `gap_um` lies between one cell's tail cap
    and the next cell's head cap (inside the guiding range). Cell 0 leads, innermost; cell c follows cell c - 1."""
    n, N, l0, W, L = scene.n_cells, scene.N, scene.rest_length, scene.width, scene.length
    b, r0 = _spiral_params(scene)
    centre = 0.5 * np.array(scene.box)
    pitch = L + gap_um                         # arc length per cell
    pos = np.zeros((n, N, 2))
    for c in range(n):
        # particle 0 is the head (k_e = +1) and lies innermost along the spiral
        s = c * pitch + W / 2 + np.arange(N) * l0
        th = _spiral_arc_to_theta(s, b, r0)
        r = r0 + b * th
        pos[c, :, 0] = centre[0] + r * np.cos(th)
        pos[c, :, 1] = centre[1] + r * np.sin(th)
    # exact segment lengths (the arc-length formula is approximate), keeping each head where the spiral put it
    for c in range(n):
        for k in range(1, N):
            d = pos[c, k] - pos[c, k - 1]
            pos[c, k] = pos[c, k - 1] + d / np.linalg.norm(d) * l0
    return pos, np.ones(n, np.int8)


def initial_configuration(scene, progress=None):
    """The scene's start. progress(placed, n, tries): see random_start (the other starts are fast and silent)."""
    if scene.start == "random":
        pos, ke = random_start(scene, progress=progress)
    else:
        pos, ke = {"aligned": aligned_start, "spiral": spiral_start}[scene.start](scene)
    L = np.array(scene.box)
    shift = np.floor(pos[:, :1, :] / L) * L      # particle 0 in the box, chains unwrapped
    return pos - shift, ke
