"""The one rank criterion of pamid's fits, and the constants a rank-deficient fit cannot pin.

A fit's constants are determined by the data when the Jacobian J of the weighted residuals
at the optimum has full column rank. The test, used by every fit, decay, diagnosis refit
and linear regression in pamid (through :func:`scaled_svd`, or on its Cholesky pivots in
Sárosi's written-out statistics): scale J's columns to unit length (the test does not
depend on the constants' units), and count a direction as determined when its singular
value of the scaled J is above :data:`RANK_RTOL` times the largest.

Why 1e-7: the variance of a constant grows as 1/σ²; at σ_min/σ_max = 1e-7 the normal matrix
JᵀJ has lost 14 of its 16 digits (condition 1e14), so an interval computed from it is
rounding noise, while an exactly dependent J (a repeated column, a constant the model does
not see) gives σ_min/σ_max of rounding size, 1e-16 … 1e-12, far below. The written-out
Sárosi statistics factorise the equilibrated JᵀJ, whose smallest Cholesky pivot plays the
part of σ_min²: their threshold is :data:`RANK_RTOL` squared (``RANK_PIVOT``).

Constants held fixed (``free`` 0: masked, or held on a bound) take no part: their columns
are replaced by unit vectors in rows of their own, which adds a singular value of exactly 1
per held constant (the free columns have unit length, so the largest singular value is
still theirs) and leaves the free block's singular values as they are.

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


def _xp(a):
    """NumPy for NumPy arrays (host code: no compiled programs), jax.numpy otherwise (JAX
    is imported only then: host code that uses this module need not load it)."""
    if isinstance(a, np.ndarray):
        return np
    import jax.numpy as jnp

    return jnp


def scaled_svd(jac, free=None):
    """The SVD behind pamid's rank criterion, for one Jacobian ``jac`` (n × p) or a stack
    (…, n × p); NumPy in, NumPy out (no compiled program), else jax.numpy (works under
    ``jit``, ``vmap`` and ``grad``).

    The columns are scaled to unit length, J = Js·D (a zero column stays zero); constants
    where ``free`` (p,) or (…, p) is 0 are held out (module docstring). J = Q·R first
    (Householder, backward stable: R has J's singular values to rounding) and the SVD of the
    p × p R: the SVD of the tall J would allocate n × n (47 GB for one muscle of 9,596 rows
    in a batch of 64 lanes), and the eigenvalues of JsᵀJs would square the condition number.

    Returns (s, vt, d, held): singular values (descending), right singular vectors (rows),
    the column norms D (1 where a column is zero or held) and the count of held constants.
    """
    xp = _xp(jac)
    jac = jac.astype(xp.float64) if xp is np else jac
    p = jac.shape[-1]
    if free is not None:
        free = xp.asarray(free, dtype=jac.dtype)
        jac = jac * free[..., None, :]
    norms = xp.sqrt(xp.sum(jac**2, axis=-2))
    d = xp.where(norms > 0, norms, 1.0)
    scaled = jac / d[..., None, :]
    if free is not None:
        # held constants: a unit column in a row of its own (an exact singular value of 1)
        eye = xp.eye(p, dtype=jac.dtype) * (1.0 - free)[..., :, None]
        scaled = xp.concatenate([scaled, xp.broadcast_to(eye, scaled.shape[:-2] + (p, p))],
                                axis=-2)
        held = xp.sum(1.0 - free, axis=-1)
    else:
        held = 0
    if scaled.shape[-2] > p:
        scaled = xp.linalg.qr(scaled, mode="r")
    _, s, vt = xp.linalg.svd(scaled, full_matrices=False)
    if s.shape[-1] < p:  # fewer rows than constants: the missing singular values are 0
        pad = [(0, 0)] * (s.ndim - 1) + [(0, p - s.shape[-1])]
        s = xp.pad(s, pad)
    return s, vt, d, held


def determined(s):
    """Which singular values (from :func:`scaled_svd`) count: above ``RANK_RTOL`` times the
    largest; none where the largest is 0."""
    return (s > s[..., :1] * RANK_RTOL) & (s[..., :1] > 0)


def numerical_rank(jac, free=None):
    """Numerical rank of ``jac`` (n × p, or a stack) under the one criterion: the directions
    of the free constants that the data determine. Constants the data cannot tell apart
    count once (a BIC's k)."""
    s, _, _, held = scaled_svd(jac, free)
    xp = _xp(s)
    return xp.sum(determined(s), axis=-1) - held


def null_direction(jac) -> tuple[float, np.ndarray]:
    """``(σ_min / σ_max, v)`` of the column-scaled ``jac``: the relative smallest singular
    value (0 for a Jacobian of zeros or with fewer rows than columns) and its right
    singular vector, normalised so that its largest component is +1."""
    jac = np.asarray(jac, dtype=np.float64)
    p = jac.shape[1]
    if jac.shape[0] < p or not np.all(np.isfinite(jac)):
        return 0.0, np.zeros(p)
    s, vt, _, _ = scaled_svd(jac)
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
