"""Numerical-stability invariants of a running Simulation, shared by the tests and benchmarks.

A state is healthy when
  - every position is finite;
  - every segment length is within +-20 % of the rest length l0;
  - no cell's centre moves faster than 5 v_b, and no particle faster than 5 v_b, speeds measured as displacements
    over the displayed-speed window (docs/model.md: 1 s; single-step velocities in dense cores jitter far above that
    without meaning anything). Exception, by the physics: a guiding or slime pull of up to F_max = 200 pN acts on
    one particle, whose normal drag is zeta_n = 94 pN s/µm, so a head swinging sideways (a flexible follower curling
    round a leader's tail: ~10 v_b for about a second) or a rigid cell spinning as a ring on its own tail (tail
    particle 5.2 v_b, steady) is legitimately faster, identically at dt / 4. And in every scene a contact can pass
    a whole cell's engine force F_e onto one particle (a pole pressing on a side; cells buckling in a dense jam:
    S11 without guiding reaches 5.04 v_b at 2 ms, unchanged at dt / 8, docs/accuracy.md). The particle bound is
    therefore 5 v_b + max(F_e, F_max) / (zeta_n v_b) (21 v_b without pulls, 37 v_b with the paper's guiding); the
    centre bound stays 5 v_b.
    An explicit-Euler instability grows geometrically and breaks the length and distance bounds as well;
  - no two segments of different cells come closer than 0.3 W, nor two non-adjacent segments of one cell
    (segments k and k + 2 included: a hairpin folded on the node of k + 1 is pushed apart by the node contacts of
    nodes k and k + 3, see terms/contacts.py and tests/test_stability.py).
    Why 0.3 W: the contact force at that depth is k_c * 0.7 W = 700 pN at the high-density k_c = 0.002 N/m and
    3500 pN at 0.01 N/m, i.e. 7 to 35 cells' full engine force pressing on one contact. Nothing in a small or
    moderately dense population pushes that hard, so a deeper overlap means the step let segments pass through
    each other rather than a physical jam;
  - the spring energy (stretch + bending, and separately the contact energy) does not grow without bound: in the
    second half of a run it stays below twice its first-half maximum plus a small floor.

`measure(positions, ...)` computes the quantities from plain numpy positions; `InvariantMonitor` steps a
Simulation in windows and records them; `check_invariants(sim, steps)` does both and raises AssertionError
naming every violated bound.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geometry import closest_points, contact_energy, min_image
from .terms.bending import bend_angles  # noqa: F401  (bend_angles: API)
from .terms.bending import energy as bend_energy
from .terms.springs import energy as spring_energy


@dataclass(frozen=True)
class Bounds:
    length_tol: float = 0.20            # |l / l0 - 1| <= length_tol
    speed_factor: float = 5.0           # windowed particle speed <= speed_factor * v_b
    centre_speed_factor: float = 5.0    # windowed speed of a cell's centre <= centre_speed_factor * v_b
    min_distance_W: float = 0.30        # segment distance between different cells >= min_distance_W * W
    self_min_sep: int = 2               # same-cell segment pairs this far apart along the cell count collide
    energy_growth: float = 2.0          # late max <= energy_growth * early max + floor
    energy_floor_pN_um_per_cell: float = 5.0   # the work of one engine (100 pN) over 0.05 µm; absorbs noise

    @classmethod
    def for_scene(cls, scene, **kw) -> "Bounds":
        """The default bounds, with the particle speed bound widened by the largest force one particle can take
        (a cell's engine force through a contact, guiding F_max^g, slime F_max^s) over the normal drag (see the
        module docstring)."""
        pull = scene.engine_force
        if scene.guiding != "none":
            pull = max(pull, scene.guiding_f_max)
        if scene.slime:
            pull = max(pull, scene.slime_f_max)
        base = kw.pop("speed_factor", cls.speed_factor)
        return cls(speed_factor=base + pull / (scene.zeta_n * scene.v_b), **kw)


def segment_lengths(pos: np.ndarray) -> np.ndarray:
    """(n_cells, N-1) lengths of chains given unwrapped (n_cells, N, 2)."""
    return np.linalg.norm(np.diff(pos, axis=1), axis=-1)


def segment_pairs(pos: np.ndarray, box, W: float, self_min_sep: int = 3):
    """Closest distances of every pair of segments that could touch: different cells, or one cell with segment
    indices at least `self_min_sep` apart. Returns (d_other, d_self) as 1-D arrays of pair distances (only pairs
    whose midpoints are within l_max + W are evaluated). Minimum image everywhere."""
    L = np.asarray(box, dtype=np.float64)
    n, N = pos.shape[:2]
    a = pos[:, :-1].reshape(-1, 2)
    b = pos[:, 1:].reshape(-1, 2)
    cell = np.repeat(np.arange(n), N - 1)
    k = np.tile(np.arange(N - 1), n)
    mid = 0.5 * (a + b)
    half = 0.5 * np.linalg.norm(b - a, axis=-1)
    S = len(a)
    reach = 2 * half.max(initial=0.0) + W
    # candidate pairs by midpoint distance, in blocks to bound memory
    I, J = [], []
    block = max(1, 2_000_000 // max(S, 1))
    for i0 in range(0, S, block):
        dm = mid[i0:i0 + block, None, :] - mid[None, :, :]
        dm -= L * np.round(dm / L)
        close = (dm * dm).sum(-1) < reach * reach
        ii, jj = np.nonzero(close)
        ii = ii + i0
        keep = ii < jj
        I.append(ii[keep])
        J.append(jj[keep])
    I = np.concatenate(I) if I else np.zeros(0, int)
    J = np.concatenate(J) if J else np.zeros(0, int)
    same = cell[I] == cell[J]
    ok = ~same | (np.abs(k[I] - k[J]) >= self_min_sep)
    I, J, same = I[ok], J[ok], same[ok]
    # bring segment J next to segment I (minimum image of its first end relative to I's first end)
    shift = a[J] - a[I]
    shift = shift - L * np.round(shift / L) - shift
    d = closest_points(a[I], b[I], a[J] + shift, b[J] + shift)[4]
    return d[~same], d[same]


def measure(pos: np.ndarray, box, l0: float, W: float, k_s: float, k_a: float, k_c: float,
            self_min_sep: int = 3) -> dict:
    """Every invariant quantity of one state; positions (n_cells, N, 2) unwrapped chains, internal units."""
    pos = np.asarray(pos, dtype=np.float64)
    out = {"finite": bool(np.all(np.isfinite(pos)))}
    if not out["finite"]:
        nan = float("nan")
        out.update(len_min=nan, len_max=nan, d_other_min=nan, d_self_min=nan, e_spring=nan, e_bend=nan,
                   e_contact=nan)
        return out
    ln = segment_lengths(pos)
    d_other, d_self = segment_pairs(pos, box, W, self_min_sep)
    out["len_min"] = float(ln.min() / l0)
    out["len_max"] = float(ln.max() / l0)
    out["d_other_min"] = float(d_other.min() / W) if d_other.size else math.inf
    out["d_self_min"] = float(d_self.min() / W) if d_self.size else math.inf
    out["e_spring"] = float(spring_energy(pos, k_s, l0))
    out["e_bend"] = float(bend_energy(pos, k_a))
    out["e_contact"] = contact_energy(pos, box, W, k_c)
    return out


def centres(pos: np.ndarray) -> np.ndarray:
    """(n_cells, 2) mean position of each unwrapped chain."""
    return np.asarray(pos, dtype=np.float64).mean(axis=1)


class InvariantMonitor:
    """Run a Simulation in windows, recording the invariants after each (speeds = displacements over the window)."""

    def __init__(self, sim, bounds: Bounds | None = None):
        self.sim = sim
        sc = sim.scene
        self.bounds = bounds if bounds is not None else Bounds.for_scene(sc)
        self.records: list[dict] = []
        self.params = dict(box=sc.box, l0=sc.rest_length, W=sc.width, k_s=sc.k_s, k_a=sc.k_a, k_c=sc.k_c)
        self.v_b = sc.v_b_um_per_min

    def default_window(self) -> int:
        return max(1, int(round(self.sim.scene.speed_window_s / self.sim.scene.dt)))

    def sample(self, window_steps: int | None = None, measure_only: bool = False) -> dict:
        """Advance one window (default: the scene's speed window) and record; measure_only records the current
        state without stepping (no speeds)."""
        sim = self.sim
        nan = float("nan")
        speed = centre_speed = nan
        fastest = None
        if not measure_only:
            window_steps = window_steps or self.default_window()
            c0 = centres(sim.positions())
            t0 = sim.time
            sim.snapshot_speed()
            sim.advance(window_steps)
            sp = sim.particle_speed()
            pos = sim.positions()
            if np.all(np.isfinite(sp)) and np.all(np.isfinite(pos)):
                speed = float(np.max(sp))
                fastest = tuple(int(i) for i in np.unravel_index(int(np.argmax(sp)), sp.shape))
                d = min_image(centres(pos) - c0, sim.scene.box)
                centre_speed = float(np.sqrt((d * d).sum(-1)).max() / (sim.time - t0) * 60.0)
            else:
                speed = centre_speed = float("inf")
        rec = measure(sim.positions(), self.params["box"], self.params["l0"], self.params["W"], self.params["k_s"],
                      self.params["k_a"], self.params["k_c"], self.bounds.self_min_sep)
        rec["t_s"] = sim.time
        rec["step"] = sim.step_count
        rec["speed_max_vb"] = speed / self.v_b
        rec["centre_speed_max_vb"] = centre_speed / self.v_b
        rec["fastest"] = fastest                  # (cell, particle) of the fastest particle
        self.records.append(rec)
        return rec

    def run(self, steps: int, window_steps: int | None = None) -> list:
        window_steps = window_steps or self.default_window()
        done = 0
        while done < steps:
            w = min(window_steps, steps - done)
            self.sample(w)
            done += w
            if not self.records[-1]["finite"]:
                break
        return self.records

    def violations(self, skip: int = 0) -> list[str]:
        """Human-readable violations over the records after the first `skip`."""
        b = self.bounds
        recs = self.records[skip:]
        n_cells = self.sim.scene.n_cells
        bad = []
        for r in recs:
            at = f"t={r['t_s']:.3f} s (step {r['step']})"
            if not r["finite"]:
                bad.append(f"{at}: non-finite positions")
                break
            if not (1 - b.length_tol <= r["len_min"] and r["len_max"] <= 1 + b.length_tol):
                bad.append(f"{at}: segment length {r['len_min']:.3f}..{r['len_max']:.3f} l0 outside "
                           f"1 +- {b.length_tol}")
            # nan: a record taken without a window (measure_only)
            if not math.isnan(r["speed_max_vb"]) and not r["speed_max_vb"] <= b.speed_factor:
                bad.append(f"{at}: particle speed {r['speed_max_vb']:.2f} v_b > {b.speed_factor:.3g} v_b "
                           f"(cell, particle {r['fastest']})")
            if not math.isnan(r["centre_speed_max_vb"]) and not r["centre_speed_max_vb"] <= b.centre_speed_factor:
                bad.append(f"{at}: cell centre speed {r['centre_speed_max_vb']:.2f} v_b > "
                           f"{b.centre_speed_factor:.3g} v_b")
            if not r["d_other_min"] >= b.min_distance_W:
                bad.append(f"{at}: segments of different cells {r['d_other_min']:.3f} W apart < "
                           f"{b.min_distance_W} W")
            if not r["d_self_min"] >= b.min_distance_W:
                bad.append(f"{at}: segments of one cell {r['d_self_min']:.3f} W apart < {b.min_distance_W} W")
        finite = [r for r in recs if r["finite"]]
        if len(finite) >= 2:
            h = len(finite) // 2
            floor = b.energy_floor_pN_um_per_cell * n_cells
            for key, name in (("e_int", "spring (stretch + bending)"), ("e_contact", "contact")):
                e = np.array([r["e_spring"] + r["e_bend"] if key == "e_int" else r[key] for r in finite])
                early, late = e[:h].max(), e[h:].max()
                if late > b.energy_growth * early + floor:
                    bad.append(f"{name} energy grows: max {early:.3g} pN·µm in the first half, {late:.3g} in the "
                               f"second (bound {b.energy_growth} x early + {floor:.3g})")
        return bad

    def summary(self, skip: int = 0) -> str:
        recs = [r for r in self.records[skip:] if r["finite"]] or self.records[skip:]
        if not recs:
            return "no records"

        def mx(key):
            v = [r[key] for r in recs if not math.isnan(r[key])]
            return max(v) if v else float("nan")

        return (f"{len(recs)} records to t={recs[-1]['t_s']:.2f} s: length {min(r['len_min'] for r in recs):.3f}.."
                f"{mx('len_max'):.3f} l0, particle speed <= {mx('speed_max_vb'):.2f} v_b, centre speed <= "
                f"{mx('centre_speed_max_vb'):.2f} v_b, other-cell distance >= "
                f"{min(r['d_other_min'] for r in recs):.3f} W, self >= {min(r['d_self_min'] for r in recs):.3f} W, "
                f"E_int <= {max(r['e_spring'] + r['e_bend'] for r in recs):.3g}, "
                f"E_contact <= {mx('e_contact'):.3g} pN·µm")


def check_invariants(sim, steps: int, window_steps: int | None = None, bounds: Bounds | None = None,
                     settle_steps: int = 0) -> InvariantMonitor:
    """Run `sim` for settle_steps (not checked: e.g. cells that start on top of each other need time to separate)
    and then `steps` more in windows (default: the scene's speed window), asserting every invariant (bounds default
    to Bounds.for_scene). Returns the monitor (records, summary)."""
    mon = InvariantMonitor(sim, bounds)
    if settle_steps:
        sim.advance(settle_steps)
    mon.sample(measure_only=True)
    if not mon.records[0]["finite"]:
        raise AssertionError(f"non-finite positions after {settle_steps} settling steps")
    mon.run(steps, window_steps)
    bad = mon.violations()
    if bad:
        raise AssertionError(f"{len(bad)} invariant violation(s): " + "; ".join(bad[:5]) + f"\n{mon.summary()}")
    return mon
