"""Tests of a residual: is it white, and does it depend on a covariate?

All functions take NumPy arrays; a residual is grouped by muscle (or trial) and ordered in
time within each group.

* Runs test (Wald and Wolfowitz, 1940): the number of runs of equal sign in the
  time-ordered residual against its mean and variance for independent signs; few runs mean
  a slowly varying residual.
* Ljung–Box (1978): Q = n(n+2)·Σ_k r_k²/(n−k) over the first ``lags`` autocorrelations,
  χ² with ``lags`` degrees of freedom under whiteness; summed over groups (independent
  groups add their Q and degrees of freedom). The pooled lag-1 autocorrelation is reported
  as the size of the effect.
* Effective sample size (:func:`effective_sample_size`): the n independent samples whose
  mean is as variable as that of the n samples of a dependent residual, n_eff = n/τ with
  τ = 1 + 2·Σ_k ρ_k the integrated autocorrelation time (Bayley and Hammersley, 1946;
  (1 + ρ)/(1 − ρ) for an AR(1) process). τ is summed over Sokal's self-consistent window,
  the fewest lags M with M ≥ 5·τ(M) (Madras and Sokal, 1988; as emcee's
  ``integrated_time``): a residual that is white noise plus a slow wander has a small lag-1
  autocorrelation but a long τ, which the AR(1) formula from ρ_1 would miss. The
  selection's BIC uses it (:mod:`pamid._diagnose._select`).
* Wilcoxon's signed-rank test (1945), one-sided (:func:`signed_rank_greater`): whether a
  candidate predicts held-out curves better than the current model, curve by curve (the
  selection's held-out check, :mod:`pamid._diagnose._select`).
* Covariate dependence: the residual regressed on Legendre polynomials P1…P3 of the
  covariate scaled to [−1, 1], and on their products with the direction of motion when it
  is known (so a loop that changes with the covariate shows too), against the mean alone
  within each group; an F test. Binned statistics (mean, RMSE, count per quantile bin) go
  into the report.
"""

from __future__ import annotations

import math

import numpy as np

from .._effects._basis import legendre_basis, scaled
from .._inference import normal_upper_tail, numerical_rank

__all__ = ["autocorrelation_time", "covariate_dependence", "effective_sample_size",
           "ljung_box", "runs_test", "scaled", "signed_rank_greater", "legendre_basis"]

# The p-values come from scipy.special's distribution functions, not from scipy.stats:
# importing scipy.stats takes 0.6 s (it builds every distribution's docstring), about a
# fifth of a warm ``pamid diagnose`` of a one-muscle file (benchmarks/README.md, latency.py).
# The functions are those scipy.stats itself evaluates: chi2.sf(q, k) = chdtrc(k, q),
# f.sf(f, d1, d2) = fdtrc(d1, d2, f); the normal tail norm.sf(z) is pamid's one
# (pamid._inference.normal_upper_tail, ½·erfc(z/√2), what scipy's ndtr(−z) computes).

#: A residual whose lag-1 autocorrelation is below this many of its standard errors (1/√n
#: for a white series: Bartlett, 1946) is taken as white by :func:`autocorrelation_time`
#: (τ = 1): a white residual estimates ρ_1 ≈ ±1/√n, and its n_eff stays n (the plain BIC).
RHO_STANDARD_ERRORS = 3.0
#: Sokal's window constant: τ is summed over the fewest lags M with M ≥ SOKAL_C·τ(M).
SOKAL_C = 5.0


