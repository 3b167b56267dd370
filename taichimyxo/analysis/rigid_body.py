"""The paper's continuous rigid-body model of a rotating aggregate (S2 Text), generalised to chains of particles and
finite rods: an independent prediction of the angular speed omega and the edge speed omega R.

Derivation (docs/model.md, "Equation of motion"). Every particle k of a cell is overdamped and feels

- its engine share f_e u_k, f_e = F_e / N, along the cell's forward axis u_k (toward the head);
- the anisotropic drag -zeta_t (v.u) u - zeta_n (v.n) n, n = u turned by +90°, zeta_t = f_e / v_b (so a free
  straight cell moves at v_b) and zeta_n = drag_ratio_normal * zeta_t (scene key ``cell.drag_ratio_normal``);
- internal forces: springs, bending, contacts, and adhesion's action-reaction pairs;
- external driving: active following's pull on a follower's head particle (no reaction anywhere).

Summing p_k x (force) over all particles (p_k = x_k - c, 2D cross product a x b = a_x b_y - a_y b_x) the internal
forces drop out: springs and contacts are central pairs (a contact's force and its lever-rule reaction act along the
same line), bending is minus the gradient of a rotation-invariant energy, adhesion's pull and reaction cancel (up to
the small lever of the head and tail particles about their line). Hence, for ANY motion,

    sum_k p_k x (zeta . v_k)  =  sum_k p_k x f_k                                  (torque identity)

with f_k the external driving force on particle k. If the aggregate turns rigidly at omega about c, v_k = omega z x
p_k, so v.u = omega (p x u) and v.n = omega (p x n), and

    omega = sum_k f_k (p_k x u_k) / sum_k [zeta_t (p_k x u_k)^2 + zeta_n (p_k x n_k)^2]          (rad/min)

((p x u)^2 + (p x n)^2 = |p|^2). Known answers:

- continuous disk of radius R, uniform density, cells along circles (p x u = r, p x n = 0): omega = v_b int r^2 dr /
  int r^3 dr, omega R = (4/3) v_b, whatever the drag ratio; with every cell also pulled by F_g on its head,
  omega R = (4/3)(1 + F_g / F_e) v_b = 4 v_b at F_g = F_max^g = 200 pN, F_e = 100 pN: the paper's 5.3 µm/min for
  adhesion and "maximum speed 4 v_b" for active following (disk_edge_speed);
- a single ring of cells bent along a circle of radius r: omega r = v_b (every cell at its free speed);
- a straight rod (chord) at distance h from the centre: p x u = h for every particle and p x n = s, its position
  along the rod, so omega = N f h / (zeta_t N h^2 + zeta_n sum s^2), sum s^2 = l0^2 N (N^2 - 1) / 12: the normal
  drag of a rod sweeping round a centre it does not pass through slows it. An aggregate of rods tangent to circles
  with uniform density up to apothem H (rod_disk_edge_speed): omega H = (4/3) v_b / (1 + 2 rho sigma^2 / H^2),
  rho = zeta_n / zeta_t, sigma^2 = sum s^2 / N = l0^2 (N^2 - 1) / 12, and the outer radius (outermost particle plus
  W/2) is R = sqrt(H^2 + a^2) + W/2, a = (N - 1) l0 / 2: finite rods turn slower than the disk when R is comparable
  with the cell length, and the drag ratio sets by how much. rod_rings builds the same aggregate as concentric
  polygon rings of straight cells (rod_ring_edge_speed, edge_speed_table).

What the model assumes and the simulator need not share: (1) rigid rotation: the torque identity holds for any
motion, but omega is the rigid one only if every particle moves at omega z x p; a spiral of cells whose contacts are
frictionless (normal to the polylines, docs/model.md term 4) can shear between turns; (2) cells along circles (or
the chords assumed); (3) the pulls: F_max^g on every cell is the maximum, a pull is k_g g below it inside the range.
rigid_motion accepts the pulls (and any extra external force) actually present, so each assumption can be tested
on its own (benchmarks/rigid_body_check.py).

Units: positions µm, speeds µm/min, forces pN, drag pN·min/µm, omega rad/min (positive counter-clockwise).
"""
from __future__ import annotations

import math

import numpy as np

from ..physics.geometry import closest_points, min_image

