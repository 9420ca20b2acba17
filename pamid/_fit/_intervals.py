"""95% intervals for fitted constants: Wald, profile likelihood, and a curve bootstrap.

- Wald: θ̂ ± t_{0.975, n−p}·se, se² = s²·diag((JᵀJ)⁻¹), s² = SSE/(n − p). This is what
  regression add-ins such as Excel's Data Analysis report (Sárosi computed Table 3-1 so).
- Profile likelihood: for constant j, the set of values v for which the best fit with
  θ_j = v has (S(v) − S_min)/s² ≤ t²_{0.975, n−p} (the profile-t interval of Bates & Watts).
  It follows the curvature of the nonlinear constant a3 that the Wald interval ignores.
  Each end is found by Newton's method on the equations that define it (Venzon &
  Moolgavkar 1988), all ends of all muscles as lanes of one batched iteration.
- Bootstrap: whole curves (sweeps) are resampled with replacement and every replicate is
  refitted in the same batched solve; percentile interval. It carries the correlation of
  samples within a curve (hysteresis, drift) that the other two assume away.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._inference import t_critical, wald, wald_interval  # noqa: F401  (pamid.engine)
from ._batch import FitData, default_chunk, map_lanes
from ._least_squares import _key, residuals, solve
from ._spec import ModelSpec

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


def _generic_derivatives(spec, x, y, w):
    """The same as :func:`pamid._fit._gauss_newton.sarosi_derivatives` for any model, by
    automatic differentiation of its weighted residuals (one muscle per lane)."""

    def one(theta, x, y, w):
        res = lambda th: residuals(spec, th, x, y, w)  # noqa: E731
        r = res(theta)
        jac = jax.jacfwd(res)(theta)
        hess = jax.hessian(lambda th: 0.5 * jnp.sum(res(th) ** 2))(theta)
        return jnp.sum(r**2), jac.T @ r, hess, jac.T @ jac

    def sse_only(theta, x, y, w):
        return jnp.sum(residuals(spec, theta, x, y, w) ** 2)

    return (lambda theta: jax.vmap(one)(theta, x, y, w),
            lambda theta: jax.vmap(sse_only)(theta, x, y, w))


def _end_step(hess, g, sse, sse_end, onehot, side):
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
    from ._gauss_newton import _solve_scaled

    free = 1.0 - onehot
    # H with row and column j replaced by those of the identity: solving it keeps δ_j = 0.
    reduced = hess * free[..., :, None] * free[..., None, :] + onehot[..., :, None] * (
        onehot[..., None, :]
    )
    h_j = jnp.sum(hess * onehot[..., None, :], axis=-1)  # H·e_j
    rhs = jnp.stack([-g * free, -h_j * free], axis=-1)
    z, pivot = _solve_scaled(reduced, rhs, 0.0, with_pivot=True)
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


@functools.partial(jax.jit, static_argnames=("spec", "max_steps", "tol", "max_jump", "check"))
def _profile_ends(spec, theta_hat, cov, tcrit, s2, sse_min, x, y, w, max_steps, tol, max_jump,
                  check):
    """Both ends of the profile-t interval of every constant of every muscle: the 2·p ends
    of a muscle are lanes of one batched Newton iteration (:func:`_end_step`), each started
    at its Wald end with the other constants moved as the covariance says (the end of the
    linearised model). Exact Hessian where the reduced problem is positive definite there,
    JᵀWJ (Gauss–Newton) where not; ``check`` = (largest step, tolerance on S) of the
    shortcut described at ``PROFILE_CHECK_STEP``. Returns ends (M, p, 2) and converged flags
    (M, p, 2)."""
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
    sse_tol = check[1] * (tcrit**2 * s2)[:, None]
    fast = spec.fast_path
    if fast is not None and fast.profile_derivatives is not None:
        derivatives, sse_only = fast.profile_derivatives(x, y, w)
    else:
        derivatives, sse_only = _generic_derivatives(spec, x, y, w)
    derivatives = jax.vmap(derivatives, in_axes=1, out_axes=1)  # every end of a muscle
    sse_only = jax.vmap(sse_only, in_axes=1, out_axes=1)

    def body(state):
        it, theta, active, converged = state
        sse, g, hess, jtj = derivatives(theta)
        step_n, ok_n = _end_step(hess, g, sse, sse_end, onehot, side)
        # Gauss–Newton's step only where Newton's is not usable (rarely: skipped when none).
        step_g, ok_g = jax.lax.cond(
            jnp.any(active & ~ok_n),
            lambda: _end_step(jtj, g, sse, sse_end, onehot, side),
            lambda: (jnp.zeros_like(step_n), jnp.zeros_like(ok_n)),
        )
        step = jnp.where(ok_n[..., None], step_n, step_g)
        ok = (ok_n | ok_g) & jnp.isfinite(sse)
        rel = jnp.max(jnp.abs(step) / half[:, None, :], axis=-1)
        step = step * jnp.minimum(1.0, max_jump / rel)[..., None]
        move = active & ok
        new = theta + step
        done = move & (rel < jnp.where(ok_n, tol, tol * tol))
        # The shortcut: S alone at the new point, for the ends that took a small Newton step.
        close = jnp.abs(sse_only(new) - sse_end) <= sse_tol
        done |= move & ok_n & (rel < check[0]) & close
        theta = jnp.where(move[..., None], new, theta)
        return it + 1, theta, move & ~done, converged | done

    active = jnp.all(jnp.isfinite(start), axis=-1) & jnp.isfinite(sse_end)
    state = (jnp.array(0), start, active, jnp.zeros_like(active))
    _, theta, _, converged = jax.lax.while_loop(
        lambda s: (s[0] < max_steps) & jnp.any(s[2]), body, state
    )
    ends = jnp.sum(theta * onehot, axis=-1)  # (M, L)
    converged &= side * (ends - theta_hat[:, js]) > 0
    return ends.reshape(m, n_par, 2), converged.reshape(m, n_par, 2)


def profile(spec: ModelSpec, data: FitData, theta, se, s2, sse, dof, level: float = 0.95,
            *, jtj_inv=None, bounds=None, max_steps: int = PROFILE_MAX_STEPS,
            tol: float = PROFILE_STEP_TOL,
            check: tuple[float, float] = (PROFILE_CHECK_STEP, PROFILE_SSE_TOL)):
    """Profile-likelihood (profile-t) intervals: for constant j, the values v for which the
    best fit with θ_j = v has (S(v) − S_min)/s² ≤ t² (Bates & Watts). Each end is found by
    Newton's method on the conditions that define it (:func:`_end_step`), all ends of all
    muscles in one batched call.

    ``jtj_inv`` (M, p, p), (JᵀJ)⁻¹ at the optimum, places the starts at the ends of the
    linearised model; without it they are θ̂ ± t·se in the constant alone.

    ``bounds``: (lower, upper) arrays (p,) of the constants' physical bounds (±inf where
    none), as the fit took them: an end past its constant's bound is the bound (the values
    beyond it are not possible values of the constant, however well the data would fit
    them).

    Returns lower, upper (M, p) and a flag (M, p): True where both ends converged; an end
    that did not converge is NaN (an unbounded or badly determined constant).
    """
    theta = np.asarray(theta, dtype=np.float64)
    tcrit = t_critical(dof, level)
    if jtj_inv is None:
        cov = np.eye(theta.shape[-1]) * (np.asarray(se) ** 2)[..., None]
    else:
        with np.errstate(invalid="ignore"):  # NaN for undetermined constants (no interval)
            cov = np.asarray(s2)[:, None, None] * np.asarray(jtj_inv)
    ends, ok = map_lanes(
        lambda *a: _profile_ends(spec, *a, max_steps=max_steps, tol=tol,
                                 max_jump=PROFILE_MAX_JUMP, check=check),
        theta, cov, np.asarray(tcrit), np.asarray(s2), np.asarray(sse), data.x, data.y, data.w,
        chunk=_profile_chunk(spec, theta.shape[-1]),
        cache_key=_key("profile", spec, max_steps, tol, PROFILE_MAX_JUMP, check),
    )
    ends, ok = np.asarray(ends), np.asarray(ok)
    ends = np.where(ok, ends, np.nan)
    lo, hi = ends[..., 0], ends[..., 1]
    if bounds is not None and bounds[0] is not None:
        with np.errstate(invalid="ignore"):  # NaN ends stay NaN
            lo = np.where(lo < bounds[0], bounds[0], lo)
            hi = np.where(hi > bounds[1], bounds[1], hi)
    return lo, hi, ok.all(axis=-1)


def _profile_chunk(spec: ModelSpec, n_params: int) -> int | None:
    """Muscles per call on the CPU: as many interval ends (2·p per muscle) as
    :func:`map_lanes` takes lanes there, so that a chunk's arrays stay in the caches;
    elsewhere ``map_lanes``'s default."""
    if jax.default_backend() != "cpu":
        return None
    return max(1, default_chunk() // (2 * n_params))


@jax.jit
def _curve_weights(key, curve, w, n_boot):
    """Bootstrap weights: each replicate draws a muscle's curves with replacement."""
    n_curves = jnp.max(curve, axis=-1) + 1  # (M,)
    c_max = curve.shape[-1]

    def one_muscle(key, curve, w, n_c):
        def one_replicate(key):
            draws = jax.random.randint(key, (c_max,), 0, n_c)
            valid = jnp.arange(c_max) < n_c
            counts = jnp.zeros(c_max).at[draws].add(jnp.where(valid, 1.0, 0.0))
            return w * counts[jnp.clip(curve, 0)]

        return jax.vmap(one_replicate)(jax.random.split(key, n_boot.shape[0]))

    keys = jax.random.split(key, curve.shape[0])
    return jax.vmap(one_muscle)(keys, curve, w, n_curves)


def bootstrap(spec: ModelSpec, data: FitData, theta, key, n_boot: int = 1000,
              level: float = 0.95, solver: str = "gauss-newton"):
    """Percentile intervals from resampling whole curves; replicates fitted as one batch.

    Returns lower, upper (M, p), the replicate estimates (M, B, p) and the fraction of
    replicates that converged per muscle.
    """
    if n_boot < 2:
        raise ValueError("n_boot must be at least 2")
    m, n = data.y.shape
    weights = _curve_weights(key, data.curve, data.w, jnp.zeros(n_boot))  # (M, B, n)
    rep = lambda a: jnp.repeat(a, n_boot, axis=0)  # noqa: E731
    boot = FitData(
        x=tuple(rep(a) for a in data.x),
        y=rep(data.y),
        w=weights.reshape(m * n_boot, n),
        curve=rep(data.curve),
    )
    start = np.repeat(np.asarray(theta), n_boot, axis=0)
    est, ok, _ = solve(spec, boot, solver=solver, theta0=start)
    est = est.reshape(m, n_boot, -1)
    ok = ok.reshape(m, n_boot)
    alpha = (1 - level) / 2
    masked = np.where(ok[..., None], est, np.nan)
    lower = np.nanquantile(masked, alpha, axis=1)
    upper = np.nanquantile(masked, 1 - alpha, axis=1)
    return lower, upper, est, ok.mean(axis=1)
