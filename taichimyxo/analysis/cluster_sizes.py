"""The cluster-size distribution (clusters of touching cells, clusters.py) with the fit experimental groups make
(Peruani et al. 2012 on Myxococcus: P(s) ∝ s^-α exp(-s / s_c)), against an exponential.

Both models are discrete, for s_min <= s <= s_max (s_max: the number of cells), fitted by maximum likelihood to the
number of clusters of each size pooled over frames: power law with cut-off P(s) ∝ s^-α e^{-λ s} (s_c = 1/λ;
λ = 0 is a pure power law) and exponential P(s) ∝ e^{-λ s}, which is the first with α = 0; so the likelihood ratio
2 (ln L_pl - ln L_exp) is χ² with one degree of freedom when the exponential holds (``p_exponential``), and the power
law with cut-off is preferred when p < 0.05. The exponent's 95 % interval is a percentile bootstrap: resampling whole
frames in moving blocks of about n_frames^(1/3) consecutive frames (clusters in one frame, and in neighbouring frames,
are not independent), or resampling clusters when there is one frame. freud.cluster.Cluster finds the same clusters
(tests/test_measures.py) but the contact clusters stay in clusters.py (its labels and order are fixed)."""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2

SIZE_DEFAULTS = dict(s_min=1, n_boot=200, seed=0, alpha_bounds=(-3.0, 6.0), lam_max=5.0)


class _Model:
    """P(s) ∝ s^-alpha e^{-lam s} on s_min..s_max and the counts' sufficient statistics (N, Σ n ln s, Σ n s):
    the negative log-likelihood is convex in (alpha, lam) (an exponential family), so Newton steps converge."""

    def __init__(self, s, n, s_min, s_max):
        self.t = np.array([(n * np.log(s)).sum(), (n * s).sum()])
        self.N = float(n.sum())
        sg = np.arange(s_min, s_max + 1, dtype=float)
        self.T = np.stack([np.log(sg), sg])           # (2, grid)

    def nll(self, x, derivs=False):
        lz = -x @ self.T
        m = lz.max()
        e = np.exp(lz - m)
        z = e.sum()
        f = float(x @ self.t + self.N * (m + np.log(z)))
        if not derivs:
            return f
        p = e / z
        mean = self.T @ p
        cov = (self.T * p) @ self.T.T - np.outer(mean, mean)
        return f, self.t - self.N * mean, self.N * cov

    def fit(self, x, lo, hi, free=(True, True), iters=100):
        """Projected Newton with backtracking within the bounds lo..hi; free: which of (alpha, lam) vary."""
        x = np.clip(np.asarray(x, float), lo, hi)
        fr = np.array(free)
        f, g, H = self.nll(x, True)
        for _ in range(iters):
            act = fr & ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))   # variables held at a bound
            if not act.any():
                break
            d = np.zeros(2)
            Ha = H[np.ix_(act, act)] + 1e-12 * np.eye(int(act.sum()))
            d[act] = -np.linalg.solve(Ha, g[act])
            t = 1.0
            while True:
                xn = np.clip(x + t * d, lo, hi)
                fn = self.nll(xn)
                if fn <= f + 1e-4 * g @ (xn - x) or t < 1e-12:
                    break
                t *= 0.5
            done = np.abs(xn - x).max() < 1e-10 or abs(f - fn) < 1e-12 * max(1.0, abs(f))
            x = xn
            f, g, H = self.nll(x, True)
            if done:
                break
        return x, f


def fit_sizes(counts: np.ndarray, s_min: int = 1, s_max: int | None = None, **kw) -> dict:
    """Maximum-likelihood fits of the counts (counts[s] = clusters of size s) for s >= s_min. Returns alpha, s_cut,
    log-likelihoods, AIC, the likelihood-ratio p of the exponential and the preferred model."""
    P = dict(SIZE_DEFAULTS, **kw)
    counts = np.asarray(counts, float)
    s_max = int(s_max or len(counts) - 1)
    s = np.nonzero(counts[: s_max + 1])[0]
    s = s[s >= s_min]
    n = counts[s]
    out = dict(n_clusters=int(n.sum()), s_min=s_min, s_max=s_max, alpha=None, s_cut=None, lam_exponential=None,
               loglik_power_law_cutoff=None, loglik_exponential=None, p_exponential=None, preferred=None)
    if len(s) < 2:
        return out
    M = _Model(s.astype(float), n, s_min, s_max)
    lo = np.array([P["alpha_bounds"][0], 0.0])
    hi = np.array([P["alpha_bounds"][1], P["lam_max"]])
    x0 = [1.0, 1.0 / max(float(s.mean()), 1.0)]
    xp, fp = M.fit(x0, lo, hi)
    xe, fe = M.fit([0.0, x0[1]], lo, hi, free=(False, True))
    ll_pl, ll_ex = -fp, -fe
    lr = max(0.0, 2.0 * (ll_pl - ll_ex))
    p = float(chi2.sf(lr, 1))
    out.update(alpha=float(xp[0]), s_cut=float(1.0 / xp[1]) if xp[1] > 0 else None,
               lam_exponential=float(xe[1]), loglik_power_law_cutoff=ll_pl, loglik_exponential=ll_ex,
               aic_power_law_cutoff=4.0 - 2 * ll_pl, aic_exponential=2.0 - 2 * ll_ex, likelihood_ratio=lr,
               p_exponential=p, preferred="power law with cut-off" if p < 0.05 else "exponential")
    return out


def size_distribution(per_frame_sizes, n_cells: int | None = None, **kw) -> dict:
    """The pooled distribution of the frames' cluster sizes (list of int arrays, one per frame: every cluster, single
    cells included), its fits (fit_sizes) and the bootstrap 95 % interval of the exponent."""
    P = dict(SIZE_DEFAULTS, **kw)
    frames = [np.asarray(f, int) for f in per_frame_sizes]
    s_max = int(n_cells or max((f.max() for f in frames if len(f)), default=1))
    H = np.array([np.bincount(f, minlength=s_max + 1)[: s_max + 1] for f in frames], float)
    tot = H.sum(0)
    fit = fit_sizes(tot, P["s_min"], s_max, alpha_bounds=P["alpha_bounds"], lam_max=P["lam_max"])
    rng = np.random.default_rng(P["seed"])
    boot = []
    if fit["alpha"] is not None and P["n_boot"] > 0:
        nf = len(frames)
        for _ in range(P["n_boot"]):
            if nf >= 2:
                b = max(1, int(round(nf ** (1.0 / 3.0))))
                starts = rng.integers(0, nf - b + 1, size=int(np.ceil(nf / b)))
                idx = (starts[:, None] + np.arange(b)[None, :]).reshape(-1)[:nf]
                c = H[idx].sum(0)
            else:
                c = rng.multinomial(int(tot.sum()), tot / tot.sum()).astype(float)
            a = fit_sizes(c, P["s_min"], s_max, alpha_bounds=P["alpha_bounds"], lam_max=P["lam_max"])["alpha"]
            if a is not None:
                boot.append(a)
    ci = [float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))] if len(boot) >= 20 else None
    nz = np.nonzero(tot)[0]
    return dict(fit, alpha_ci95=ci, n_boot=len(boot), n_frames=len(frames),
                sizes=nz.tolist(), counts=tot[nz].astype(int).tolist(),
                note="clusters of touching cells, pooled over frames; P(s) ∝ s^-alpha exp(-s/s_cut) against "
                     "exp(-lam s) by likelihood ratio; alpha_ci95: block bootstrap over frames")