V_B = 4.0               # µm/min
F_E = 100.0             # pN per cell
F_MAX = 200.0           # pN
L_CELL, W_CELL, N_CELL = 5.0, 0.5, 8


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def cell_axes(positions, engine_direction) -> np.ndarray:
    """Forward unit axes u (n_cells, N, 2) as the simulator's engine takes them (terms/engine.py): at the poles the
    end segment's direction, inside the normalised mean of the two segments meeting there, toward the head
    (particle 0 when engine_direction = +1, else particle N - 1)."""
    x = np.asarray(positions, float)
    ke = np.asarray(engine_direction, float).reshape(-1)
    d = np.diff(x, axis=1)
    U = d / np.linalg.norm(d, axis=-1, keepdims=True)          # unit segment vectors k -> k+1
    T = np.empty_like(x)
    T[:, 0] = -U[:, 0]
    T[:, -1] = -U[:, -1]
    mid = -(U[:, :-1] + U[:, 1:])
    T[:, 1:-1] = mid / np.maximum(np.linalg.norm(mid, axis=-1, keepdims=True), 1e-12)
    return T * ke[:, None, None]


def drag_coefficients(v_b: float, engine_force_pN: float, N: int, drag_ratio_normal: float):
    """(zeta_t, zeta_n) per particle, pN·min/µm: zeta_t = (F_e / N) / v_b."""
    zt = engine_force_pN / N / v_b
    return zt, drag_ratio_normal * zt


def _head_index(engine_direction, N):
    ke = np.asarray(engine_direction).reshape(-1)
    return np.where(ke > 0, 0, N - 1)


def _tail_index(engine_direction, N):
    ke = np.asarray(engine_direction).reshape(-1)
    return np.where(ke > 0, N - 1, 0)


def external_forces(positions, engine_direction, engine_force_pN=F_E, guiding_pull_pN=None, extra_force_pN=None):
    """The external driving force on every particle, (n_cells, N, 2) pN: the engine share F_e / N along u, plus
    guiding_pull_pN on each head particle (a scalar or (n_cells,) magnitude along the head's axis, or (n_cells, 2)
    vectors), plus extra_force_pN (n_cells, N, 2) where given."""
    x = np.asarray(positions, float)
    n, N = x.shape[:2]
    u = cell_axes(x, engine_direction)
    F = (engine_force_pN / N) * u
    if guiding_pull_pN is not None:
        g = np.asarray(guiding_pull_pN, float)
        h = _head_index(engine_direction, N)
        uh = u[np.arange(n), h]
        if g.ndim == 2:
            F[np.arange(n), h] += g
        else:
            F[np.arange(n), h] += np.broadcast_to(g, (n,))[:, None] * uh
    if extra_force_pN is not None:
        F = F + np.asarray(extra_force_pN, float)
    return F


