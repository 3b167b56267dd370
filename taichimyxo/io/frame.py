"""A Frame: one snapshot of the population, plain numpy, handed from the simulator to writers.

Everything downstream of the simulator (renderer, trajectory writer, analysis) sees only Frames, never Taichi
fields. Coordinates are µm in a box [0, Lx) x [0, Ly) with the origin at the lower left and y pointing up.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..physics.geometry import min_image


@dataclass
class Frame:
    time_s: float                   # simulated time, s
    step: int                       # integration step number
    box: tuple[float, float]        # (Lx, Ly), µm, periodic
    width_um: float                 # cell width W, µm (capsule diameter)
    positions: np.ndarray           # (n_cells, N, 2) float64 µm; each chain unwrapped (consecutive particles are
                                    # minimum-image neighbours), particle 0 wrapped into the box
    engine_direction: np.ndarray    # (n_cells,) int8, +1: particle 0 is the head, -1: particle N-1 is the head
    particle_speed: np.ndarray      # (n_cells, N) float32, µm/min, averaged over docs/model.md's short window
    segment_strain: np.ndarray | None = None   # (n_cells, N-1) float64, J, or None when not computed
    particle_velocity: np.ndarray | None = None  # (n_cells, N, 2) float32 µm/min over the same window as the
                                                 # speed (its norm), or None where not recorded
    meta: dict = field(default_factory=dict)   # scene name etc., free-form

    @property
    def n_cells(self) -> int:
        return int(self.positions.shape[0])

    @property
    def particles_per_cell(self) -> int:
        return int(self.positions.shape[1])

    @property
    def segment_speed(self) -> np.ndarray:
        """(n_cells, N-1) µm/min: mean of the speeds of a segment's two particles (the paper's definition)."""
        s = self.particle_speed
        return 0.5 * (s[:, 1:] + s[:, :-1])

    @property
    def heads(self) -> np.ndarray:
        """(n_cells, 2) positions of the leading poles."""
        idx = np.where(self.engine_direction > 0, 0, self.particles_per_cell - 1)
        return self.positions[np.arange(self.n_cells), idx]

    @property
    def tails(self) -> np.ndarray:
        idx = np.where(self.engine_direction > 0, self.particles_per_cell - 1, 0)
        return self.positions[np.arange(self.n_cells), idx]

    def with_strain(self, W: float, k_c: float) -> "Frame":
        """This frame with its per-segment strain energy (J) computed from its positions (geometry.segment_strain,
        the numpy twin of the strain term; W µm, k_c pN/µm) where its run did not log it: a function of the positions
        alone. The frame itself where strain is already there."""
        if self.segment_strain is not None:
            return self
        from dataclasses import replace

        from ..physics.geometry import segment_strain
        return replace(self, segment_strain=segment_strain(self.positions, self.box, W, k_c) * 1e-18)


def unwrap_chains(pos: np.ndarray, box) -> np.ndarray:
    """Make each cell's chain continuous: particle 0 wrapped into the box, each next particle the minimum image of
    its predecessor. pos: (n_cells, N, 2)."""
    L = np.asarray(box, dtype=np.float64)
    p = np.asarray(pos, dtype=np.float64).copy()
    p[:, 0] = np.mod(p[:, 0], L)
    d = min_image(np.diff(np.asarray(pos, dtype=np.float64), axis=1), L)
    p[:, 1:] = p[:, :1] + np.cumsum(d, axis=1)
    return p
