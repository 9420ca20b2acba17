"""Variable projection for Sárosi eq. 2.1: the exact fit for a fixed a3, and the start values.

With a3 fixed, eq. 2.1 is linear in the other five constants: F = Φ(a3)·β with columns
[p·e, e, κ·p, p, 1], e = exp(a3·κ), β = (a1, a2, a4, a5, a6). The least-squares β(a3) is
a 5×5 solve, so the whole problem reduces to one dimension, S(a3) = min_β ‖w^½(F − Φβ)‖².
We scan S on a grid of a3 for every muscle at once and refine the best point by successive
parabolic interpolation. This gives start values in the basin of the global optimum without
any user guess, and is itself a complete solver (``solver="variable-projection"``).

The grid is in s = a3·κ_span (κ_span the largest contraction in the muscle's data), so it
adapts to the data: s from −30 (the exponential has died out within the first percent) to
+3; s near 0 is skipped, where the exponential is indistinguishable from the linear terms.
"""

from __future__ import annotations

import functools
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ._base import Solver

# NumPy, not jnp: a jnp constant would start the JAX backend at import (benchmarks/README.md,
# "Figures that used to live in docstrings", (h)).
_S_GRID = np.concatenate([-np.geomspace(30.0, 0.05, 20), np.geomspace(0.05, 3.0, 4)])


def _design(a3, p, k):
    e = jnp.exp(a3 * k)
    return jnp.stack([p * e, e, k * p, p, jnp.ones_like(p)], axis=-1)


def _linear_solve(a3, p, k, y, w, accurate=True):
    """β(a3) and S(a3) for one muscle.

    ``accurate``: weighted least squares through a column-scaled QR (used for the answer).
    Otherwise the 5×5 normal equations, equilibrated and solved by Cholesky: several times
    cheaper, accurate enough to rank grid points and refine a start (used in the scan).
    """
    sw = jnp.sqrt(w)
    if accurate:
        phi = _design(a3, p, k) * sw[:, None]
        scale = jnp.sqrt(jnp.sum(phi**2, axis=0))
        scale = jnp.where(scale > 0, scale, 1.0)
        q, r = jnp.linalg.qr(phi / scale)
        z = jax.scipy.linalg.solve_triangular(r, q.T @ (sw * y), lower=False)
    else:
        # Gram entries as elementwise products and sums: far faster under vmap on the CPU
        # than a batch of small matrix products.
        e = jnp.exp(a3 * k)
        cols = [w * p * e, w * e, w * k * p, w * p, w]  # w·φ_j
        raw = [p * e, e, k * p, p, jnp.ones_like(p)]  # φ_j
        upper = {(i, j): jnp.sum(cols[i] * raw[j]) for i in range(5) for j in range(i, 5)}
        diag = jnp.stack([upper[i, i] for i in range(5)])
        scale = jnp.sqrt(jnp.where(diag > 0, diag, 1.0))
        gram = jnp.stack(
            [jnp.stack([upper[min(i, j), max(i, j)] for j in range(5)]) for i in range(5)]
        ) / jnp.outer(scale, scale)
        rhs = jnp.stack([jnp.sum(c * y) for c in cols]) / scale
        z = small_cholesky_solve(gram + 1e-13 * jnp.eye(5), rhs)
        # S = yᵀWy − zᵀ·rhs: no second pass over the samples; the cancellation costs a few
        # digits of S, harmless for ranking grid points.
        sse = jnp.sum(w * y * y) - jnp.dot(z, rhs)
        return z / scale, jnp.where(jnp.isfinite(sse), sse, jnp.inf)
    beta = z / scale
    resid = sw * y - phi @ beta
    sse = jnp.sum(resid**2)
    return beta, jnp.where(jnp.isfinite(sse), sse, jnp.inf)


def sarosi_fit_at_a3(a3, p, k, y, w, *, accurate: bool = True):
    """Eq. 2.1 fitted to one muscle with a3 held: (β, S), β = (a1, a2, a4, a5, a6) the
    weighted least-squares linear constants and S(a3) their sum of squares; p the gauge
    pressure in bar, k the contraction in %, y the force in N, w the weights (n,) each. The
    inner problem of variable projection: S(a3) over a grid of a3 is the profile the starts
    scan. ``accurate``: through a column-scaled QR (exact to rounding); else the equilibrated
    5×5 normal equations (several times cheaper, what the scans use). Pure JAX: ``jax.vmap``
    it over values of a3 or over muscles."""
    return _linear_solve(a3, p, k, y, w, accurate=accurate)


def small_cholesky_solve(a, b, with_pivot=False):
    """Solve a·z = b for a small symmetric positive definite ``a``, unrolled.

    Batched LAPACK calls on 5×5 matrices cost microseconds each on the CPU; written out as
    scalar arithmetic, the solve becomes a few dozen elementwise operations across the batch.
    ``with_pivot``: also return the smallest pivot before clamping (≤ 0: ``a`` is not
    positive definite and z is meaningless).
    """
    n = a.shape[0]
    low = [[None] * n for _ in range(n)]
    pivots = []
    for i in range(n):
        for j in range(i + 1):
            acc = a[i, j] - sum(low[i][m] * low[j][m] for m in range(j))
            if i == j:
                pivots.append(acc)
                low[i][i] = jnp.sqrt(jnp.maximum(acc, 1e-300))
            else:
                low[i][j] = acc / low[j][j]
    z = [None] * n
    for i in range(n):  # forward: L·u = b
        z[i] = (b[i] - sum(low[i][m] * z[m] for m in range(i))) / low[i][i]
    for i in reversed(range(n)):  # backward: Lᵀ·z = u
        z[i] = (z[i] - sum(low[m][i] * z[m] for m in range(i + 1, n))) / low[i][i]
    if with_pivot:
        return jnp.stack(z), jnp.min(jnp.stack(pivots))
    return jnp.stack(z)


