"""Intervals of success rates that stay honest at 0 and at 1: the exact binomial interval and the interval
clustered by seed that every study reports."""
from __future__ import annotations

import numpy as np


def clopper_pearson(k: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) binomial interval of k successes in n trials: honest at k = 0 (upper
    bound 1 - (alpha/2)^(1/n), e.g. 0/500 -> [0, 0.0074]) and at k = n."""
    from scipy.stats import beta
    if isinstance(k, bool) or isinstance(n, bool) or int(k) != k or int(n) != n:
        raise TypeError(f"k and n must be integers, got k={k!r}, n={n!r}")
    k, n = int(k), int(n)
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not 0 <= k <= n:
        raise ValueError(f"k must be in [0, n = {n}], got {k}")
    if not 0 < conf < 1:
        raise ValueError(f"conf must be in (0, 1), got {conf!r}")
    a = 1.0 - conf
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def seed_clustered_ci(M, conf: float = 0.95) -> tuple[float, float]:
    """Interval of the success rate clustered by seed, from M (seeds x episodes, 0/1): the Student t
    interval over the seed means (seeds - 1 degrees of freedom) clipped to [0, 1], widened to contain
    the pooled Clopper-Pearson interval, so that it is honest where every seed mean is 0 or 1 (the t
    interval then has width 0). Unlike a percentile bootstrap over seeds it can leave the seed means'
    hull. One seed: the pooled Clopper-Pearson interval."""
    from scipy.stats import t as student_t
    M = np.asarray(M, float)
    if M.ndim != 2 or M.size == 0:
        raise ValueError(f"M must be a non-empty (seeds, episodes) array, got shape {M.shape}")
    if not np.isin(M, (0.0, 1.0)).all():
        raise ValueError("M must hold 0/1 episode outcomes")
    lo, hi = clopper_pearson(int(M.sum()), M.size, conf)
    S = M.shape[0]
    if S >= 2:
        means = M.mean(axis=1)
        half = float(student_t.ppf(0.5 + conf / 2, S - 1)) * float(means.std(ddof=1)) / np.sqrt(S)
        lo = min(lo, max(0.0, float(means.mean()) - half))
        hi = max(hi, min(1.0, float(means.mean()) + half))
    return lo, hi