def rigid_motion(positions, engine_direction, v_b=V_B, drag_ratio_normal=0.5, engine_force_pN=F_E,
                 guiding_pull_pN=None, extra_force_pN=None, centre=None, translate=False, mask=None) -> dict:
    """The rigid motion of the chains `positions` (n_cells, N, 2) µm that balances drag against the external
    driving forces (external_forces): omega (rad/min) about `centre` (default: the particles' mean), and with
    translate=True also a translation velocity V (µm/min) from the full 3 x 3 force-and-torque balance (then omega
    does not depend on the reference point). mask (n_cells,) bool: only these cells count.

    Returns dict(omega, velocity (2,), centre (2,), drive_torque pN·µm, rotational_drag pN·µm·min (the sum in the
    denominator), r_max_um: the outermost counted particle's distance from the centre)."""
    x = np.asarray(positions, float)
    n, N = x.shape[:2]
    m = np.ones(n, bool) if mask is None else np.asarray(mask, bool)
    F = external_forces(x, engine_direction, engine_force_pN, guiding_pull_pN, extra_force_pN)[m].reshape(-1, 2)
    u = cell_axes(x, engine_direction)[m].reshape(-1, 2)
    nrm = np.stack([-u[:, 1], u[:, 0]], axis=1)
    pts = x[m].reshape(-1, 2)
    c = pts.mean(0) if centre is None else np.asarray(centre, float)
    p = pts - c
    zt, zn = drag_coefficients(v_b, engine_force_pN, N, drag_ratio_normal)
    pu, pn = _cross(p, u), _cross(p, nrm)
    if not translate:
        drive = float((_cross(p, F)).sum())
        drag = float((zt * pu ** 2 + zn * pn ** 2).sum())
        return dict(omega=drive / drag, velocity=[0.0, 0.0], centre=c.tolist(), drive_torque=drive,
                    rotational_drag=drag, r_max_um=float(np.linalg.norm(p, axis=1).max()))
    # drag force on particle: D v, D = zt u u^T + zn n n^T; v = V + omega z x p. Unknowns (Vx, Vy, omega).
    D = zt * u[:, :, None] * u[:, None, :] + zn * nrm[:, :, None] * nrm[:, None, :]
    zp = np.stack([-p[:, 1], p[:, 0]], axis=1)                    # z x p
    Dz = np.einsum("kij,kj->ki", D, zp)
    A = np.zeros((3, 3))
    A[:2, :2] = D.sum(0)
    A[:2, 2] = Dz.sum(0)
    A[2, :2] = np.einsum("ki,kij->j", zp, D)                      # torque of D V: p x (D V) = (z x p) . D V
    A[2, 2] = float((zp * Dz).sum())
    b = np.array([F[:, 0].sum(), F[:, 1].sum(), float(_cross(p, F).sum())])
    V0, V1, om = np.linalg.solve(A, b)
    return dict(omega=float(om), velocity=[float(V0), float(V1)], centre=c.tolist(), drive_torque=float(b[2]),
                rotational_drag=float(A[2, 2]), r_max_um=float(np.linalg.norm(p, axis=1).max()))


def rigid_omega(positions, engine_direction, v_b=V_B, drag_ratio_normal=0.5, engine_force_pN=F_E,
                guiding_pull_pN=None, centre=None, extra_force_pN=None, mask=None) -> float:
    """omega (rad/min, + counter-clockwise) of the rigid rotation about `centre` (default: the particles' mean)
    that the torque balance gives (module docstring) for the chains `positions` (n_cells, N, 2) µm, unwrapped;
    guiding_pull_pN: each cell's extra pull on its head particle along its axis (scalar or (n_cells,); or
    (n_cells, 2) vectors), default none."""
    return rigid_motion(positions, engine_direction, v_b, drag_ratio_normal, engine_force_pN, guiding_pull_pN,
                        extra_force_pN, centre, mask=mask)["omega"]


def drag_torque(positions, engine_direction, velocities, v_b=V_B, drag_ratio_normal=0.5, engine_force_pN=F_E,
                centre=None, mask=None) -> float:
    """sum_k p_k x (zeta . v_k), pN·µm, for measured velocities (n_cells, N, 2) µm/min: by the torque identity it
    equals the external driving torque whatever the motion (a check of the model's premise on the simulator)."""
    x = np.asarray(positions, float)
    n, N = x.shape[:2]
    m = np.ones(n, bool) if mask is None else np.asarray(mask, bool)
    u = cell_axes(x, engine_direction)[m].reshape(-1, 2)
    nrm = np.stack([-u[:, 1], u[:, 0]], axis=1)
    v = np.asarray(velocities, float)[m].reshape(-1, 2)
    pts = x[m].reshape(-1, 2)
    p = pts - (pts.mean(0) if centre is None else np.asarray(centre, float))
    zt, zn = drag_coefficients(v_b, engine_force_pN, N, drag_ratio_normal)
    f = zt * (v * u).sum(1)[:, None] * u + zn * (v * nrm).sum(1)[:, None] * nrm
    return float(_cross(p, f).sum())


# ---------------------------------------------------------------------------------------------------- known answers
def disk_edge_speed(kind: str, v_b: float = V_B, f_max_pN: float = F_MAX, engine_force_pN: float = F_E) -> float:
    """Edge speed omega R (µm/min) of the ideal continuous disk with cells along circles: (4/3) v_b for "adhesion"
    (its pulls are internal), "none" and "passive" (no net guiding torque); (4/3)(1 + F_max/F_e) v_b for "active",
    the maximum, every cell pulled at F_max (4 v_b at the paper's values)."""
    if kind in ("adhesion", "none", "passive"):
        return 4.0 / 3.0 * v_b
    if kind == "active":
        return 4.0 / 3.0 * (1.0 + f_max_pN / engine_force_pN) * v_b
    raise ValueError(f"disk_edge_speed(kind={kind!r}): expected adhesion, none, passive or active")


