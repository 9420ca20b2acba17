"""The Student-t quantile, in NumPy: what every interval of pamid multiplies its standard error
by (:func:`pamid._inference.t_critical`).

Written here rather than taken from SciPy so that a fit does not import SciPy: importing
``scipy.special`` cost a one-muscle ``pamid fit`` 0.1-0.15 s of its ~1.1 s
(benchmarks/README.md, "A fit without SciPy, and pandas beside the parse"). The tests hold
it to ``scipy.special.stdtrit`` to 2e-13 over ν = 1 … 10¹² and levels 0.2 … 0.99999
(tests/test_distributions.py).

The method, for the upper quantile t of probability q > ½ with ν degrees of freedom:

- ν ≥ :data:`EXPANSION_DOF`: the Cornish–Fisher expansion of t in the normal quantile z
  (Abramowitz & Stegun 26.7.5, four terms), within rounding of the exact value there.
- Below: Newton's method on the upper tail P(T > t) = ½·I_x(ν/2, ½), x = ν/(ν + t²)
  (Abramowitz & Stegun 26.7.1, the tail as a regularized incomplete beta function), from
  the expansion (exact for ν = 1 and 2). The tail is convex in t > 0 and t ≥ z: the
  iterates are kept at or above z, and after the first step they approach t from below.
- I_x(a, b) by its continued fraction (DLMF 8.17.22), evaluated by the modified Lentz
  method (Thompson & Barnett 1986), on the side of x where it converges
  (I_x(a, b) = 1 − I_{1−x}(b, a) on the other, DLMF 8.17.4); log B(a, ½) from
  ``math.lgamma`` for small a and from Stirling's series (DLMF 5.11.1) term by term for
  large a, where the difference of two large log-gammas would lose digits.
"""

from __future__ import annotations

import math

import numpy as np

#: Degrees of freedom from which the four-term expansion alone is the quantile: at ν = 3,000
#: it is within 2e-15 of SciPy's ``stdtrit`` for every q up to 0.999995 (1.5e-10 at ν = 300).
EXPANSION_DOF = 3000.0
#: Below this a, log B(a, ½) comes from ``math.lgamma``; above it from Stirling's series,
#: whose first omitted term is below 1e-16 there.
_LGAMMA_BELOW = 30.0
#: Stirling's series of log Γ(s): the coefficients B_2k / (2k(2k − 1)), k = 1 … 4.
_STIRLING = (1.0 / 12.0, -1.0 / 360.0, 1.0 / 1260.0, -1.0 / 1680.0)
#: Newton stops for a value once its step is below this fraction of it; the continued
#: fraction once its last factor is within this of 1.
_NEWTON_RTOL = 1e-13
_FRACTION_RTOL = 1e-15
_TINY = 1e-300
#: Quantiles computed before, by (ν, q): a fit asks for the same one for each kind of
#: interval (each Newton solve is 1-2 ms). Emptied when it would pass :data:`_KNOWN_MAX`.
_KNOWN: dict[tuple[float, float], float] = {}
_KNOWN_MAX = 65536


def t_upper_quantile(dof, q: float) -> np.ndarray:
    """The t with P(T ≤ t) = ``q`` (½ ≤ q < 1) for ``dof`` degrees of freedom (an array of
    values ≥ 1, ``inf`` for the normal quantile; NaN stays NaN). Returns an array of
    ``dof``'s shape; each distinct ``dof`` is computed once."""
    from statistics import NormalDist  # Wichura's AS 241, in the standard library

    dof = np.asarray(dof, dtype=np.float64)
    if not 0.5 <= q < 1.0:
        raise ValueError(f"the quantile's probability must be in [0.5, 1), got {q}")
    flat = dof.reshape(-1)
    if flat.size and (flat == flat[0]).all():  # one ν, known already (the usual call)
        known = _KNOWN.get((float(flat[0]), q))
        if known is not None:
            return np.full(dof.shape, known)
    out = np.full(dof.shape, np.nan)
    finite = ~np.isnan(dof)
    if not finite.any():
        return out
    values, where = np.unique(dof[finite], return_inverse=True)
    if q == 0.5:
        out[finite] = 0.0
        return out
    t = np.array([_KNOWN.get((v, q), np.nan) for v in values.tolist()])
    new = np.isnan(t)
    if new.any():
        z = NormalDist().inv_cdf(q)
        nu = values[new]
        fresh = _expansion(nu, z, q)
        small = nu < EXPANSION_DOF
        if small.any():
            fresh[small] = _newton(nu[small], q, z, fresh[small])
        t[new] = fresh
        if len(_KNOWN) + int(new.sum()) > _KNOWN_MAX:
            _KNOWN.clear()
        _KNOWN.update(zip(((v, q) for v in nu.tolist()), fresh.tolist()))
    out[finite] = t[where.reshape(-1)]
    return out


