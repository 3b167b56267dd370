"""Data with known answers for the experimental measures (defects, cluster sizes, correlations, MSD): used by
tests/test_measures.py and benchmarks/measures.py."""
from __future__ import annotations

import numpy as np


def defect_rods(box, defects, n_rods=20000, noise_deg=0.0, seed=0, shift=(0.0, 0.0), psi0=0.0):
    """Rod midpoints (n, 2) and unit directions (n, 2) sampling the director ψ(r) = psi0 + Σ_k q_k atan2(r - r_k),
    defects = [(x, y, q), ...] with Σ q = 0 (so the field is nearly continuous across the box edge), plus Gaussian
    angular noise of SD noise_deg; the whole pattern is then translated by shift (periodically), as are the
    returned true positions. Returns (mid, dirs, true positions (k, 2), charges (k,))."""
    rng = np.random.default_rng(seed)
    L = np.asarray(box, float)
    p = rng.random((n_rods, 2)) * L
    psi = np.full(n_rods, float(psi0))
    for x, y, q in defects:
        psi += q * np.arctan2(p[:, 1] - y, p[:, 0] - x)
    psi += np.deg2rad(noise_deg) * rng.standard_normal(n_rods)
    d = np.stack([np.cos(psi), np.sin(psi)], axis=1)
    s = np.asarray(shift, float)
    true = np.mod(np.array([[x, y] for x, y, _ in defects], float).reshape(-1, 2) + s, L)
    return np.mod(p + s, L), d, true, np.array([q for *_, q in defects], float)


def gaussian_field(shape, h, ell, seed=0, n=1):
    """n independent periodic Gaussian random fields on a grid (shape, spacing h µm) with covariance
    exp(-r² / (2 ell²)) and unit variance (FFT filter: exact on the periodic grid up to aliasing). (n, *shape)."""
    rng = np.random.default_rng(seed)
    kx = 2 * np.pi * np.fft.fftfreq(shape[0], h)
    ky = 2 * np.pi * np.fft.fftfreq(shape[1], h)
    k2 = kx[:, None] ** 2 + ky[None, :] ** 2
    amp = np.sqrt(np.exp(-0.5 * k2 * ell * ell))       # square root of the spectrum of the Gaussian covariance
    out = []
    for _ in range(n):
        f = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal(shape)) * amp))
        out.append(f / f.std())
    return np.array(out)


def sample_grid(fields, h, points):
    """Values (n_fields, n_points) of grid fields at points (nearest node, node (i, j) at (i h, j h))."""
    shape = fields.shape[1:]
    i = np.rint(points[:, 0] / h).astype(int) % shape[0]
    j = np.rint(points[:, 1] / h).astype(int) % shape[1]
    return fields[:, i, j]


def power_law_cutoff_sizes(n, alpha, s_cut, s_min=1, s_max=100000, seed=0):
    """n cluster sizes drawn from P(s) ∝ s^-alpha exp(-s / s_cut), s_min <= s <= s_max."""
    rng = np.random.default_rng(seed)
    s = np.arange(s_min, s_max + 1, dtype=float)
    lp = -alpha * np.log(s) - s / s_cut
    p = np.exp(lp - lp.max())
    return rng.choice(s.astype(int), size=n, p=p / p.sum())


def exponential_sizes(n, lam, s_min=1, seed=0):
    """n cluster sizes drawn from P(s) ∝ exp(-lam s), s >= s_min (geometric)."""
    rng = np.random.default_rng(seed)
    return s_min - 1 + rng.geometric(1.0 - np.exp(-lam), size=n)


def clusters_of_sizes(sizes, width=0.5, length=5.0, N=8, gap=3.0):
    """Cells (n, N, 2) in stacks of parallel touching rods W apart, one stack per size, stacks gap µm apart on a
    square lattice, and the box (Lx, Ly) that holds them periodically: contact clusters of exactly these sizes."""
    sizes = np.asarray(sizes, int)
    l0 = (length - width) / (N - 1)
    col = max(1, int(np.ceil(np.sqrt(len(sizes)))))
    pitch_x = length + gap
    pitch_y = sizes.max() * width + gap
    cells = []
    for k, s in enumerate(sizes):
        x0, y0 = (k % col) * pitch_x, (k // col) * pitch_y
        for r in range(s):
            xs = x0 + np.arange(N) * l0
            cells.append(np.stack([xs, np.full(N, y0 + r * width)], axis=1))
    box = (col * pitch_x, int(np.ceil(len(sizes) / col)) * pitch_y)
    return np.array(cells), box


def walkers(n_cells, n_frames, box, step_um, persistence=0.0, speed=0.0, seed=0):
    """Unwrapped centre tracks (n_frames, n_cells, 2): a random walk of SD step_um per frame and axis, plus motion
    at ``speed`` µm/frame along a heading that keeps direction (persistence 1: ballistic). Also the wrapped copy."""
    rng = np.random.default_rng(seed)
    x = np.zeros((n_frames, n_cells, 2))
    x[0] = rng.random((n_cells, 2)) * np.asarray(box, float)
    th = rng.uniform(0, 2 * np.pi, n_cells)
    for t in range(1, n_frames):
        if persistence < 1.0:
            th = th + np.sqrt(1.0 - persistence) * rng.standard_normal(n_cells)
        x[t] = x[t - 1] + step_um * rng.standard_normal((n_cells, 2)) + speed * np.stack([np.cos(th), np.sin(th)], 1)
    return x, np.mod(x, np.asarray(box, float))