def runs_test(residuals: list[np.ndarray]) -> dict:
    """Wald–Wolfowitz runs test on the signs, summed over groups (zeros dropped)."""
    runs = mean = var = 0.0
    n_total = 0
    for r in residuals:
        s = np.sign(np.asarray(r, float))
        s = s[s != 0]
        n1, n2 = int(np.sum(s > 0)), int(np.sum(s < 0))
        n = n1 + n2
        if n1 == 0 or n2 == 0:
            continue
        runs += 1 + int(np.sum(s[1:] != s[:-1]))
        mean += 2.0 * n1 * n2 / n + 1.0
        var += 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n**2 * (n - 1.0))
        n_total += n
    if var <= 0:
        return {"runs": runs, "expected": mean, "z": math.nan, "p_value": math.nan}
    z = (runs - mean) / math.sqrt(var)
    return {"runs": int(runs), "expected": mean, "z": z,
            "p_value": float(2.0 * normal_upper_tail(abs(z)))}


def ljung_box(residuals: list[np.ndarray], lags: int = 10) -> dict:
    """Ljung–Box Q over the first ``lags`` autocorrelations, summed over groups."""
    q, dof = 0.0, 0
    for r in residuals:
        r = np.asarray(r, float) - np.mean(r)
        n = len(r)
        h = min(lags, n - 2)
        denom = float(r @ r)
        if h < 1 or denom <= 0:
            continue
        acf = np.array([float(r[k:] @ r[:-k]) / denom for k in range(1, h + 1)])
        q += n * (n + 2.0) * float(np.sum(acf**2 / (n - np.arange(1, h + 1))))
        dof += h
    from scipy.special import chdtrc

    p = float(chdtrc(dof, q)) if dof else math.nan
    num, den = np.sum([_lag1_sums(r) for r in residuals], axis=0) if residuals else (0.0, 0.0)
    rho1 = float(num / den) if den > 0 else math.nan
    return {"q": q, "dof": dof, "lags": lags, "p_value": p, "lag1_autocorrelation": rho1}


def _lag1_sums(r: np.ndarray) -> tuple[float, float]:
    """Σ r_t·r_(t−1) and Σ r_t², of r less its mean."""
    r = np.asarray(r, float)
    if len(r) < 2:
        return 0.0, 0.0
    r = r - np.mean(r)
    return float(r[1:] @ r[:-1]), float(r @ r)


