"""Batched least squares: every muscle of a batch fitted in one jit-compiled, vmapped solve.

Solver path (measured in ``benchmarks/fit_batch.py``): for the Sárosi model, "gauss-newton"
is the written-out batched Gauss–Newton of ``_gauss_newton.py`` (its own coarse variable-
projection start, one loop over the samples per iteration); for other models it is
optimistix's, from the model's start. Under a batched loop every lane runs until the slowest
converges, so what matters for the batch is that no lane needs many steps; from a
variable-projection start none does. Levenberg–Marquardt and jaxopt's Levenberg–Marquardt
(from the 24-point variable-projection start) and pure variable projection are available
for comparison, and jaxopt's L-BFGS-B for fits with bounds on the constants.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ._batch import FitData, map_lanes
from ._gauss_newton import CPU_CHUNK_LANES
from ._spec import ModelSpec, builtin_key

SOLVERS = (
    "gauss-newton",
    "levenberg-marquardt",
    "variable-projection",
    "jaxopt-levenberg-marquardt",
)


def residuals(spec: ModelSpec, theta, x, y, w):
    """Weighted residuals w^½·(model − data) of one muscle."""
    return jnp.sqrt(w) * (spec.predict(theta, x) - y)


def _optx_solver(name, rtol, atol):
    import optimistix as optx  # imported here: the default Sárosi path does not need it

    if name == "gauss-newton":
        return optx.GaussNewton(rtol=rtol, atol=atol)
    return optx.LevenbergMarquardt(rtol=rtol, atol=atol)


@functools.partial(jax.jit, static_argnames=("spec", "solver", "max_steps", "rtol", "atol"))
def _solve_batch(spec, solver, theta0, x, y, w, max_steps, rtol, atol):
    """Solve every lane from its start; returns theta, success flag and step count per lane."""
    if solver == "variable-projection":
        theta, _, width = spec.fast_path.variable_projection(x, y, w, n_refine=max_steps)
        # Converged: the bracket around a3 has shrunk to the tolerance.
        ok = jnp.all(jnp.isfinite(theta), axis=-1) & (width < jnp.maximum(rtol, 1e-8))
        return theta, ok, jnp.full(theta.shape[0], max_steps)

    if solver == "jaxopt-levenberg-marquardt":
        import jaxopt  # imported here: unmaintained upstream, and it warns on import

        def one(theta0, x, y, w):
            lm = jaxopt.LevenbergMarquardt(
                lambda th: residuals(spec, th, x, y, w),
                stop_criterion="madsen-nielsen",
                maxiter=max_steps,
                xtol=rtol,
                gtol=atol,
            )
            out = lm.run(theta0)
            return out.params, out.state.iter_num < max_steps, out.state.iter_num

        return jax.vmap(one)(theta0, x, y, w)

    import optimistix as optx

    def one(theta0, x, y, w):
        sol = optx.least_squares(
            lambda th, args: residuals(spec, th, *args),
            _optx_solver(solver, rtol, atol),
            theta0,
            args=(x, y, w),
            max_steps=max_steps,
            throw=False,
        )
        ok = sol.result == optx.RESULTS.successful
        return sol.value, ok, sol.stats["num_steps"]

    return jax.vmap(one)(theta0, x, y, w)


@functools.partial(jax.jit, static_argnames=("spec", "max_steps"))
def _solve_bounded(spec, theta0, x, y, w, lower, upper, max_steps):
    """Bounded fits with jaxopt's L-BFGS-B, in coordinates scaled by the Jacobian at the start."""

    import jaxopt  # jaxopt adds what optimistix lacks here: box bounds (L-BFGS-B)

    def one(theta0, x, y, w):
        jac = jax.jacfwd(lambda th: residuals(spec, th, x, y, w))(theta0)
        scale = 1.0 / jnp.maximum(jnp.sqrt(jnp.sum(jac**2, axis=0)), 1e-300)

        def objective(u):
            r = residuals(spec, u * scale, x, y, w)
            return 0.5 * jnp.sum(r**2)

        solver = jaxopt.LBFGSB(fun=objective, maxiter=max_steps, tol=1e-12)
        u0 = jnp.clip(theta0, lower, upper) / scale
        out = solver.run(u0, bounds=(lower / scale, upper / scale))
        # Scaled coordinates can land one rounding unit outside a bound: clip back.
        theta = jnp.clip(out.params * scale, lower, upper)
        return theta, out.state.iter_num < max_steps, out.state.iter_num

    return jax.vmap(one)(theta0, x, y, w)


