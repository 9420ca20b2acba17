"""The bases in which an effect's constants enter a model: a covariate scaled to [−1, 1] and
Legendre polynomials of it (shared by the effect definitions, the residual's covariate test
and the static diagnosis)."""

from __future__ import annotations

import numpy as np

__all__ = ["legendre_basis", "scaled"]


def scaled(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Map [lo, hi] onto [−1, 1] (a constant covariate maps to 0)."""
    span = hi - lo
    if not np.isfinite(span) or span <= 0:
        return np.zeros_like(values, dtype=float)
    return 2.0 * (np.asarray(values, float) - lo) / span - 1.0


def legendre_basis(z, degree: int):
    """Legendre polynomials P1…P_degree of z (array module agnostic: NumPy or jax.numpy)."""
    cols = []
    p_prev, p = 1.0, z
    for k in range(1, degree + 1):
        cols.append(p)
        p_prev, p = p, ((2 * k + 1) * z * p - k * p_prev) / (k + 1)
    return cols