def rod_sigma2(N: int = N_CELL, l0: float | None = None) -> float:
    """sum s^2 / N over a straight rod's particles, µm^2: l0^2 (N^2 - 1) / 12."""
    l0 = (L_CELL - W_CELL) / (N - 1) if l0 is None else l0
    return l0 * l0 * (N * N - 1) / 12.0


def rod_disk_edge_speed(R_um: float, drag_ratio_normal: float = 0.5, kind: str = "adhesion", v_b: float = V_B,
                        f_max_pN: float = F_MAX, engine_force_pN: float = F_E, L: float = L_CELL,
                        W: float = W_CELL, N: int = N_CELL) -> dict:
    """The closed form for a disk of straight rods tangent to circles, uniform density up to apothem H, outer
    radius R = sqrt(H^2 + a^2) + W/2 (module docstring). Returns dict(omega rad/min, edge_speed µm/min = omega R,
    H_um, ratio_to_disk = edge speed / the ideal disk's)."""
    l0 = (L - W) / (N - 1)
    a = (N - 1) * l0 / 2.0
    if R_um - W / 2 < a:
        raise ValueError(f"rod_disk_edge_speed: R = {R_um:g} µm is below half a cell ({a + W / 2:g} µm)")
    H = math.sqrt((R_um - W / 2) ** 2 - a * a)
    boost = disk_edge_speed(kind, v_b, f_max_pN, engine_force_pN) / (4.0 / 3.0 * v_b)
    if H == 0:
        return dict(omega=0.0, edge_speed=0.0, H_um=0.0, ratio_to_disk=0.0)
    omega = boost * v_b * (4.0 / 3.0) / H / (1.0 + 2.0 * drag_ratio_normal * rod_sigma2(N, l0) / H ** 2)
    return dict(omega=omega, edge_speed=omega * R_um, H_um=H,
                ratio_to_disk=omega * R_um / disk_edge_speed(kind, v_b, f_max_pN, engine_force_pN))


def bent_ring(r_um: float, n_cells: int, N: int = N_CELL, l0: float | None = None, centre=(0.0, 0.0),
              clockwise: bool = False):
    """n_cells cells bent along the circle of radius r, evenly spaced, all heads forward (counter-clockwise unless
    clockwise): (positions (n_cells, N, 2), engine_direction (n_cells,))."""
    l0 = (L_CELL - W_CELL) / (N - 1) if l0 is None else l0
    dphi = 2.0 * math.asin(min(1.0, l0 / (2 * r_um)))          # chords of exactly l0
    sgn = -1.0 if clockwise else 1.0
    pos = np.zeros((n_cells, N, 2))
    for c in range(n_cells):
        phi0 = 2 * math.pi * c / n_cells
        phi = phi0 - sgn * dphi * np.arange(N)           # particle 0, the head, furthest forward
        pos[c, :, 0] = centre[0] + r_um * np.cos(phi)
        pos[c, :, 1] = centre[1] + r_um * np.sin(phi)
    return pos, np.ones(n_cells, np.int8)


def straight_rod(h_um: float, phi: float = 0.0, N: int = N_CELL, l0: float | None = None, offset_um: float = 0.0,
                 clockwise: bool = False):
    """One straight cell tangent to the circle of radius h at angle phi (its foot at s = offset), moving
    counter-clockwise round the origin unless clockwise: (positions (N, 2), s (N,) along the rod, head first)."""
    l0 = (L_CELL - W_CELL) / (N - 1) if l0 is None else l0
    foot = h_um * np.array([math.cos(phi), math.sin(phi)])
    t = np.array([-math.sin(phi), math.cos(phi)]) * (-1.0 if clockwise else 1.0)
    s = offset_um + ((N - 1) / 2.0 - np.arange(N)) * l0           # particle 0 (head) furthest forward
    return foot[None, :] + s[:, None] * t[None, :], s


