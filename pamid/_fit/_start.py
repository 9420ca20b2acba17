"""Start values for any model: trial values of its nonlinear constants, the linear ones solved.

A force law is usually linear in most of its constants (Sárosi eq. 2.1 in five of six,
Cullinan eq. 3 in all). For a model ``F = f(θ, x)`` whose constants split into a linear set
L (∂²f/∂θᵢ∂θⱼ = 0 for i, j in L) and the rest N, the least-squares problem in L for fixed N
is linear and has one exact answer (variable projection; Golub & Pereyra 1973). The start is
then a search over N alone: for each of a fixed, space-filling set of trial values of N (the
model's defaults first, then a Halton sequence over ranges set by the bounds and defaults),
L is solved and the residual sum of squares kept; the candidates are returned best first, so
that a solver can be started from one or several of them.

Which constants are linear is found once per model, from the second derivatives of the model
at probe inputs (exact zeros under automatic differentiation), not declared by hand.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

#: Typical magnitude of each named input, for the probes that find the linear constants.
_INPUT_SCALES = {"kPa": 300.0, "bar": 3.0, "MPa": 0.3, "Pa": 3e5, "pct": 10.0, "ratio": 0.1,
                 "mm": 10.0, "m": 0.01, "mm_s": 10.0, "m_s": 0.01, "C": 25.0, "s": 10.0}
#: Trial values of the nonlinear constants: 1 (the defaults) + this many per constant,
#: capped at :data:`MAX_CANDIDATES`.
CANDIDATES_PER_CONSTANT = 15
MAX_CANDIDATES = 64
#: Factor around a nonzero default, on a log scale, searched where no bounds are given.
DEFAULT_SPAN = 10.0


def _input_scale(name: str) -> float:
    unit = name.split("_", 1)[1] if "_" in name else ""
    return _INPUT_SCALES.get(unit, 1.0)


def _fractions(n: int, offset: float) -> np.ndarray:
    """``n`` well-spread numbers in (0, 1): a Weyl sequence (golden ratio)."""
    golden = (math.sqrt(5.0) - 1.0) / 2.0
    return (offset + golden * np.arange(1, n + 1)) % 1.0


def probe_inputs(inputs: tuple[str, ...], n: int = 8) -> tuple:
    """``n`` probe values of each named input, of its typical magnitude, all different."""
    return tuple(
        jnp.asarray(_input_scale(name) * (0.2 + 1.6 * _fractions(n, 0.1 * (i + 1))))
        for i, name in enumerate(inputs)
    )


def linear_constants(predict, n_params: int, inputs: tuple[str, ...], reference,
                     cache_key: tuple | None = None) -> np.ndarray:
    """Which constants the model is linear in, jointly: a boolean mask of length p.

    The Hessian of the model in its constants is taken at ``reference`` (perturbed, so that
    no constant sits at a special value such as 0) at eight probe inputs of typical
    magnitude; constants with a zero second derivative are added one by one while every
    cross derivative with those already taken is zero too.

    ``cache_key``: a name for ``predict`` that is the same in every process (one of pamid's
    own models): the Hessian's program is then kept on disk when the command line keeps
    programs (:mod:`._export_cache`), and a later process does not trace it again.
    """
    probe = probe_inputs(inputs)
    ref = np.asarray(reference, dtype=np.float64)
    bump = _fractions(n_params, 0.37) - 0.5
    theta = jnp.asarray(ref * (1.0 + 0.2 * bump) + 0.05 * bump)
    # One compiled program (kept by the compilation cache), not the model's operations one
    # by one: run eagerly, each operation of the Hessian's trace was a program of its own,
    # 4.6 s of a warm `pamid compare` of one muscle.
    hessian = jax.jacfwd(jax.jacfwd(lambda th: predict(th, probe)))
    if cache_key is None:
        hess = jax.jit(hessian)(theta)  # (n, p, p)
    else:
        from .._lanes._export_cache import call

        hess = call(("linear_constants", *cache_key, tuple(np.asarray(ref).tolist())),
                    hessian, theta)
    size = np.nanmax(np.abs(np.asarray(hess)), axis=0)
    size = np.where(np.isfinite(size), size, np.inf)
    zero = size <= 1e-12 * max(float(np.max(np.where(np.isfinite(size), size, 0.0))), 1e-300)
    linear = np.zeros(n_params, dtype=bool)
    for i in range(n_params):
        if zero[i, i] and all(zero[i, j] for j in np.flatnonzero(linear)):
            linear[i] = True
    return linear


def trial_values(defaults, lower, upper, nonlinear: np.ndarray) -> np.ndarray:
    """Trial values of the constants, (K, p): the defaults first, then a Halton-like design
    over each nonlinear constant's range (its bounds; else a factor of
    :data:`DEFAULT_SPAN` around a nonzero default, on a log scale; else ±1 around 0).
    Linear constants keep their defaults (the start solves them)."""
    defaults = np.asarray(defaults, dtype=np.float64)
    idx = np.flatnonzero(nonlinear)
    k = min(1 + CANDIDATES_PER_CONSTANT * len(idx), MAX_CANDIDATES) if len(idx) else 1
    out = np.tile(defaults, (k, 1))
    for col, j in enumerate(idx):
        u = _fractions(k - 1, 0.5 / (col + 2))  # a different sequence per constant
        d, lo, hi = defaults[j], lower[j], upper[j]
        if np.isfinite(lo) and np.isfinite(hi):
            a, b = lo, hi
        elif d != 0:
            a, b = sorted((d / DEFAULT_SPAN, d * DEFAULT_SPAN))
            a, b = max(a, lo), min(b, hi)
        else:
            a, b = max(-1.0, lo), min(1.0, hi)
            if not np.isfinite(a):
                a = b - 2.0
            if not np.isfinite(b):
                b = a + 2.0
        if a > 0 and b / a > 20:
            values = a * (b / a) ** u
        elif b < 0 and a / b > 20:
            values = b * (a / b) ** u
        else:
            values = a + (b - a) * u
        out[1:, j] = values
    return out


#: Smallest Cholesky pivot of a trial's equilibrated normal matrix (unit diagonal) for which
#: the start solves the linear constants from the normal equations, written out
#: (:func:`pamid._solvers.small_cholesky_solve`), then refined once with the
#: residual of the design itself (corrected semi-normal equations, Björck 1996, §2.8.4): the
#: error of the normal equations alone, about 1e-16 / pivot, is squared away. Where a lane
#: of a batch has a smaller pivot (dependent columns, a constant the data do not see), the
#: whole batch is solved by an SVD instead.
CHOLESKY_PIVOT = 1e-8
#: Most linear constants solved by the written-out Cholesky. Its trace grows as the cube of
#: their number (n³/6 scalar operations, twice for the refinement): for 20 constants, 9 s of
#: a profiled 20 s ``pamid fit --intervals wald``; for 50, not done in 120 s; above this,
#: one batched LAPACK Cholesky (benchmarks/README.md, "Models of many constants").
UNROLLED_CHOLESKY_MAX = 8


def _lapack_cholesky_solve(gram, c):
    """``(z, smallest pivot)`` of gram·z = c over a batch (…, n, n), as
    :func:`pamid._solvers.small_cholesky_solve` gives them, by LAPACK. A
    matrix that is not positive definite (NaN factor) gets the pivot −inf, so that the
    caller falls back to the SVD."""
    low = jnp.linalg.cholesky(gram)
    diag = jnp.diagonal(low, axis1=-2, axis2=-1)
    pivot = jnp.min(diag**2, axis=-1)
    ok = jnp.all(jnp.isfinite(low), axis=(-2, -1))
    from jax.scipy.linalg import cho_solve

    z = cho_solve((low, True), c[..., None])[..., 0]
    return z, jnp.where(ok, pivot, -jnp.inf)


def projected_candidates(predict, linear: np.ndarray, trials: np.ndarray, lower, upper):
    """A batched start function ``(x, y, w, clip=True) -> (theta (M, K, p), sse (M, K))``,
    candidates sorted best first, each with its linear constants solved by weighted least
    squares for the trial values of the others, then clipped into the bounds (unless
    ``clip`` is False). For a model linear in every constant the one candidate is the
    weighted least-squares fit itself, and with ``clip=False`` the fit without bounds.

    The least-squares problems (columns scaled to unit length) are solved from their normal
    equations by an unrolled Cholesky, a few dozen elementwise operations across the batch:
    a batched SVD (one LAPACK call per lane and trial) took 40 % of the time of Cullinan
    fits of 1000 muscles (``benchmarks/run.py --quick --only cullinan``; benchmarks/README.md,
    "Figures that used to live in docstrings", (g)). A
    batch with a nearly singular design (:data:`CHOLESKY_PIVOT`) is solved by the SVD,
    which tolerates a rank-deficient design (a constant the data do not see stays at 0)."""
    from .._solvers import small_cholesky_solve

    # NumPy constants, not JAX arrays: the spec keeps this function, and it may first be
    # made while a caller is being traced (a JAX array made then would be a tracer that
    # leaks into every later call).
    lin = np.flatnonzero(linear)
    n_lin = int(np.sum(linear))
    trials = np.asarray(trials, dtype=np.float64)
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)

    def design(theta, x, y, w):
        """One trial's problem in the linear constants: base, scaled design, rhs, scale."""
        base = theta.at[lin].set(0.0)
        f0 = predict(base, x)
        g = jax.jacfwd(lambda b: predict(base.at[lin].set(b), x))(jnp.zeros(n_lin))
        sw = jnp.sqrt(w)
        a = sw[:, None] * g
        norm = jnp.sqrt(jnp.sum(a**2, axis=0))
        scale = jnp.where(norm > 0, 1.0 / norm, 0.0)
        return base, a * scale, sw * (y - f0), scale

    def svd_solve(a, rhs):
        return jnp.linalg.lstsq(a, rhs, rcond=1e-10)[0]

    def finish(theta, x, y, w, clip):
        if clip:
            theta = jnp.clip(theta, lower, upper)
        sse = jnp.sum(w * (predict(theta, x) - y) ** 2)
        return theta, jnp.where(jnp.isfinite(sse), sse, jnp.inf)

    def cholesky(gram, c):
        if n_lin > UNROLLED_CHOLESKY_MAX:
            return _lapack_cholesky_solve(gram, c)
        return jax.vmap(jax.vmap(lambda g, c: small_cholesky_solve(g, c, with_pivot=True)))(
            gram, c)

    def each(fn, trial_axis, *static):
        """``fn`` over the muscles (axis 0 of x, y, w) and the trials."""
        one = lambda theta, x, y, w: fn(theta, x, y, w, *static)  # noqa: E731
        return jax.vmap(jax.vmap(one, in_axes=(0, None, None, None)),
                        in_axes=(trial_axis, 0, 0, 0))

    def batch(x, y, w, clip=True):
        theta = jnp.broadcast_to(trials, (y.shape[0], *trials.shape))
        if n_lin:
            base, a, rhs, scale = each(design, None)(trials, x, y, w)  # (M, K, …)
            gram = jnp.einsum("mkni,mknj->mkij", a, a)
            beta, pivot = cholesky(gram, jnp.einsum("mkni,mkn->mki", a, rhs))
            # One refinement from the design's own residual (see CHOLESKY_PIVOT).
            left = rhs - jnp.einsum("mkni,mki->mkn", a, beta)
            beta = beta + cholesky(gram, jnp.einsum("mkni,mkn->mki", a, left))[0]
            beta = jax.lax.cond(jnp.all(pivot > CHOLESKY_PIVOT), lambda: beta,
                                lambda: jax.vmap(jax.vmap(svd_solve))(a, rhs))
            theta = base.at[..., lin].set(beta * scale)
        theta, sse = each(finish, 0, clip)(theta, x, y, w)
        order = jnp.argsort(sse, axis=-1)
        return (jnp.take_along_axis(theta, order[..., None], axis=1),
                jnp.take_along_axis(sse, order, axis=1))

    # Compiled once per model (the spec keeps this function): called op by op, the start
    # of a linear model took 40 times its whole fit (benchmarks/README.md, "Figures that
    # used to live in docstrings", (g)).
    return jax.jit(batch, static_argnames="clip")