def autocorrelation_time(r: np.ndarray) -> tuple[float, float]:
    """(τ, ρ_1) of one group's time-ordered residual (its mean removed): the integrated
    autocorrelation time over Sokal's window (module text) and the lag-1 autocorrelation.

    τ = 1 where ρ_1 < :data:`RHO_STANDARD_ERRORS`/√n (white within its noise) and where the
    residual is constant; otherwise at least 1, and where no window up to n/2 lags is
    self-consistent (a series too short for its dependence) the sum up to n/2 lags.
    """
    r = np.asarray(r, float)
    n = len(r)
    num, den = _lag1_sums(r)
    if n < 3 or den <= 0:
        return 1.0, math.nan
    rho1 = num / den
    if rho1 < RHO_STANDARD_ERRORS / math.sqrt(n):
        return 1.0, rho1
    x = r - np.mean(r)
    size = 1 << (2 * n - 1).bit_length()  # zero-padded: the linear, not circular, sums
    f = np.fft.rfft(x, size)
    acf = np.fft.irfft(f * np.conj(f), size)[: n // 2 + 1]
    acf = acf / acf[0]
    taus = 2.0 * np.cumsum(acf) - 1.0  # τ(M) = 1 + 2·Σ_{k=1..M} ρ_k
    ok = np.flatnonzero(np.arange(len(taus)) >= SOKAL_C * taus)
    tau = taus[ok[0]] if len(ok) else taus[-1]
    return max(1.0, float(tau)), rho1


def effective_sample_size(n, tau):
    """n/τ per group (module text), at least 2; n itself where τ is 1 or unknown (NaN)."""
    n = np.asarray(n, float)
    tau = np.nan_to_num(np.asarray(tau, float), nan=1.0)
    return np.where(tau > 1.0, np.maximum(n / np.maximum(tau, 1.0), 2.0), n)


def _demean(values: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Subtract each group's mean (the within transformation: the same fit as one dummy
    column per group, without building them)."""
    _, idx = np.unique(groups, return_inverse=True)
    counts = np.bincount(idx)
    if values.ndim == 1:
        return values - (np.bincount(idx, values) / counts)[idx]
    means = np.stack([np.bincount(idx, c) / counts for c in values.T], axis=1)
    return values - means[idx]


def covariate_dependence(
    residual: np.ndarray,
    covariate: np.ndarray,
    groups: np.ndarray,
    direction: np.ndarray | None = None,
    *,
    degree: int = 3,
    n_bins: int = 5,
) -> dict:
    """F test of the residual's dependence on a covariate, with per-bin statistics.

    ``groups`` gives each sample's muscle; each muscle has its own mean in both the null and
    the alternative. With ``direction``, the alternative also has P_k(z)·direction, k = 0…3
    (P0·direction is the direction's own effect, which the ``direction`` covariate tests,
    so it is left out for every other covariate unless ``covariate`` is the direction).
    """
    r = np.asarray(residual, float)
    x = np.asarray(covariate, float)
    ok = np.isfinite(r) & np.isfinite(x)
    r, x, groups = r[ok], x[ok], np.asarray(groups)[ok]
    n_unique = len(np.unique(x))
    n_groups = len(np.unique(groups))
    z = scaled(x, float(np.min(x)), float(np.max(x))) if len(x) else x
    deg = min(degree, n_unique - 1)
    cols = list(legendre_basis(z, deg)) if deg >= 1 else []
    if direction is not None and deg >= 1:
        d = np.asarray(direction, float)[ok]
        cols += [c * d for c in legendre_basis(z, deg)]
    bins = _bins(r, x, n_bins)
    if not cols:
        return {"f": math.nan, "dof": [0, 0], "p_value": math.nan, "bins": bins}
    r0 = _demean(r, groups)
    alt = _demean(np.column_stack(cols), groups)
    rss0 = float(r0 @ r0)
    rss1 = _rss(alt, r0)
    df1 = int(numerical_rank(alt))  # pamid's one rank criterion
    df2 = len(r) - n_groups - df1
    if df1 <= 0 or df2 <= 0 or rss1 <= 0:
        return {"f": math.nan, "dof": [int(df1), int(df2)], "p_value": math.nan, "bins": bins}
    from scipy.special import fdtrc

    f = ((rss0 - rss1) / df1) / (rss1 / df2)
    return {"f": float(f), "dof": [int(df1), int(df2)],
            "p_value": float(fdtrc(df1, df2, f)), "bins": bins,
            "explained_fraction": float(1.0 - rss1 / rss0) if rss0 > 0 else 0.0}


def _rss(design: np.ndarray, r: np.ndarray) -> float:
    coef, *_ = np.linalg.lstsq(design, r, rcond=None)
    e = r - design @ coef
    return float(e @ e)


def _bins(r: np.ndarray, x: np.ndarray, n_bins: int) -> list[dict]:
    """Quantile bins of the covariate (distinct values when there are few)."""
    values = np.unique(x)
    if len(values) <= n_bins:
        edges = [(v, v) for v in values]
        masks = [x == v for v in values]
    else:
        q = np.quantile(x, np.linspace(0.0, 1.0, n_bins + 1))
        edges = list(zip(q[:-1], q[1:], strict=True))
        idx = np.clip(np.searchsorted(q, x, side="right") - 1, 0, n_bins - 1)
        masks = [idx == i for i in range(n_bins)]
    out = []
    for (lo, hi), m in zip(edges, masks, strict=True):
        if not np.any(m):
            continue
        out.append({"low": float(lo), "high": float(hi), "n": int(np.sum(m)),
                    "mean": float(np.mean(r[m])), "rmse": float(np.sqrt(np.mean(r[m] ** 2))),
                    "max_abs": float(np.max(np.abs(r[m])))})
    return out


#: Largest number of differences for which :func:`signed_rank_greater` uses the exact null
#: distribution of the statistic (without ties); above it, the normal approximation. The
#: same rule as ``scipy.stats.wilcoxon(method="auto")`` (scipy 1.18).
SIGNED_RANK_EXACT_MAX = 50
#: Largest number of differences with tied sizes for which the p-value is the exact
#: permutation test over every sign pattern (as scipy's "auto"; that case is left to
#: scipy.stats itself: tied SSE differences of held-out curves do not occur in practice).
SIGNED_RANK_PERMUTATION_MAX = 13


def _signed_rank_distribution(n: int) -> np.ndarray:
    """P(T⁺ = t), t = 0 … n(n+1)/2, for n differences without ties under the null: each
    rank k is positive with probability ½, so the distribution of n is that of n − 1 halved
    and shifted by k (scipy's recursion, the same arithmetic)."""
    c = np.ones(1, dtype=np.float64)
    for k in range(1, n + 1):
        prev = c
        c = np.zeros(k * (k + 1) // 2 + 1, dtype=np.float64)
        m = len(prev)
        c[:m] = prev * 0.5
        c[-m:] += prev * 0.5
    return c


def _average_ranks(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranks 1 … n of ``a`` with tied values given the mean of their ranks, and the size of
    every group of equal values."""
    order = np.argsort(a, kind="mergesort")
    sorted_a = a[order]
    first = np.r_[True, sorted_a[1:] != sorted_a[:-1]]
    starts = np.flatnonzero(first)
    sizes = np.diff(np.r_[starts, len(a)])
    mean_rank = starts + (sizes + 1) / 2.0  # 1-based mean rank of each group
    ranks = np.empty(len(a), dtype=np.float64)
    ranks[order] = np.repeat(mean_rank, sizes)
    return ranks, sizes


def signed_rank_greater(d) -> float:
    """Wilcoxon's signed-rank test (1945) that the differences ``d`` are centred above 0,
    one-sided: the p-value of T⁺, the sum of the ranks of |d| over the positive d.

    Zeros are dropped (Wilcoxon's rule). Without ties and with at most
    :data:`SIGNED_RANK_EXACT_MAX` differences, the exact null distribution; otherwise the
    normal approximation, E T⁺ = n(n+1)/4, Var T⁺ = (n(n+1)(2n+1) − Σ(t³ − t)/2)/24 with t
    the sizes of groups of tied |d| (no continuity correction). This is
    ``scipy.stats.wilcoxon(d, alternative="greater").pvalue`` (scipy 1.18, tested against it
    in tests/test_diagnose_residual.py), without importing scipy.stats. NaN without any
    difference.
    """
    d = np.asarray(d, dtype=np.float64)
    d = d[d != 0]
    n = len(d)
    if n == 0:
        return math.nan
    ranks, sizes = _average_ranks(np.abs(d))
    r_plus = float(np.sum((d > 0) * ranks))
    ties = bool(np.any(sizes > 1))
    if n <= SIGNED_RANK_EXACT_MAX and not ties:
        pmf = _signed_rank_distribution(n)
        k = int(np.floor(r_plus))
        # As scipy sums it: the upper tail directly where it is the smaller side.
        return float(pmf[k:].sum() if k <= n * (n + 1) / 4 else 1.0 - pmf[:k].sum())
    if n <= min(SIGNED_RANK_EXACT_MAX, SIGNED_RANK_PERMUTATION_MAX):
        from scipy import stats  # the rare case: scipy's own permutation test

        return float(stats.wilcoxon(d, alternative="greater").pvalue)
    mean = n * (n + 1.0) * 0.25
    var = n * (n + 1.0) * (2.0 * n + 1.0)
    se = math.sqrt((var - float(np.sum(sizes.astype(float) ** 3 - sizes)) / 2) / 24)
    return float(normal_upper_tail((r_plus - mean) / se))