@functools.partial(jax.jit, static_argnames=("spec",))
def _statistics(spec, theta, x, y, w):
    """SSE, Jacobian-based covariance factor, and the correlation of data and model."""

    def one(theta, x, y, w):
        r = residuals(spec, theta, x, y, w)
        jac = jax.jacfwd(lambda th: residuals(spec, th, x, y, w))(theta)
        # (JᵀJ)⁻¹ through the SVD: stable, and honest (large) where J is nearly singular.
        # J = Q·R first: R has J's singular values and right vectors, and the SVD of the
        # small R plus the QR cost half the SVD of the tall J (measured at 1000 × 300 × 6).
        _, s, vt = jnp.linalg.svd(jnp.linalg.qr(jac, mode="r"), full_matrices=False)
        s_inv = jnp.where(s > s[0] * 1e-14, 1.0 / s, jnp.inf)
        jtj_inv = (vt.T * s_inv**2) @ vt
        model = spec.predict(theta, x)
        n = jnp.sum(w)
        mean_y = jnp.sum(w * y) / n
        mean_m = jnp.sum(w * model) / n
        cov_ym = jnp.sum(w * (y - mean_y) * (model - mean_m))
        var_y = jnp.sum(w * (y - mean_y) ** 2)
        corr = cov_ym / jnp.sqrt(var_y * jnp.sum(w * (model - mean_m) ** 2))
        full_rank = s[-1] > s[0] * 1e-14
        return jnp.sum(r**2), jtj_inv, corr, n, full_rank

    return jax.vmap(one)(theta, x, y, w)


def solve(
    spec: ModelSpec,
    data: FitData,
    *,
    solver: str = "gauss-newton",
    theta0=None,
    bounds=None,
    max_steps: int = 100,
    rtol: float = 1e-10,
    atol: float = 1e-10,
):
    """Fit ``spec`` to every muscle of ``data`` in one compiled call.

    Returns ``(theta, converged, n_steps)`` as NumPy arrays with a leading muscle axis.
    """
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {SOLVERS}")
    fast = spec.fast_path
    if solver == "variable-projection" and (fast is None or fast.variable_projection is None):
        raise ValueError(f"variable projection is written out for the Sárosi model only, "
                         f"not for {spec.name}; use the gauss-newton or levenberg-marquardt "
                         "solver")
    if solver == "gauss-newton" and fast is not None and bounds is None:
        # The model's registered written-out Gauss–Newton, with its own start.
        start = () if theta0 is None else (jnp.asarray(theta0, dtype=jnp.float64),)
        theta, ok, steps = map_lanes(
            lambda x, y, w, *t0: fast.gauss_newton(
                x, y, w, *t0, max_steps=max_steps, rtol=rtol, atol=atol
            ),
            data.x, data.y, data.w, *start,
            chunk=_sarosi_chunk(),
            cache_key=(f"{fast.key}_gauss_newton", max_steps, rtol, atol),
        )
        theta = np.asarray(theta)
        ok = np.asarray(ok) & np.all(np.isfinite(theta), axis=-1)
        return theta, ok, np.asarray(steps)
    if theta0 is None:
        theta0 = map_lanes(spec.start, data.x, data.y, data.w, cache_key=_key("start", spec))
    theta0 = jnp.asarray(theta0, dtype=jnp.float64)
    if bounds is not None:
        lower, upper = (jnp.broadcast_to(jnp.asarray(b, float), theta0.shape[-1:]) for b in bounds)
        if bool(jnp.any(lower > upper)):
            raise ValueError("every lower bound must be at most its upper bound")
        theta, ok, steps = map_lanes(
            lambda t0, x, y, w: _solve_bounded(
                spec, t0, x, y, w, lower, upper, max_steps=max(max_steps, 500)
            ),
            theta0, data.x, data.y, data.w,
        )
    else:
        theta, ok, steps = map_lanes(
            lambda t0, x, y, w: _solve_batch(spec, solver, t0, x, y, w, max_steps, rtol, atol),
            theta0, data.x, data.y, data.w,
            cache_key=_key("solve", spec, solver, max_steps, rtol, atol),
        )
    theta = np.asarray(theta)
    ok = np.asarray(ok) & np.all(np.isfinite(theta), axis=-1)
    return theta, ok, np.asarray(steps)


def _sarosi_chunk() -> int | None:
    """Lanes per call of the written-out Sárosi kernels: ``CPU_CHUNK_LANES`` on the CPU (the
    arrays of a chunk stay in the caches), ``map_lanes``'s default elsewhere."""
    return CPU_CHUNK_LANES if jax.default_backend() == "cpu" else None


def _key(what: str, spec: ModelSpec, *static) -> tuple | None:
    """The ``cache_key`` of a batched call (None, no caching, for specs not pamid's own)."""
    name = builtin_key(spec)
    return None if name is None else (what, *name, *static)


def statistics(spec: ModelSpec, theta, data: FitData):
    """Per muscle: SSE, (JᵀJ)⁻¹, correlation of model and data, sample count, and whether
    the Jacobian has full rank at the optimum (the constants are identifiable).

    For the Sárosi model, the written-out sums of ``sarosi_statistics`` (two passes over the
    samples; 10,000 muscles of 300 samples: 21 ms, against 128 ms for a Jacobian, QR and SVD
    per lane, the same inverse to 1e-10: ``benchmarks/profile_pieces.py --only-cores``);
    for other models, the Jacobian by ``jax.jacfwd`` and an SVD."""
    if spec.fast_path is not None:
        out = map_lanes(
            spec.fast_path.statistics, jnp.asarray(theta), data.x, data.y, data.w,
            chunk=_sarosi_chunk(),
            cache_key=(f"{spec.fast_path.key}_statistics",),
        )
        return tuple(np.asarray(a) for a in out)
    out = map_lanes(
        lambda t, x, y, w: _statistics(spec, t, x, y, w), jnp.asarray(theta), data.x, data.y,
        data.w, cache_key=_key("statistics", spec),
    )
    return tuple(np.asarray(a) for a in out)
