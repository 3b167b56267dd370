"""Trajectories with known answers (rotating disks, straight streams, a random gas), for the tests and benchmarks."""
from __future__ import annotations

import math
from typing import Iterator

import numpy as np

from ..io.frame import Frame
from ..physics.geometry import min_image


def synthetic_frames(box=(200.0, 200.0), n_frames=1, dt_s=60.0, disks=(), streams=(), gas=0, gas_speed=4.0,
                     width=0.5, length=5.0, N=8, seed=0, strain=False, t0_s=0.0, jitter_deg=0.0,
                     speed_noise=0.0, gas_avoids_disks=False, velocity=True, jams=(),
                     background_strain_J=0.0) -> Iterator[Frame]:
    """Trajectories with known answers (for tests and benchmarks).

    disks: dicts(centre=(x, y), radius=R, omega=rad/min (signed, > 0 counter-clockwise), r_in=1.5, speed=None):
        cells of outline `length` on concentric rings W apart from r_in to R - W/2 (R: the outer edge of the outermost
        ring), head to tail, each an exact arc, particle speeds |omega| r, rotating rigidly; with speed=v every ring
        turns at v / r instead (uniform speed, like a slime-trail aggregate; only the sign of omega is used). Half of
        the cells have k_e = -1 (chain stored tail first). With strain=True, segment strain energy
        1e-18 J x (1 - r/R); every other cell (streams, gas, jams, free cells) then has background_strain_J.
    streams: dicts(origin=(x, y), angle=rad, rows=int, per_row=int, speed=µm/min): straight parallel cells, rows W
        apart, head to tail, translating.
    gas: that many straight cells at random places and angles, moving along their headings at gas_speed; with
        gas_avoids_disks, none starts within R + length of a disk centre (they still cross disks later).
    jitter_deg, speed_noise: disk cells turned about their centres by a random angle of that SD (fixed per cell) and
        particle speeds multiplied by (1 + speed_noise x standard normal), drawn anew each frame. A disk's
        ``pitch_deg`` turns every cell of it by that fixed angle (> 0: heads point inward), cells moving along their
        bodies: a spiral (cells circulate and drift inward).
    Events (for tracking): a disk with ``t_on_min`` / ``t_off_min`` exists only for t_on <= t < t_off (minutes);
        disks with the same ``pool`` name share cell slots (cell indices), each disk taking ``slot`` .. slot + its
        number of cells (default: after the previous disks of its pool), so one disk can be made of the cells of two
        earlier ones (a merge), or the reverse (a split). Slots no disk of the pool uses at a time are free cells:
        straight, scattered (away from the disks), moving at gas_speed (a disk appears from them, dissolves into
        them). Without these keys a disk is its own pool, always there.
    jams: dicts(centre, radius, speed=0.5, ...): a jammed cluster: straight cells packed in rows W apart within the
        radius, each at a random orientation (fixed), pushing slowly (speed) along its body in a random direction.
    velocity: store particle velocities (µm/min): speed x the direction each particle moves (the tangent of its
        circle for a disk cell, turned with the cell by jitter and pitch; the cell's axis for streams, gas and jams),
        as trajectories with particles/velocity do; False: none (older trajectories)."""
    rng = np.random.default_rng(seed)
    L = np.asarray(box, float)
    l0 = (length - width) / (N - 1)
    j = np.arange(N) - 0.5 * (N - 1)
    parts = []   # (kind, data)
    for dk in disks:
        ringr = []
        r = float(dk.get("r_in", 1.5))
        while r <= dk["radius"] - 0.5 * width + 1e-9:
            m = int(2 * math.pi * r // length)
            if m >= 1 and (N - 1) * l0 < 0.95 * 2 * math.pi * r:
                ringr.append((r, m))
            r += width
        rr, th = [], []
        for r, m in ringr:
            th0 = rng.uniform(0, 2 * math.pi)
            for q in range(m):
                rr.append(r)
                th.append(th0 + 2 * math.pi * q / m)
        rr, th = np.array(rr), np.array(th)
        ke = np.where(rng.random(len(rr)) < 0.5, 1, -1).astype(np.int8)
        jit = np.deg2rad(jitter_deg) * rng.standard_normal(len(rr)) + np.deg2rad(dk.get("pitch_deg", 0.0)) * \
            (1.0 if float(dk["omega"]) >= 0 else -1.0)
        parts.append(("disk", dk, rr, th, ke, jit))
    pools: dict = {}            # pool key -> list of (disk part index, slot)
    for q, part in enumerate(parts):
        key = part[1].get("pool", ("own", q))
        used = pools.setdefault(key, [])
        slot = part[1].get("slot")
        if slot is None:
            slot = max((s_ + len(parts[p_][2]) for p_, s_ in used), default=0)
        used.append((q, int(slot)))
    pool_free = {}
    frng = np.random.default_rng([seed, 7])        # its own stream: the other parts stay as they were
    for key, used in pools.items():
        size = max(s_ + len(parts[p_][2]) for p_, s_ in used)
        always = len(used) == 1 and used[0][1] == 0 and "t_on_min" not in parts[used[0][0]][1] \
            and "t_off_min" not in parts[used[0][0]][1]
        if always:
            pool_free[key] = None
            continue
        c0 = frng.uniform(0, 1, (size, 2)) * L
        for _ in range(1000):
            bad = np.zeros(size, bool)
            for dk in disks:
                dd = min_image(c0 - np.asarray(dk["centre"], float), L)
                bad |= np.hypot(dd[:, 0], dd[:, 1]) < dk["radius"] + length
            if not bad.any():
                break
            c0[bad] = frng.uniform(0, 1, (int(bad.sum()), 2)) * L
        pool_free[key] = (c0, frng.uniform(0, 2 * math.pi, size),
                          np.where(frng.random(size) < 0.5, 1, -1).astype(np.int8))
    disk_parts = len(parts)
    for sd in streams:
        rows, per = int(sd["rows"]), int(sd["per_row"])
        u = np.array([math.cos(sd["angle"]), math.sin(sd["angle"])])
        v = np.array([-u[1], u[0]])
        a, b = np.meshgrid(np.arange(per), np.arange(rows), indexing="ij")
        c0 = np.asarray(sd["origin"], float) + (a.ravel() * length)[:, None] * u + (b.ravel() * width)[:, None] * v
        parts.append(("stream", sd, c0, u))
    for jd in jams:
        R, c = float(jd["radius"]), np.asarray(jd["centre"], float)
        g = np.arange(-R, R + 1e-9, max(width, 0.5 * length))
        gx, gy = np.meshgrid(g, g)
        cc = np.stack([gx.ravel(), gy.ravel()], 1)
        cc = cc[np.hypot(cc[:, 0], cc[:, 1]) <= R - 0.5 * length]
        # rows of cells along random directions per 2.5 µm patch: a dense, disordered (jammed) packing
        ang = rng.uniform(0, math.pi, len(cc))
        u = np.stack([np.cos(ang), np.sin(ang)], -1)
        keep = np.ones(len(cc), bool)
        for q in range(len(cc)):          # drop cells whose axes would cross an earlier one closer than W
            if keep[q]:
                d = np.hypot(*(cc[q + 1:] - cc[q]).T)
                keep[q + 1:] &= d >= 0.5 * length
        cc, u = cc[keep], u[keep]
        ke = np.where(rng.random(len(cc)) < 0.5, 1, -1).astype(np.int8)
        parts.append(("jam", jd, c + cc, u, ke))
    if gas:
        c0 = rng.uniform(0, 1, (gas, 2)) * L
        if gas_avoids_disks and disks:
            for _ in range(1000):
                bad = np.zeros(gas, bool)
                for dk in disks:
                    dd = min_image(c0 - np.asarray(dk["centre"], float), L)
                    bad |= np.hypot(dd[:, 0], dd[:, 1]) < dk["radius"] + length
                if not bad.any():
                    break
                c0[bad] = rng.uniform(0, 1, (int(bad.sum()), 2)) * L
        ang = rng.uniform(0, 2 * math.pi, gas)
        ke = np.where(rng.random(gas) < 0.5, 1, -1).astype(np.int8)
        parts.append(("gas", None, c0, ang, ke))
    for f in range(n_frames):
        t_s = t0_s + f * dt_s
        tm = t_s / 60.0
        P_, K_, S_, E_, V_ = [], [], [], [], []
        disk_out = {}
        for qi, part in enumerate(parts):
            if part[0] == "disk":
                _, dk, rr, th, ke, jit = part
                w = float(dk["omega"])
                sgn = 1.0 if w >= 0 else -1.0
                # particle 0 of a k_e = +1 cell leads (largest angle in the sense of motion)
                v_const = dk.get("speed")          # None: rigid rotation; a number: every cell at that speed
                wr = sgn * v_const / rr if v_const is not None else np.full(len(rr), w)
                ang = th[:, None] + (wr * tm)[:, None] + sgn * (-j[None, :]) * (l0 / rr[:, None]) * ke[:, None]
                c = np.asarray(dk["centre"], float)
                pos = c + rr[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
                tang = sgn * np.stack([-np.sin(ang), np.cos(ang)], -1)
                if jit.any():
                    cc = pos.mean(1, keepdims=True)
                    co, si = np.cos(jit)[:, None], np.sin(jit)[:, None]
                    q = pos - cc
                    pos = cc + np.stack([co * q[..., 0] - si * q[..., 1], si * q[..., 0] + co * q[..., 1]], -1)
                    tang = np.stack([co * tang[..., 0] - si * tang[..., 1], si * tang[..., 0] + co * tang[..., 1]], -1)
                spd = np.repeat((np.abs(wr) * rr)[:, None], N, 1)
                if speed_noise:
                    spd = spd * np.clip(1 + speed_noise * rng.standard_normal(spd.shape), 0, None)
                disk_out[qi] = (pos, ke, spd, spd[..., None] * tang,
                                np.repeat((1e-18 * np.clip(1 - rr / dk["radius"], 0, None))[:, None], N - 1, 1))
                if qi == disk_parts - 1:
                    for key, used in pools.items():
                        out = _pool_frame(key, used, parts, disk_out, pool_free[key], tm, gas_speed, j, l0, N,
                                          background_strain_J)
                        for lst, arr in zip((P_, K_, S_, V_, E_), out):
                            lst.append(arr)
            elif part[0] == "stream":
                _, sd, c0, u = part
                c = c0 + sd["speed"] * tm * u
                pos = c[:, None, :] - (j * l0)[None, :, None] * u     # particle 0 in front
                P_.append(pos)
                K_.append(np.ones(len(c), np.int8))
                S_.append(np.full((len(c), N), float(sd["speed"])))
                V_.append(np.broadcast_to(float(sd["speed"]) * u, (len(c), N, 2)))
                E_.append(np.full((len(c), N - 1), background_strain_J))
            elif part[0] == "jam":
                _, jd, c0, u, ke = part
                pos = c0[:, None, :] - (j * l0)[None, :, None] * u[:, None, :]
                P_.append(pos)
                K_.append(ke)
                S_.append(np.full((len(c0), N), float(jd.get("speed", 0.5))))
                V_.append(np.repeat((float(jd.get("speed", 0.5)) * ke[:, None] * u)[:, None, :], N, 1))
                E_.append(np.full((len(c0), N - 1), background_strain_J))
            else:
                _, _, c0, ang, ke = part
                u = np.stack([np.cos(ang), np.sin(ang)], -1)
                c = c0 + gas_speed * tm * u
                pos = c[:, None, :] - (j * l0)[None, :, None] * u[:, None, :] * ke[:, None, None].astype(float)
                P_.append(pos)
                K_.append(ke)
                S_.append(np.full((len(c), N), float(gas_speed)))
                V_.append(np.repeat((gas_speed * u)[:, None, :], N, 1))
                E_.append(np.full((len(c), N - 1), background_strain_J))
        pos = np.concatenate(P_) if P_ else np.zeros((0, N, 2))
        pos = pos - np.floor(pos[:, :1] / L) * L
        vel = (np.concatenate(V_).astype(np.float32) if V_ else np.zeros((0, N, 2), np.float32)) if velocity else None
        yield Frame(time_s=t_s, step=f, box=(float(L[0]), float(L[1])), width_um=width, positions=pos,
                    particle_velocity=vel,
                    engine_direction=np.concatenate(K_).astype(np.int8),
                    particle_speed=np.concatenate(S_).astype(np.float32),
                    segment_strain=np.concatenate(E_) if strain else None, meta={"name": "synthetic"})


def _pool_frame(key, used, parts, disk_out, free, tm, gas_speed, j, l0, N, strain0=0.0):
    """A pool's cells at time tm (min): the active disks' cells in their slots, the other slots free cells."""
    if free is None:
        return disk_out[used[0][0]]
    c0, ang, ke = free
    u = np.stack([np.cos(ang), np.sin(ang)], -1)
    c = c0 + gas_speed * tm * u
    pos = c[:, None, :] - (j * l0)[None, :, None] * u[:, None, :] * ke[:, None, None].astype(float)
    n = len(c0)
    out = [pos, ke.copy(), np.full((n, N), float(gas_speed)), np.repeat((gas_speed * u)[:, None, :], N, 1),
           np.full((n, N - 1), strain0)]
    for q, slot in used:
        dk = parts[q][1]
        if dk.get("t_on_min", -math.inf) <= tm < dk.get("t_off_min", math.inf):
            for arr, val in zip(out, disk_out[q]):
                arr[slot:slot + len(val)] = val
    return out


def write_synthetic(path: str, v_b: float = 4.0, scene: dict | None = None, **kw) -> str:
    """Write synthetic_frames(**kw) to a GSD trajectory at path. scene: sections stored with it besides "cell"
    (e.g. {"guiding": {"kind": "active"}} to stand for an active-following run)."""
    from ..io.trajectory import TrajectoryWriter
    N = kw.get("N", 8)
    scene = {**(scene or {}), "name": "synthetic",
             "cell": {"particles": N, "width_um": kw.get("width", 0.5), "speed_um_per_min": v_b}}
    with TrajectoryWriter(path, scene) as w:
        for fr in synthetic_frames(**kw):
            w.append(fr)
    return path
