"""The one rank criterion of pamid's fits, and the constants a rank-deficient fit cannot pin.

A fit's constants are determined by the data when the Jacobian J of the weighted residuals
at the optimum has full column rank. The test, used by every fit (the generic statistics of
``_least_squares``, Sárosi's written-out ``sarosi_statistics``, the diagnosis refits of
``_diagnose/_static``): scale J's columns to unit length (the test does not depend on the
constants' units), and count the constants as determined when the smallest singular value
of the scaled J is above :data:`RANK_RTOL` times the largest.

Why 1e-7: the variance of a constant grows as 1/σ²; at σ_min/σ_max = 1e-7 the normal matrix
JᵀJ has lost 14 of its 16 digits (condition 1e14), so an interval computed from it is
rounding noise, while an exactly dependent J (a repeated column, a constant the model does
not see) gives σ_min/σ_max of rounding size, 1e-16 … 1e-12, far below. The written-out
Sárosi statistics factorise the equilibrated JᵀJ, whose smallest Cholesky pivot plays the
part of σ_min²: their threshold is :data:`RANK_RTOL` squared (``RANK_PIVOT``).

Which constants a rank-deficient fit cannot determine is read off the null direction of J:
the right singular vector of the smallest singular value of the scaled J. Moving the
constants along it changes no residual (to first order), and its largest components name
the constants that move most.
"""

from __future__ import annotations

import numpy as np

#: Smallest singular value of the column-scaled Jacobian, relative to its largest, for which
#: the constants count as determined by the data.
RANK_RTOL = 1e-7

#: The same criterion on the smallest Cholesky pivot of the equilibrated (unit-diagonal)
#: JᵀJ, whose pivots scale as the squared singular values of the column-scaled J.
RANK_PIVOT = RANK_RTOL**2

#: Components of the null direction at least this fraction of its largest name a constant.
NULL_SHARE = 0.3


def scaled_singular(jac):
    """Singular values (descending) and right singular vectors (rows) of ``jac`` (n × p)
    with its columns scaled to unit length, in NumPy; a zero column stays zero."""
    jac = np.asarray(jac, dtype=np.float64)
    norms = np.sqrt(np.sum(jac**2, axis=0))
    scaled = jac / np.where(norms > 0, norms, 1.0)
    r = np.linalg.qr(scaled, mode="r") if scaled.shape[0] > scaled.shape[1] else scaled
    _, s, vt = np.linalg.svd(r, full_matrices=False)
    return s, vt


def null_direction(jac) -> tuple[float, np.ndarray]:
    """``(σ_min / σ_max, v)`` of the column-scaled ``jac``: the relative smallest singular
    value (0 for a Jacobian of zeros or with fewer rows than columns) and its right
    singular vector, normalised so that its largest component is +1."""
    jac = np.asarray(jac, dtype=np.float64)
    p = jac.shape[1]
    if jac.shape[0] < p or not np.all(np.isfinite(jac)):
        v = np.zeros(p)
        return 0.0, v
    s, vt = scaled_singular(jac)
    ratio = float(s[-1] / s[0]) if s[0] > 0 else 0.0
    v = vt[-1]
    big = np.argmax(np.abs(v))
    return ratio, v / v[big]


def undetermined(jac, names) -> tuple[str, ...]:
    """The constants the null direction of ``jac`` moves most (components at least
    :data:`NULL_SHARE` of the largest), largest first; () where ``jac`` has full rank."""
    ratio, v = null_direction(jac)
    if ratio > RANK_RTOL:
        return ()
    order = np.argsort(-np.abs(v))
    return tuple(names[j] for j in order if abs(v[j]) >= NULL_SHARE)