def _expansion(nu: np.ndarray, z: float, q: float) -> np.ndarray:
    """Abramowitz & Stegun 26.7.5 (the normal quantile where ν is infinite), and the exact
    quantiles of ν = 1 (Cauchy) and ν = 2 as starts for Newton there."""
    g = ((z**3 + z) / 4.0,
         (5 * z**5 + 16 * z**3 + 3 * z) / 96.0,
         (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384.0,
         (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / 92160.0)
    with np.errstate(divide="ignore"):
        inv = 1.0 / nu
    t = z + inv * (g[0] + inv * (g[1] + inv * (g[2] + inv * g[3])))
    t = np.where(nu == 1.0, math.tan(math.pi * (q - 0.5)), t)
    t = np.where(nu == 2.0, (2.0 * q - 1.0) / math.sqrt(2.0 * q * (1.0 - q)), t)
    return np.maximum(t, z)


def _newton(nu: np.ndarray, q: float, z: float, t: np.ndarray) -> np.ndarray:
    """Newton's method on the upper tail, from ``t``; only values not yet converged are
    iterated."""
    alpha = 1.0 - q
    t = t.copy()
    active = np.arange(t.size)
    for _ in range(100):
        ta, na = t[active], nu[active]
        tail, density = _tail_and_density(ta, na)
        step = (tail - alpha) / density
        new = np.maximum(ta + step, z)
        t[active] = new
        active = active[np.abs(new - ta) > _NEWTON_RTOL * ta]
        if active.size == 0:
            break
    return t


def _tail_and_density(t: np.ndarray, nu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """P(T > t) and the density at t > 0."""
    a, b = nu / 2.0, 0.5
    log_beta = _log_beta_half(a)
    log_x = -np.log1p(t * t / nu)  # x = ν / (ν + t²)
    log_y = 2.0 * np.log(t) - np.log(nu + t * t)  # 1 − x, without the cancellation
    log_front = a * log_x + b * log_y - log_beta  # log(x^a (1 − x)^b / B(a, b))
    tail = np.empty_like(t)
    direct = np.exp(log_x) < (a + 1.0) / (a + b + 2.0)
    if direct.any():
        s = direct
        tail[s] = 0.5 * np.exp(log_front[s]) / (a[s] * _fraction(a[s], b, np.exp(log_x[s])))
    if not direct.all():
        s = ~direct
        tail[s] = 0.5 - 0.5 * np.exp(log_front[s]) / (b * _fraction(b, a[s], np.exp(log_y[s])))
    density = np.exp(-log_beta - 0.5 * np.log(nu) - (nu + 1.0) / 2.0 * np.log1p(t * t / nu))
    return tail, density


def _fraction(a, b, x) -> np.ndarray:
    """The denominator 1 + d₁/(1 + d₂/(1 + …)) of DLMF 8.17.22, so that
    I_x(a, b) = x^a (1 − x)^b / (a·B(a, b)·fraction); modified Lentz."""
    f = np.ones_like(x)
    c = np.ones_like(x)
    d = np.zeros_like(x)
    m = 0
    for j in range(1, 2000):
        if j % 2:  # d_{2m+1}
            dj = -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))
            m += 1
        else:  # d_{2m}
            dj = m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m))
        d = 1.0 + dj * d
        d = 1.0 / np.where(np.abs(d) < _TINY, _TINY, d)
        c = 1.0 + dj / c
        c = np.where(np.abs(c) < _TINY, _TINY, c)
        delta = c * d
        f = f * delta
        if np.all(np.abs(delta - 1.0) <= _FRACTION_RTOL):
            break
    return f


def _log_beta_half(a: np.ndarray) -> np.ndarray:
    """log B(a, ½) = log Γ(a) + log Γ(½) − log Γ(a + ½)."""
    out = np.empty_like(a)
    small = a < _LGAMMA_BELOW
    for i in np.flatnonzero(small):  # few values: at most one per distinct dof below 60
        out[i] = math.lgamma(a[i]) - math.lgamma(a[i] + 0.5)
    s = a[~small]
    if s.size:
        # Stirling's series of log Γ(s) − log Γ(s + ½), its leading terms combined exactly:
        # (s − ½)·log s − s − (s·log(s + ½) − s − ½) = −½·log s + ½ − s·log1p(1/(2s))
        diff = -0.5 * np.log(s) + (0.5 - s * np.log1p(0.5 / s))
        for k, c in enumerate(_STIRLING):
            power = 2 * k + 1
            diff = diff + c * (s**-power - (s + 0.5) ** -power)
        out[~small] = diff
    return out + 0.5 * math.log(math.pi)


def normal_upper_tail(z) -> np.ndarray:
    """P(Z > z) for a standard normal Z, ½·erfc(z/√2) (``math.erfc``, elementwise; accurate
    in the far tail, where 1 − Φ(z) would round to 0). NaN stays NaN."""
    z = np.asarray(z, dtype=np.float64)
    half = [0.5 * math.erfc(x) for x in (z / math.sqrt(2.0)).reshape(-1).tolist()]
    return np.array(half, dtype=np.float64).reshape(z.shape)
