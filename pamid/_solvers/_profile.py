"""The ends of profile-likelihood intervals as a solver value: Newton's method on the
conditions that define an end (Venzon & Moolgavkar 1988), every end of every muscle a lane of
one batched loop.

The end of constant j of a least-squares fit at level t (the profile-t interval of Bates &
Watts 1988, section 6.1) is the point where the other constants are at their optimum,
∂S/∂θ_k = 0 for k ≠ j, and S = S_min + t²·s². That is a root-finding problem, not a least-
squares one, so it has its own solver class (:class:`ProfileNewton`); ``pamid._fit._intervals``
passes it the model's derivatives (the model's registered written-out ones where it has them,
Sárosi's :func:`pamid._solvers._sarosi.sarosi_derivatives`, else automatic differentiation of
its residuals, :func:`generic_derivatives`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ._base import residuals, residuals_and_jacobian
from ._sarosi import solve_scaled

#: An interval end has converged when the last Newton step moved every constant by less
#: than this fraction of its Wald half-width t·se (the square of it for a Gauss–Newton
#: step, which converges only linearly); the step is then taken. Newton's error after it is
#: of the order of the step's square.
PROFILE_STEP_TOL = 1e-4

#: Newton steps per interval end before it is given up (reported NaN, not converged).
PROFILE_MAX_STEPS = 30

#: The largest step, in Wald half-widths of the constant that moves most: a profile that
#: bends away from its quadratic model is followed, not jumped over.
PROFILE_MAX_JUMP = 1.0

#: A shortcut that saves most ends their second full pass: after a Newton step smaller than
#: ``PROFILE_CHECK_STEP`` half-widths the other constants are within about its square of
#: their optimum (which moves the end by about the square of that: 1e-8 of a half-width),
#: and one pass that only sums rᵀWr checks the remaining condition, S = S_min + t²·s², to
#: ``PROFILE_SSE_TOL``·t²·s² (τ = t to 1e-7; the end to ~1e-7 of a half-width). An end that
#: fails the check goes on with full Newton steps. (Measured on 500 virtual muscles at 0.01,
#: 2 and 20 N of noise: every end within 5e-8 of its interval's width of the end converged
#: with full steps to 1e-9; tests/test_fit_path.py holds them to 1e-6 of SciPy's.)
PROFILE_CHECK_STEP = 1e-2
PROFILE_SSE_TOL = 2e-7


def generic_derivatives(spec, x, y, w):
    """The same as :func:`pamid._solvers._sarosi.sarosi_derivatives` for any model, by
    automatic differentiation of its weighted residuals (one muscle per lane): functions of
    theta (M, p) giving (S, g = ∂(S/2)/∂θ, H = ∂²(S/2)/∂θ², JᵀJ) and S alone."""

    def one(theta, x, y, w):
        res = lambda th: residuals(spec, th, x, y, w)  # noqa: E731
        r, jac = residuals_and_jacobian(spec, theta, x, y, w)
        hess = jax.hessian(lambda th: 0.5 * jnp.sum(res(th) ** 2))(theta)
        return jnp.sum(r**2), jac.T @ r, hess, jac.T @ jac

    def sse_only(theta, x, y, w):
        return jnp.sum(residuals(spec, theta, x, y, w) ** 2)

    return (lambda theta: jax.vmap(one)(theta, x, y, w),
            lambda theta: jax.vmap(sse_only)(theta, x, y, w))


def end_step(hess, g, sse, sse_end, onehot, side):
    """One Newton step towards an end of the profile-t interval (Venzon & Moolgavkar 1988).

    The end of constant j is the point where the others are at their optimum, ∂S/∂θ_k = 0
    for k ≠ j, and S = ``sse_end``. Both conditions linearised at θ, with H the Hessian of
    S/2 and g = ∂(S/2)/∂θ: the others follow θ_j as δ_k = d0_k + δ_j·d1_k (their Newton
    step with θ_j moved by δ_j), and S/2 along that line is the quadratic
    c0 + b·δ_j + κ·δ_j²/2, κ = 1/(H⁻¹)_jj. Its larger root is the upper end (``side`` +1),
    the smaller the lower end. Where it has no root (the model's minimum lies above
    ``sse_end``: far from the optimum), the step goes to that minimum instead.

    Arrays have any leading lane axes; ``onehot`` marks j. Returns the step and whether it
    is usable (the reduced Hessian positive definite, everything finite).
    """
    free = 1.0 - onehot
    # H with row and column j replaced by those of the identity: solving it keeps δ_j = 0.
    reduced = hess * free[..., :, None] * free[..., None, :] + onehot[..., :, None] * (
        onehot[..., None, :]
    )
    h_j = jnp.sum(hess * onehot[..., None, :], axis=-1)  # H·e_j
    rhs = jnp.stack([-g * free, -h_j * free], axis=-1)
    z, pivot = solve_scaled(reduced, rhs, 0.0, with_pivot=True)
    d0, d1 = z[..., 0], onehot + z[..., 1]
    kappa = jnp.einsum("...i,...ij,...j->...", d1, hess, d1)
    b = jnp.sum(g * d1, axis=-1)
    c0 = 0.5 * (sse - sse_end) + jnp.sum(g * d0, -1) + 0.5 * jnp.einsum(
        "...i,...ij,...j->...", d0, hess, d0
    )
    disc = b * b - 2.0 * kappa * c0
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    # The roots of κ·δ²/2 + b·δ + c0, each without cancellation.
    far = -(b + jnp.where(b >= 0, root, -root)) / kappa
    near = jnp.where(far != 0, 2.0 * c0 / (kappa * far), 0.0)
    d_j = jnp.where(side > 0, jnp.maximum(far, near), jnp.minimum(far, near))
    d_j = jnp.where(disc >= 0, d_j, -b / kappa)
    step = d0 + d_j[..., None] * d1
    ok = (pivot > 0) & (kappa > 0) & jnp.all(jnp.isfinite(step), axis=-1)
    return step, ok


class ProfileNewton(eqx.Module):
    """Newton's method for the ends of profile-t intervals (module docstring).

    Each end starts at its Wald end with the other constants moved as the covariance says
    (the end of the linearised model). Exact Hessian where the reduced problem is positive
    definite there, JᵀWJ (Gauss–Newton) where not; steps capped at ``max_jump`` Wald
    half-widths; converged after a step below ``tol`` half-widths, or by the shortcut
    ``check`` = (largest step, tolerance on S) described at :data:`PROFILE_CHECK_STEP`.
    """

    max_steps: int = PROFILE_MAX_STEPS
    tol: float = PROFILE_STEP_TOL
    max_jump: float = PROFILE_MAX_JUMP
    check: tuple[float, float] = (PROFILE_CHECK_STEP, PROFILE_SSE_TOL)

    def ends(self, derivatives, sse_only, theta_hat, cov, tcrit, s2, sse_min):
        """Both ends of every constant's interval for a batch of M muscles, traced inside
        the caller's compiled program.

        Args:
            derivatives, sse_only: functions of theta (M, p) as
                :func:`generic_derivatives` returns them.
            theta_hat (M, p): the fitted constants; cov (M, p, p): their covariance
                s²·(JᵀJ)⁻¹; tcrit, s2, sse_min (M,): the t quantile, the residual variance
                and the minimum SSE.

        Returns ends (M, p, 2) and converged flags (M, p, 2).
        """
        m, n_par = theta_hat.shape
        js = jnp.repeat(jnp.arange(n_par), 2)
        side = jnp.tile(jnp.array([-1.0, 1.0]), n_par)  # (L,)
        onehot = jnp.eye(n_par, dtype=theta_hat.dtype)[js]  # (L, p)
        se = jnp.sqrt(jnp.diagonal(cov, axis1=-2, axis2=-1))  # (M, p)
        half = tcrit[:, None] * se  # Wald half-widths (M, p)
        start = theta_hat[:, None, :] + (
            side[None, :, None] * tcrit[:, None, None] * cov[:, js, :] / se[:, js][..., None]
        )
        sse_end = (sse_min + tcrit**2 * s2)[:, None]  # (M, 1)
        sse_tol = self.check[1] * (tcrit**2 * s2)[:, None]
        derivatives = jax.vmap(derivatives, in_axes=1, out_axes=1)  # every end of a muscle
        sse_only = jax.vmap(sse_only, in_axes=1, out_axes=1)
        tol, max_jump, check_step = self.tol, self.max_jump, self.check[0]

        def body(state):
            it, theta, active, converged = state
            sse, g, hess, jtj = derivatives(theta)
            step_n, ok_n = end_step(hess, g, sse, sse_end, onehot, side)
            # Gauss–Newton's step only where Newton's is not usable (rarely: skipped when
            # none).
            step_g, ok_g = jax.lax.cond(
                jnp.any(active & ~ok_n),
                lambda: end_step(jtj, g, sse, sse_end, onehot, side),
                lambda: (jnp.zeros_like(step_n), jnp.zeros_like(ok_n)),
            )
            step = jnp.where(ok_n[..., None], step_n, step_g)
            ok = (ok_n | ok_g) & jnp.isfinite(sse)
            rel = jnp.max(jnp.abs(step) / half[:, None, :], axis=-1)
            step = step * jnp.minimum(1.0, max_jump / rel)[..., None]
            move = active & ok
            new = theta + step
            done = move & (rel < jnp.where(ok_n, tol, tol * tol))
            # The shortcut: S alone at the new point, for the ends that took a small Newton
            # step.
            close = jnp.abs(sse_only(new) - sse_end) <= sse_tol
            done |= move & ok_n & (rel < check_step) & close
            theta = jnp.where(move[..., None], new, theta)
            return it + 1, theta, move & ~done, converged | done

        active = jnp.all(jnp.isfinite(start), axis=-1) & jnp.isfinite(sse_end)
        state = (jnp.array(0), start, active, jnp.zeros_like(active))
        _, theta, _, converged = jax.lax.while_loop(
            lambda s: (s[0] < self.max_steps) & jnp.any(s[2]), body, state
        )
        ends = jnp.sum(theta * onehot, axis=-1)  # (M, L)
        converged &= side * (ends - theta_hat[:, js]) > 0
        return ends.reshape(m, n_par, 2), converged.reshape(m, n_par, 2)