def rod_rings(R_um: float, L: float = L_CELL, W: float = W_CELL, N: int = N_CELL, gap_um: float = 0.05,
              centre=(0.0, 0.0)):
    """Straight cells as concentric polygon rings, counter-clockwise, an aggregate of outer radius R (outermost
    particle's distance + W/2). Ring j has apothem h_j = H - j W (H = sqrt((R - W/2)^2 - a^2), a the half chain) and
    m_j = floor(pi / atan((L + gap) / (2 h_j))) sides (at least 2: two antiparallel rods fit at any h), one cell
    centred on each side, while h_j >= W/2. Returns (positions (n, N, 2), engine_direction (n,), apothems (n,))."""
    l0 = (L - W) / (N - 1)
    a = (N - 1) * l0 / 2.0
    if R_um - W / 2 < a:
        raise ValueError(f"rod_rings: R = {R_um:g} µm is below half a cell ({a + W / 2:g} µm)")
    H = math.sqrt((R_um - W / 2) ** 2 - a * a)
    cells, hs = [], []
    h = H
    j = 0
    while h >= W / 2 - 1e-12:
        m = max(2, int(math.floor(math.pi / math.atan((L + gap_um) / (2 * h)) + 1e-9)))
        off = 0.5 * j                                     # stagger the rings' corners
        for i in range(m):
            p, _ = straight_rod(h, 2 * math.pi * (i + off) / m, N, l0)
            cells.append(p + np.asarray(centre, float))
            hs.append(h)
        j += 1
        h = H - j * W
    if not cells:                                         # R below a cell and a half: one rod through the centre
        p, _ = straight_rod(0.0, 0.0, N, l0)
        cells, hs = [p + np.asarray(centre, float)], [0.0]
    return np.array(cells), np.ones(len(cells), np.int8), np.array(hs)


def rod_ring_edge_speed(R_um: float, drag_ratio_normal: float = 0.5, kind: str = "adhesion", v_b: float = V_B,
                        f_max_pN: float = F_MAX, engine_force_pN: float = F_E, L: float = L_CELL,
                        W: float = W_CELL, N: int = N_CELL) -> dict:
    """rigid_omega of rod_rings(R) about its centre (active: every cell pulled at F_max along its head's axis).
    Returns dict(omega rad/min, edge_speed µm/min = omega R, R_um (outermost particle + W/2, as built), n_cells,
    ratio_to_disk)."""
    pos, ke, _ = rod_rings(R_um, L, W, N)
    pull = f_max_pN if kind == "active" else None
    om = rigid_omega(pos, ke, v_b, drag_ratio_normal, engine_force_pN, pull, centre=(0.0, 0.0))
    R = float(np.linalg.norm(pos.reshape(-1, 2), axis=1).max()) + W / 2
    return dict(omega=om, edge_speed=om * R, R_um=R, n_cells=len(pos),
                ratio_to_disk=om * R / disk_edge_speed(kind, v_b, f_max_pN, engine_force_pN))


def edge_speed_table(R_over_L=(0.6, 0.8, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 10.0), drag_ratios=(0.5, 1.0, 2.0),
                     kind: str = "adhesion", v_b: float = V_B) -> list[dict]:
    """Rows (R/L, drag ratio, rings' edge speed / disk's, closed form's / disk's) for the docs."""
    rows = []
    for x in R_over_L:
        for rho in drag_ratios:
            ring = rod_ring_edge_speed(x * L_CELL, rho, kind, v_b)
            closed = rod_disk_edge_speed(x * L_CELL, rho, kind, v_b)
            rows.append(dict(R_over_L=x, drag_ratio_normal=rho, rings_ratio=ring["ratio_to_disk"],
                             closed_ratio=closed["ratio_to_disk"], n_cells=ring["n_cells"],
                             rings_edge_speed=ring["edge_speed"], closed_edge_speed=closed["edge_speed"]))
    return rows


