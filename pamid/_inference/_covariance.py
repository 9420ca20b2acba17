"""The one place pamid forms the covariance of least-squares constants.

Cov(θ̂) = s²·(JᵀJ)⁻¹ with s² = SSE/(n − p) and J the Jacobian of the weighted residuals at
the optimum (the Wald covariance, Bates & Watts 1988, eq. 2.25; what Excel's regression and
SciPy's ``curve_fit`` report). (JᵀJ)⁻¹ comes from the SVD of the column-scaled J of the rank
criterion (:func:`pamid._inference._rank.scaled_svd`): with J = Js·D and Js = U·S·Vᵀ,
(JᵀJ)⁻¹ = D⁻¹·V·S⁻²·Vᵀ·D⁻¹, stable where the normal matrix would lose twice the digits, and
+inf where the rank criterion says the data do not determine the constants (an interval from
rounding noise would look like a finding). Constants held fixed (``free`` 0) have no
variance: their rows and columns are 0.

Every fit goes through here or through Sárosi's written-out statistics
(``pamid._solvers._sarosi.sarosi_statistics``, the solver's own Cholesky of the same
equilibrated normal matrix, with the same criterion on its pivots); the sandwich
covariances (``pamid._fit._correlated``) take their bread A⁻¹ from here.
"""

from __future__ import annotations

import numpy as np

from ._rank import RANK_PIVOT, _xp, determined, scaled_svd


def unscaled_covariance(jac, free=None):
    """(JᵀJ)⁻¹ of ``jac`` (n × p, or a stack …× n × p), with the one rank criterion.

    NumPy in, NumPy out (no compiled program); jax arrays in, jax.numpy (works under
    ``jit``, ``vmap`` and ``grad``). ``free`` (p,) or (…, p): 0 for constants held fixed,
    whose rows and columns are 0. Returns (jtj_inv, rank, full_rank): the inverse (+inf
    everywhere where not of full rank), the numerical rank of the free constants, and
    whether every free constant is determined.
    """
    xp = _xp(jac)
    s, vt, d, held = scaled_svd(jac, free)
    ok = determined(s)
    full_rank = xp.all(ok, axis=-1)
    rank = xp.sum(ok, axis=-1) - held
    with np.errstate(divide="ignore", invalid="ignore"):
        s_inv2 = xp.where(ok, 1.0 / xp.where(ok, s, 1.0) ** 2, 0.0)
    inv = (xp.swapaxes(vt, -1, -2) * s_inv2[..., None, :]) @ vt
    inv = inv / (d[..., :, None] * d[..., None, :])
    inv = 0.5 * (inv + xp.swapaxes(inv, -1, -2))
    if free is not None:
        keep = xp.asarray(free)
        inv = xp.where((keep[..., :, None] * keep[..., None, :]) > 0, inv, 0.0)
    inv = xp.where(full_rank[..., None, None], inv, xp.inf)
    return inv, rank, full_rank


def gram_inverse(a):
    """(JᵀJ)⁻¹ from the normal matrix A = JᵀJ itself (NumPy, a stack …× p × p), for callers
    that hold A and many Jacobians (the sandwich intervals of 10,000 muscles: the QR of every
    tall J took 1.3 s, this 0.1 s). The same criterion on A: equilibrated to unit diagonal
    (A = D·As·D, D the column norms of J), its eigenvalues are the squared singular values
    of the column-scaled J, so a direction counts where its eigenvalue is above
    ``RANK_PIVOT`` = ``RANK_RTOL``² times the largest (as on the Cholesky pivots of Sárosi's
    statistics). Returns (inverse, full_rank): NaN where not of full rank (no covariance)."""
    a = np.asarray(a, np.float64)
    diag = np.diagonal(a, axis1=-2, axis2=-1)
    d = np.sqrt(np.where(diag > 0, diag, 1.0))
    lam, vec = np.linalg.eigh(a / (d[..., :, None] * d[..., None, :]))
    full_rank = (lam[..., :1] > lam[..., -1:] * RANK_PIVOT)[..., 0] & (diag > 0).all(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = (vec / np.where(lam > 0, lam, np.nan)[..., None, :]) @ np.swapaxes(vec, -1, -2)
    inv = inv / (d[..., :, None] * d[..., None, :])
    return np.where(full_rank[..., None, None], inv, np.nan), full_rank


def residual_variance(sse, dof):
    """s² = SSE/(n − p), NaN without degrees of freedom (broadcasts; NumPy)."""
    sse, dof = np.asarray(sse, float), np.asarray(dof)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(dof > 0, sse / np.maximum(dof, 1), np.nan)


def scale_covariance(jtj_inv, s2):
    """s²·(JᵀJ)⁻¹ (NumPy, broadcast over leading axes): NaN where s² is, ±inf where the
    inverse is (not of full rank)."""
    s2 = np.asarray(s2, float)
    with np.errstate(invalid="ignore"):
        return s2[..., None, None] * np.asarray(jtj_inv, float)


def covariance(jac, sse, dof, free=None):
    """The Wald covariance s²·(JᵀJ)⁻¹ (NumPy) of the constants of ``jac`` (n × p or a stack),
    s² = ``sse``/``dof``. Returns (covariance, full_rank); NaN where not of full rank (no
    covariance) or without degrees of freedom."""
    inv, _, full_rank = unscaled_covariance(np.asarray(jac, float), free)
    cov = scale_covariance(inv, residual_variance(sse, dof))
    return np.where(np.asarray(full_rank)[..., None, None], cov, np.nan), full_rank


def standard_errors(jac, sse, dof, free=None):
    """√diag of :func:`covariance` (0 for held constants, NaN where not of full rank or
    without degrees of freedom) and whether the constants are determined."""
    cov, full_rank = covariance(jac, sse, dof, free)
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1)), full_rank
