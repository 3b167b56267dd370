"""Per-frame cell geometry, in numpy.

Per cell: centre = mean of its particles (wrapped into the box); heading = k_e (p_0 - p_{N-1}) normalised (tail to
head); per-particle forward tangent = -k_e d p / d i (central differences along the chain); cell speed = mean of its
particle speeds (the logged, window-averaged speeds). Velocities are taken as speed x heading (not from finite
differences between frames: at one frame per minute an aggregate edge turns by up to ~1 rad between frames).
Particle velocities (``vel``, µm/min): the trajectory's windowed velocities where it stores them (particles/velocity),
else speed x forward tangent (a cell sliding along its own body), so that older files and frames without velocities
are analysed the same way."""
from __future__ import annotations

import numpy as np

from ..io.frame import Frame


class CellGeometry:
    """Per-frame cell geometry (all numpy)."""

    def __init__(self, fr: Frame):
        pos = np.asarray(fr.positions, float)
        self.L = np.asarray(fr.box, float)
        self.n, self.N = pos.shape[:2]
        self.W = float(fr.width_um)
        self.t_min = float(fr.time_s) / 60.0
        ke = np.where(np.asarray(fr.engine_direction).reshape(-1) >= 0, 1.0, -1.0)
        self.ke = ke
        cen_raw = pos.mean(axis=1)
        self.cen = np.mod(cen_raw, self.L)
        self.poff = pos - cen_raw[:, None, :]
        self.pos = pos
        h = ke[:, None] * (pos[:, 0] - pos[:, -1])
        hn = np.linalg.norm(h, axis=1)
        self.head = h / np.where(hn > 0, hn, 1.0)[:, None]
        if self.N > 1:
            g = -ke[:, None, None] * np.gradient(pos, axis=1)
            gn = np.linalg.norm(g, axis=2)
            self.ptan = g / np.where(gn > 0, gn, 1.0)[..., None]
            seg = np.linalg.norm(np.diff(pos, axis=1), axis=2)
            self.chain = float(np.median(seg.sum(1))) if self.n else 0.0
            self.l0 = self.chain / (self.N - 1)
        else:
            self.ptan = self.head[:, None, :].copy()
            self.chain, self.l0 = 0.0, 0.0
        self.cell_len = self.chain + self.W            # outline length L
        self.pspeed = np.asarray(fr.particle_speed, float).reshape(self.n, self.N)
        self.cspeed = self.pspeed.mean(axis=1)
        self.strain = None if fr.segment_strain is None else np.asarray(fr.segment_strain, float)
        # windowed particle velocities (µm/min) where the trajectory stores them: a rotation is fitted to vectors
        self.pvel = (None if getattr(fr, "particle_velocity", None) is None
                     else np.asarray(fr.particle_velocity, float).reshape(self.n, self.N, 2))
        self.vel = self.pvel if self.pvel is not None else self.pspeed[..., None] * self.ptan
        self.cvel = self.vel.mean(axis=1) if self.N else np.zeros((self.n, 2))
