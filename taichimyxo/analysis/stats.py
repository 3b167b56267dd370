"""The two statistics the analysis needs: ordinary least squares and a binomial tail."""
from __future__ import annotations

import math

import numpy as np


def ols(x, y):
    """Ordinary least squares y = a + b x. Returns dict(slope, intercept, stderr, r2, n) (NaN where undefined)."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    n = len(x)
    out = dict(slope=float("nan"), intercept=float("nan"), stderr=float("nan"), r2=float("nan"), n=n)
    if n < 2:
        return out
    xm, ym = x.mean(), y.mean()
    sxx = float(((x - xm) ** 2).sum())
    if sxx <= 0:
        return out
    b = float(((x - xm) * (y - ym)).sum() / sxx)
    a = float(ym - b * xm)
    res = y - a - b * x
    ssr = float((res ** 2).sum())
    sst = float(((y - ym) ** 2).sum())
    out.update(slope=b, intercept=a, r2=(1.0 - ssr / sst) if sst > 0 else float("nan"))
    if n > 2:
        out["stderr"] = math.sqrt(ssr / (n - 2) / sxx)
    return out


def binom_tail(k: int, n: int, p: float) -> float:
    """P(X >= k) for X ~ Binomial(n, p)."""
    if k <= 0:
        return 1.0
    if k > n:
        return 0.0
    lg = [math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1) + i * math.log(p) + (n - i) * math.log1p(-p)
          for i in range(k, n + 1)]
    m = max(lg)
    return min(1.0, math.exp(m) * sum(math.exp(x - m) for x in lg))