def _parabolic_trial(lo, mid, hi, f_lo, f_mid, f_hi, rel_tol):
    """The next point of safeguarded successive parabolic interpolation in the bracket
    (lo, hi) around the best point so far, mid: the vertex of the parabola through the three
    points, or a golden-section step into the larger side where the vertex is not finite,
    leaves the bracket or is within ``rel_tol`` of mid."""
    num = (mid - lo) ** 2 * (f_mid - f_hi) - (mid - hi) ** 2 * (f_mid - f_lo)
    den = (mid - lo) * (f_mid - f_hi) - (mid - hi) * (f_mid - f_lo)
    x = mid - 0.5 * num / jnp.where(den == 0, 1e-300, den)
    golden = jnp.where(hi - mid > mid - lo, mid + 0.382 * (hi - mid), mid - 0.382 * (mid - lo))
    ok = jnp.isfinite(x) & (x > lo) & (x < hi) & (jnp.abs(x - mid) > rel_tol * jnp.abs(mid))
    return jnp.where(ok, x, golden)


def _shrink_bracket(bracket, x, f_x):
    """The bracket (lo, mid, hi, f_lo, f_mid, f_hi) after f(x) = f_x: still around the best
    point found, now x where it is better than mid. Also returns whether it was."""
    lo, mid, hi, f_lo, f_mid, f_hi = bracket
    better, left = f_x < f_mid, x < mid
    return (
        jnp.where(better, jnp.where(left, lo, mid), jnp.where(left, x, lo)),
        jnp.where(better, x, mid),
        jnp.where(better, jnp.where(left, mid, hi), jnp.where(left, hi, x)),
        jnp.where(better, jnp.where(left, f_lo, f_mid), jnp.where(left, f_x, f_lo)),
        jnp.where(better, f_x, f_mid),
        jnp.where(better, jnp.where(left, f_mid, f_hi), jnp.where(left, f_hi, f_x)),
    ), better


def _theta(a3, beta):
    return jnp.stack([beta[0], beta[1], a3, beta[2], beta[3], beta[4]])


def _one_muscle(p, k, y, w, n_refine, accurate):
    span = jnp.max(jnp.where(w > 0, jnp.abs(k), 0.0))
    span = jnp.where(span > 0, span, 1.0)
    grid = _S_GRID / span
    sse = jax.vmap(lambda a: _linear_solve(a, p, k, y, w, accurate=False)[1])(grid)
    i = jnp.clip(jnp.argmin(sse), 1, grid.shape[0] - 2)
    # Bracket around the best grid point, then successive parabolic interpolation
    # (safeguarded: a step that leaves the bracket falls back to golden section).
    lo, mid, hi = grid[i - 1], grid[i], grid[i + 1]

    def reduced(a3):
        # The normal-equation S(a3) loses digits to cancellation near the optimum: good
        # enough for a start, not for the answer of the variable-projection solver.
        return _linear_solve(a3, p, k, y, w, accurate=accurate)[1]

    def refine(_, bracket):
        x = _parabolic_trial(*bracket, rel_tol=1e-15)
        return _shrink_bracket(bracket, x, reduced(x))[0]

    state = (lo, mid, hi, sse[i - 1], sse[i], sse[i + 1])
    lo, mid, hi, _, _, _ = jax.lax.fori_loop(0, n_refine, refine, state)
    beta, sse_best = _linear_solve(mid, p, k, y, w)
    return _theta(mid, beta), sse_best, (hi - lo) / jnp.maximum(jnp.abs(mid), 1e-300)


@functools.partial(jax.jit, static_argnames=("n_refine", "accurate"))
def sarosi_variable_projection(x, y, w, n_refine: int = 40, accurate: bool = True):
    """Fit eq. 2.1 to a batch of muscles by variable projection.

    Args:
        x: (pressure_bar, contraction_pct), each of shape (M, n).
        y: force in N, shape (M, n). w: sample weights (0 for padding), shape (M, n).
        n_refine: parabolic/golden refinement steps after the grid scan.
        accurate: evaluate S(a3) during the refinement through QR (exact to rounding)
            rather than the cheaper normal equations (enough for start values).

    Returns:
        theta (M, 6) ordered a1…a6, the residual sum of squares (M,), and the relative
        width of the final bracket around a3 (M,).
    """
    p, k = x
    return jax.vmap(_one_muscle, in_axes=(0, 0, 0, 0, None, None))(p, k, y, w, n_refine, accurate)


def sarosi_variable_projection_start(x, y, w):
    """Start values for the batched solvers: a short variable-projection solve."""
    return sarosi_variable_projection(x, y, w, n_refine=6, accurate=False)[0]


class VariableProjection(Solver):
    """Variable projection (Golub & Pereyra 1973) for a model with one nonlinear constant:
    its registered profile search (Sárosi eq. 2.1 over a3, :func:`sarosi_variable_projection`
    above); ``max_steps`` refinement steps of the bracket, converged where it has shrunk to
    ``rtol`` (at least 1e-8)."""

    name: ClassVar[str] = "variable-projection"

    def check(self, spec):
        fast = spec.kernels
        if fast is None or fast.variable_projection is None:
            raise ValueError(f"variable projection is written out for the Sárosi model only, "
                             f"not for {spec.name}; use the gauss-newton or "
                             "levenberg-marquardt solver")

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        theta, _, width = spec.kernels.variable_projection(x, y, w, n_refine=max_steps)
        ok = jnp.all(jnp.isfinite(theta), axis=-1) & (width < jnp.maximum(rtol, 1e-8))
        return theta, ok, jnp.full(theta.shape[0], max_steps)