# ---------------------------------------------------------------------------------------------------- guiding pulls
def guiding_pairs(positions, engine_direction, box=None, W=W_CELL, d_g=0.25, f_max_pN=F_MAX, self_follow=True):
    """Every guiding pair as terms/guiding.py finds it with distance = "segments": for every leader j whose tail
    segment lies within gap 0 < g < d_g of follower i's head segment, the pull min(k_g g, F_max) on i's head particle
    along the closest points' separation, toward the leader (k_g = F_max / d_g); adhesion puts minus it on j's tail
    particle. Returns (follower (k,), leader (k,), pull (k, 2) pN, gap (k,) µm). All pairs (O(n^2): n up to a few
    thousand)."""
    x = np.asarray(positions, float)
    n, N = x.shape[:2]
    hi, ti_ = _head_index(engine_direction, N), _tail_index(engine_direction, N)
    hn = np.where(hi == 0, 1, N - 2)
    tn = np.where(ti_ == 0, 1, N - 2)
    idx = np.arange(n)
    Ha, Hb = x[idx, hi], x[idx, hn]                  # head segment: head particle first
    Ta, Tb = x[idx, ti_], x[idx, tn]
    rel = Ta[None, :, :] - Ha[:, None, :]
    img = rel if box is None else min_image(rel, box)
    shift = img - rel
    A1 = np.broadcast_to(Ha[:, None], (n, n, 2))
    B1 = np.broadcast_to(Hb[:, None], (n, n, 2))
    s, t, c1, c2, d = closest_points(A1, B1, Ta[None, :] + shift, Tb[None, :] + shift)
    g = d - W
    ok = (g > 0) & (g < d_g)
    if not self_follow:
        ok &= ~np.eye(n, dtype=bool)
    fi, lj = np.nonzero(ok)
    sep = (c2 - c1)[fi, lj]
    unit = sep / np.maximum(np.linalg.norm(sep, axis=-1, keepdims=True), 1e-12)
    mag = np.minimum((f_max_pN / d_g) * g[fi, lj], f_max_pN)
    return fi, lj, mag[:, None] * unit, g[fi, lj]


def guiding_pulls(positions, engine_direction, box=None, W=W_CELL, d_g=0.25, f_max_pN=F_MAX, self_follow=True):
    """Each cell's guiding pull on its head particle (n_cells, 2) pN, the sum of its guiding_pairs, and the gap to
    its nearest leader (inf: none in range)."""
    n = len(positions)
    fi, lj, pull_k, gap_k = guiding_pairs(positions, engine_direction, box, W, d_g, f_max_pN, self_follow)
    pull = np.zeros((n, 2))
    np.add.at(pull, fi, pull_k)
    gap = np.full(n, np.inf)
    np.minimum.at(gap, fi, gap_k)
    return pull, gap


# ---------------------------------------------------------------------------------------------------- spiral start
def spiral_prediction(scene) -> dict:
    """The model's omega and edge speed for the spiral start the simulator would use (placement.spiral_start):
    omega about the spiral's centre with (i) no pull (adhesion, none, passive: no net guiding torque), (ii) the
    pulls of the start's gaps (active), (iii) every cell pulled at F_max (active's maximum); and the ideal disk's
    edge speed. R: the outermost particle's distance + W/2."""
    from ..physics.placement import spiral_start
    pos, ke = spiral_start(scene)
    centre = 0.5 * np.array(scene.box)
    v_b = scene.v_b_um_per_min
    rho = scene.raw["cell"]["drag_ratio_normal"]
    Fe = scene.engine_force
    pull, gap = guiding_pulls(pos, ke, scene.box, scene.width, scene.guiding_range, scene.guiding_f_max,
                              scene.guiding_self)
    R = float(np.linalg.norm(pos.reshape(-1, 2) - centre, axis=1).max()) + scene.width / 2
    om0 = rigid_omega(pos, ke, v_b, rho, Fe, None, centre)
    om_start = rigid_omega(pos, ke, v_b, rho, Fe, pull, centre)
    om_max = rigid_omega(pos, ke, v_b, rho, Fe, scene.guiding_f_max, centre)
    kind = scene.guiding
    om = om_start if kind == "active" else om0
    return dict(R_um=R, n_cells=len(pos), omega_no_pull=om0, omega_start_pulls=om_start, omega_fmax=om_max,
                omega=om, edge_speed=abs(om) * R, edge_speed_no_pull=abs(om0) * R, edge_speed_fmax=abs(om_max) * R,
                disk_edge_speed=disk_edge_speed(kind, v_b, scene.guiding_f_max, Fe),
                mean_start_pull_pN=float(np.linalg.norm(pull, axis=1).mean()))
