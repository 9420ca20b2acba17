"""Wald intervals: θ̂ ± t_{(1+level)/2, n−p}·se with se² = s²·diag((JᵀJ)⁻¹) (Bates & Watts 1988,
section 2.3; what Excel's regression add-in reports, and how Sárosi computed Table 3-1).
pamid's one Wald routine: fits, diagnosis refits, decays and the length study use it."""

from __future__ import annotations

import numpy as np

from ._covariance import residual_variance


def t_critical(dof, level: float = 0.95):
    """Two-sided Student-t quantile for ``level`` with ``dof`` degrees of freedom (NaN
    without degrees of freedom; ``inf`` gives the normal quantile). pamid's own quantile
    (:mod:`._distributions`), not SciPy's: a fit then does not import SciPy."""
    from ._distributions import t_upper_quantile

    dof = np.asarray(dof, float)
    return np.where(dof > 0, t_upper_quantile(np.maximum(dof, 1), 0.5 + level / 2), np.nan)


def wald_interval(value, se, dof, level: float = 0.95):
    """The Wald interval value ± t·se with the Student-t quantile for ``dof`` degrees of
    freedom (pamid's one Wald routine; broadcasts). Returns (lower, upper); NaN without
    degrees of freedom."""
    t = t_critical(dof, level)
    value, se = np.asarray(value, float), np.asarray(se, float)
    return value - t * se, value + t * se


def cut_at_bounds(lower, upper, bounds=(-np.inf, np.inf)):
    """An interval (``lower``, ``upper``) of a constant that physics keeps within ``bounds``
    (a slip weight ≥ 0, a wall thickness ≥ 0) cut at them: (lower, upper, cut), ``cut``
    True where either end moved. The true value lies within the bounds, so the cut
    interval covers it whenever the whole one does: the coverage is unchanged, and no end
    says the constant may be what physics forbids. NaN ends stay NaN. Broadcasts (arrays
    of ends and of bounds); scalars in, Python scalars out."""
    lo_b, hi_b = (np.asarray(b, dtype=np.float64) for b in bounds)
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    below, above = lower < lo_b, upper > hi_b
    out_lo, out_hi, cut = np.where(below, lo_b, lower), np.where(above, hi_b, upper), below | above
    if out_lo.ndim == 0 and out_hi.ndim == 0:
        return float(out_lo), float(out_hi), bool(cut)
    return out_lo, out_hi, cut


def wald(theta, jtj_inv, sse, n, level: float = 0.95):
    """Wald intervals of a least-squares fit: se² = s²·diag((JᵀJ)⁻¹), s² = SSE/(n − p), and
    :func:`wald_interval`. Returns (se, lower, upper, s2, dof)."""
    n_params = theta.shape[-1]
    dof = n - n_params
    s2 = residual_variance(sse, dof)
    with np.errstate(invalid="ignore"):  # undetermined constants: NaN, said in the message
        se = np.sqrt(s2[:, None] * np.diagonal(jtj_inv, axis1=-2, axis2=-1))
    lower, upper = wald_interval(theta, se, np.asarray(dof)[..., None], level)
    return se, lower, upper, s2, dof
