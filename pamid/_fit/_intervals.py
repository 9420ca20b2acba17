"""95% intervals for fitted constants: Wald, profile likelihood, and a curve bootstrap.

- Wald: θ̂ ± t_{0.975, n−p}·se, se² = s²·diag((JᵀJ)⁻¹), s² = SSE/(n − p). This is what
  regression add-ins such as Excel's Data Analysis report (Sárosi computed Table 3-1 so).
- Profile likelihood: for constant j, the set of values v for which the best fit with
  θ_j = v has (S(v) − S_min)/s² ≤ t²_{0.975, n−p} (the profile-t interval of Bates & Watts).
  It follows the curvature of the nonlinear constant a3 that the Wald interval ignores.
- Bootstrap: whole curves (sweeps) are resampled with replacement and every replicate is
  refitted in the same batched solve; percentile interval. It carries the correlation of
  samples within a curve (hysteresis, drift) that the other two assume away.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ._batch import FitData, map_lanes
from ._least_squares import _key, residuals, solve
from ._spec import ModelSpec


def t_critical(dof, level: float = 0.95):
    """Two-sided Student-t quantile for ``level`` with ``dof`` degrees of freedom."""
    # scipy.special's inverse t distribution: scipy.stats would cost ~0.5 s more at start-up
    from scipy.special import stdtrit

    dof = np.asarray(dof, float)
    return np.where(dof > 0, stdtrit(np.maximum(dof, 1), 0.5 + level / 2), np.nan)


def wald(theta, jtj_inv, sse, n, level: float = 0.95):
    """Wald intervals with Student-t quantiles. Returns (se, lower, upper, s2, dof)."""
    n_params = theta.shape[-1]
    dof = n - n_params
    s2 = np.where(dof > 0, sse / np.maximum(dof, 1), np.nan)
    se = np.sqrt(s2[:, None] * np.diagonal(jtj_inv, axis1=-2, axis2=-1))
    t = t_critical(dof, level)[:, None]
    return se, theta - t * se, theta + t * se, s2, dof


@functools.partial(jax.jit, static_argnames=("spec", "n_iter", "inner_steps"))
def _profile_batch(spec, theta_hat, se, tcrit, s2, sse_min, x, y, w, n_iter, inner_steps):
    import optimistix as optx  # here: ~0.3 s at import that Wald-only fits do not need

    n_params = theta_hat.shape[-1]
    idx = jnp.arange(n_params)

    def one_muscle(theta_hat, se, tcrit, s2, sse_min, x, y, w):
        def one_side(j, side):
            # θ = concat(free, [v])[gather]: constant j fixed at v, the others free.
            gather = jnp.where(idx < j, idx, idx - 1).at[j].set(n_params - 1)
            keep = jnp.where(jnp.arange(n_params - 1) < j, jnp.arange(n_params - 1),
                             jnp.arange(n_params - 1) + 1)

            def profile(v, free0):
                def res(free, _):
                    theta = jnp.concatenate([free, v[None]])[gather]
                    return residuals(spec, theta, x, y, w)

                # Gauss–Newton: every inner solve starts from the previous point's optimum,
                # a few steps away, where GN needs ~4 steps and LM ~25.
                sol = optx.least_squares(
                    res, optx.GaussNewton(rtol=1e-10, atol=1e-10), free0,
                    max_steps=inner_steps, throw=False,
                )
                r = res(sol.value, None)
                return jnp.sum(r**2), sol.value

            def tau(v, sse):
                return jnp.sign(v - theta_hat[j]) * jnp.sqrt(jnp.maximum(sse - sse_min, 0.0) / s2)

            target = side * tcrit
            v_b = theta_hat[j] + side * tcrit * se[j]
            sse_b, free_b = profile(v_b, theta_hat[keep])
            state = (theta_hat[j], 0.0, v_b, tau(v_b, sse_b), free_b)

            def converged(state):
                return jnp.abs(state[3] - target) < 1e-6 * jnp.abs(target)

            def step(state):
                it, state = state
                v_a, t_a, v_b, t_b, free_b = state
                slope = (t_b - t_a) / (v_b - v_a)
                v_new = v_b + (target - t_b) / slope
                # Safeguards: τ rises with v on both sides of θ̂; never jump more than
                # four times the current distance from θ̂.
                bad = ~jnp.isfinite(v_new) | (slope <= 0)
                far = theta_hat[j] + 4.0 * (v_b - theta_hat[j])
                v_new = jnp.where(bad, theta_hat[j] + 2.0 * (v_b - theta_hat[j]), v_new)
                v_new = jnp.where(side * (v_new - far) > 0, far, v_new)
                sse_new, free_new = profile(v_new, free_b)
                new = (v_b, t_b, v_new, tau(v_new, sse_new), free_new)
                # Under vmap the loop runs until every end is done; an end that has converged
                # stays put (two equal points would give no slope).
                done = converged(state)
                return it + 1, jax.tree.map(lambda old, nw: jnp.where(done, old, nw), state, new)

            _, (_, _, v_end, t_end, _) = jax.lax.while_loop(
                lambda s: (s[0] < n_iter) & ~converged(s[1]), step, (0, state)
            )
            ok = jnp.abs(t_end - target) < 1e-3 * jnp.abs(target)  # τ within 0.1% of t
            return v_end, ok

        js = jnp.repeat(idx, 2)
        sides = jnp.tile(jnp.array([-1.0, 1.0]), n_params)
        ends, ok = jax.vmap(one_side)(js, sides)
        return ends.reshape(n_params, 2), ok.reshape(n_params, 2)

    return jax.vmap(one_muscle)(theta_hat, se, tcrit, s2, sse_min, x, y, w)


def profile(spec: ModelSpec, data: FitData, theta, se, s2, sse, dof, level: float = 0.95,
            n_iter: int = 12, inner_steps: int = 100):
    """Profile-likelihood intervals, found by a safeguarded secant search on the signed root.

    Returns lower, upper (M, p) and a flag (M, p): True where both ends converged; an end
    that did not converge is NaN (an unbounded or badly determined constant).
    """
    tcrit = t_critical(dof, level)
    ends, ok = map_lanes(
        lambda *a: _profile_batch(spec, *a, n_iter=n_iter, inner_steps=inner_steps),
        jnp.asarray(theta), jnp.asarray(se), jnp.asarray(tcrit), jnp.asarray(s2),
        jnp.asarray(sse), data.x, data.y, data.w,
        cache_key=_key("profile", spec, n_iter, inner_steps),
    )
    ends, ok = np.asarray(ends), np.asarray(ok)
    ends = np.where(ok, ends, np.nan)
    return ends[..., 0], ends[..., 1], ok.all(axis=-1)


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
