"""95% intervals for fitted constants: Wald, profile likelihood, and a curve bootstrap.

- Wald: θ̂ ± t_{0.975, n−p}·se, se² = s²·diag((JᵀJ)⁻¹), s² = SSE/(n − p). This is what
  regression add-ins such as Excel's Data Analysis report (Sárosi computed Table 3-1 so).
- Profile likelihood: for constant j, the set of values v for which the best fit with
  θ_j = v has (S(v) − S_min)/s² ≤ t²_{0.975, n−p} (the profile-t interval of Bates & Watts).
  It follows the curvature of the nonlinear constant a3 that the Wald interval ignores.
  Each end is found by Newton's method on the equations that define it (Venzon &
  Moolgavkar 1988), all ends of all muscles as lanes of one batched iteration: the solver
  value :class:`pamid._solvers.ProfileNewton`.
- Bootstrap: whole curves (sweeps) are resampled with replacement and every replicate is
  refitted in the same batched solve; percentile interval. It carries the correlation of
  samples within a curve (hysteresis, drift) that the other two assume away.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .._inference import t_critical, wald, wald_interval  # noqa: F401  (pamid.engine)
from .._lanes._batch import FitData, items_per_call, map_lanes
from .._solvers import ProfileNewton, generic_derivatives
from ._least_squares import _key, least_squares
from ._spec import ModelSpec


@functools.partial(jax.jit, static_argnames=("spec", "solver"))
def _profile_ends(spec, solver, theta_hat, cov, tcrit, s2, sse_min, x, y, w):
    """Both ends of the profile-t interval of every constant of every muscle, by ``solver``
    (:class:`pamid._solvers.ProfileNewton`) on the model's derivatives: its registered
    written-out ones where it has them, else automatic differentiation. Returns ends
    (M, p, 2) and converged flags (M, p, 2)."""
    fast = spec.kernels
    if fast is not None and fast.profile_derivatives is not None:
        derivatives, sse_only = fast.profile_derivatives(x, y, w)
    else:
        derivatives, sse_only = generic_derivatives(spec, x, y, w)
    return solver.ends(derivatives, sse_only, theta_hat, cov, tcrit, s2, sse_min)


def profile(spec: ModelSpec, data: FitData, theta, se, s2, sse, dof, level: float = 0.95,
            *, jtj_inv=None, bounds=None, solver: ProfileNewton | None = None,
            max_steps: int | None = None, tol: float | None = None,
            check: tuple[float, float] | None = None):
    """Profile-likelihood (profile-t) intervals: for constant j, the values v for which the
    best fit with θ_j = v has (S(v) − S_min)/s² ≤ t² (Bates & Watts). Each end is found by
    Newton's method on the conditions that define it (``solver``, a
    :class:`pamid._solvers.ProfileNewton` value with its settings), all ends of all muscles
    in one batched call. ``max_steps``, ``tol`` and ``check`` are deprecated: they replace
    the solver's settings, with a ``DeprecationWarning``
    (``solver=ProfileNewton(max_steps=...)`` says it).

    ``jtj_inv`` (M, p, p), (JᵀJ)⁻¹ at the optimum, places the starts at the ends of the
    linearised model; without it they are θ̂ ± t·se in the constant alone.

    ``bounds``: (lower, upper) arrays (p,) of the constants' physical bounds (±inf where
    none), as the fit took them: an end past its constant's bound is the bound (the values
    beyond it are not possible values of the constant, however well the data would fit
    them).

    Returns lower, upper (M, p) and a flag (M, p): True where both ends converged; an end
    that did not converge is NaN (an unbounded or badly determined constant).
    """
    solver = ProfileNewton() if solver is None else solver
    settings = {k: v for k, v in {"max_steps": max_steps, "tol": tol, "check": check}.items()
                if v is not None}
    if settings:
        warnings.warn(f"profile({', '.join(f'{k}=' for k in settings)}) is deprecated: pass "
                      "solver=ProfileNewton(...) with those settings", DeprecationWarning,
                      stacklevel=2)
        solver = dataclasses.replace(solver, **settings)
    theta = np.asarray(theta, dtype=np.float64)
    tcrit = t_critical(dof, level)
    if jtj_inv is None:
        cov = np.eye(theta.shape[-1]) * (np.asarray(se) ** 2)[..., None]
    else:
        with np.errstate(invalid="ignore"):  # NaN for undetermined constants (no interval)
            cov = np.asarray(s2)[:, None, None] * np.asarray(jtj_inv)
    ends, ok = map_lanes(
        lambda *a: _profile_ends(spec, solver, *a),
        theta, cov, np.asarray(tcrit), np.asarray(s2), np.asarray(sse), data.x, data.y, data.w,
        chunk=items_per_call(2 * theta.shape[-1]),  # a muscle's 2·p ends are its lanes
        cache_key=_key("profile", spec, solver.max_steps, solver.tol, solver.max_jump,
                       solver.check),
    )
    ends, ok = np.asarray(ends), np.asarray(ok)
    ends = np.where(ok, ends, np.nan)
    lo, hi = ends[..., 0], ends[..., 1]
    if bounds is not None and bounds[0] is not None:
        with np.errstate(invalid="ignore"):  # NaN ends stay NaN
            lo = np.where(lo < bounds[0], bounds[0], lo)
            hi = np.where(hi > bounds[1], bounds[1], hi)
    return lo, hi, ok.all(axis=-1)


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
    sol = least_squares(spec, boot, solver=solver, theta0=start)
    est = sol.params.reshape(m, n_boot, -1)
    ok = sol.converged.reshape(m, n_boot)
    alpha = (1 - level) / 2
    masked = np.where(ok[..., None], est, np.nan)
    lower = np.nanquantile(masked, alpha, axis=1)
    upper = np.nanquantile(masked, 1 - alpha, axis=1)
    return lower, upper, est, ok.mean(axis=1)
