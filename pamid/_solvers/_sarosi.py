"""Batched Gauss–Newton for Sárosi eq. 2.1, written out for speed: the default Sárosi solver.

Eq. 2.1, F = (a1·p + a2)·e + a4·κ·p + a5·p + a6 with e = exp(a3·κ), has the Jacobian
∂F/∂(a1…a6) = (p·e, e, (a1·p + a2)·κ·e, κ·p, p, 1) (differentiating eq. 2.1). Every muscle of
a batch is fitted at once, with arrays of shape (M, n): M muscles by n samples.

Where the time goes, and what this module does about it (measured with
``benchmarks/profile_pieces.py``):

1. One loop over the samples per iteration. An iteration needs the 15 entries of JᵀJ that
   change with the constants (those of the columns κ·p, p, 1 are computed once), Jᵀr, rᵀr,
   three second-order sums and one maximum for the convergence test: all accumulated in
   one variadic ``lax.reduce``, one loop instead of ~25. The exponential is computed before
   that loop, behind an optimisation barrier: fused into the reduction, XLA recomputes it
   for every sum (3× slower).
2. A cheap start. Variable projection (``_variable_projection.py``) reduces the fit to one
   dimension, a3. The start scans S(a3) on a coarse grid, using an evenly spaced subsample
   of each muscle (at most ``START_SAMPLES`` samples), and refines the best grid point by a
   few parabolic steps; Gauss–Newton converges from far worse starts (a3 off by a factor 2,
   see tests/test_fast_fit.py): the scan only has to find the basin of the global optimum.
3. Few iterations. Gauss–Newton steps (6×6 normal equations, equilibrated, unrolled
   Cholesky), switching to Newton steps (JᵀJ plus Σ r·∂²F, when positive definite) once the
   steps are below 1 %: ~5 passes from the start on Sárosi's design. Under the batched loop
   every lane runs until the slowest has converged; a lane that has converged (or failed)
   stops changing.

Convergence is optimistix's Cauchy test with the same tolerances (``GaussNewton(rtol,
atol)``): the last step is small in every constant, |Δθ_i| < atol + rtol·|θ_i|, and in every
weighted residual, |Δr_n| < atol + rtol·|r_n|. Δr is evaluated to first order, Δr ≈ J·Δθ
with J at the new point; the neglected term is ½·Δθᵀ(∂²r/∂θ²)Δθ, about 1e-16 N when the
test is met (|Δa3| ≲ 1e-11/%: (a1·p + a2)·κ²·e·Δa3² ≲ 1e-16), far below atol. A step that
multiplies the residual sum of squares by more than ``GROW_LIMIT`` (or makes it non-finite)
is halved; optimistix's Gauss–Newton has no safeguard. A lane whose step is not finite stops,
not converged; so does one whose step was halved below the tolerance. Beside the Cauchy
test, an SSE test (``STALL_RTOL``): a lane whose SSE has stopped falling converges where its
steps are below ``STALL_STEP`` (rounding may keep them above the Cauchy tolerance on large
files). A lane that has not converged returns the lowest-SSE point it evaluated.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._inference import RANK_PIVOT  # the one rank criterion (``pamid._inference``)
from ._variable_projection import _parabolic_trial, _shrink_bracket, small_cholesky_solve

#: Largest subsample of a muscle scanned for the start (evenly spaced over its samples).
START_SAMPLES = 64
#: Most strides for which the subsample is taken by strided slices (see ``_subsample``).
SUBSAMPLE_MAX_STRIDES = 16

#: Relative step size (largest over the constants) of the last step below which the exact
#: Hessian replaces JᵀJ (when it is positive definite): Newton near the optimum.
NEWTON_BELOW = 0.01

#: A step that multiplies the SSE by more than this (or makes it non-finite) is halved.
#: Not 1: in narrow curved valleys full Gauss–Newton steps that raise the SSE a little
#: still converge (as optimistix's Gauss–Newton, which has no safeguard, does), while
#: halving every such step crawls; not 10 either, which lets a start with a3 three times too
#: large wander off (both measured on synthetic muscles; tests/test_fast_fit.py).
GROW_LIMIT = 2.0

#: The SSE test beside the Cauchy one: a lane whose SSE has not fallen by more than
#: ``STALL_RTOL`` of itself in ``STALL_PASSES`` accepted passes, and whose last step is
#: below ``STALL_STEP`` of every constant (atol-floored), stands at an optimum that rounding
#: keeps the Cauchy test from confirming (on tens of thousands of rows of residuals of tens
#: of newtons, Jᵀr carries rounding of n·ε·Σ|J||r|, and the steps it makes may stay above
#: rtol·|θ| = 1e-10·|θ| for ever): it counts as converged. A lane whose SSE stalls while its
#: constants still move is on a ridge (constants growing without bound) and goes on, not
#: converged, to its last pass: accepted steps that raise the SSE (``GROW_LIMIT``) are how
#: it crosses curved valleys, so the test does not cut them short.
STALL_RTOL = 1e-12
STALL_PASSES = 10
STALL_STEP = 1e-6


#: Successive parabolic steps that refine the best grid point of the start's scan.
START_REFINE = 4

#: The start's grid in s = a3·κ_span (κ_span: the largest contraction of the muscle), like
#: the variable-projection grid but coarser: s from −30 (the exponential has died out within
#: the first few percent of the range) to +3, skipping |s| < 0.05, where the exponential is
#: indistinguishable from the linear terms.
START_GRID = tuple(
    float(s) for s in np.concatenate([-np.geomspace(30.0, 0.05, 12), np.geomspace(0.05, 3.0, 3)])
)


def _reduce_samples(sums, maxima=()):
    """Sums and maxima over the last (sample) axis, all in one loop over the samples."""
    ops = tuple(sums) + tuple(maxima)
    init = tuple(jnp.zeros((), o.dtype) for o in sums) + tuple(
        jnp.full((), -jnp.inf, o.dtype) for o in maxima
    )
    n_sum = len(sums)

    def combine(a, b):
        return tuple(
            x + z if i < n_sum else jnp.maximum(x, z) for i, (x, z) in enumerate(zip(a, b))
        )

    return jax.lax.reduce(ops, init, combine, (ops[0].ndim - 1,))


def solve_scaled(mat, rhs, ridge, with_pivot=False):
    """Solve mat·z = rhs per lane, mat (..., q, q) symmetric positive semi-definite: scaled to
    unit diagonal, with ``ridge`` added to the diagonal, by an unrolled Cholesky. ``rhs`` is
    (..., q), or (..., q, k) for k right-hand sides at once (one factorisation).
    ``with_pivot``: also return the smallest pivot (≤ 0: not positive definite)."""
    diag = jnp.diagonal(mat, axis1=-2, axis2=-1)
    d = jnp.sqrt(jnp.where(diag > 0, diag, 1.0))
    scaled = mat / (d[..., :, None] * d[..., None, :]) + ridge * jnp.eye(mat.shape[-1])
    batch = mat.shape[:-2]
    d_rhs = d if rhs.ndim == mat.ndim - 1 else d[..., None]
    flat_a = scaled.reshape(-1, *scaled.shape[-2:])
    flat_b = (rhs / d_rhs).reshape(-1, *rhs.shape[len(batch):])
    z, pivot = jax.vmap(lambda a, b: small_cholesky_solve(a, b, with_pivot=True))(flat_a, flat_b)
    z = z.reshape(rhs.shape) / d_rhs
    return (z, pivot.reshape(batch)) if with_pivot else z


def _span(k, w):
    span = jnp.max(jnp.where(w > 0, jnp.abs(k), 0.0), axis=-1)
    return jnp.where(span > 0, span, 1.0)


def _subsample(arrays, w, n_sub):
    """At most ``n_sub`` evenly spaced samples per lane: every s-th, with the stride s the
    smallest that covers the lane's samples up to its last one of positive weight (padding
    sits at the end). Strided slices selected per lane, not a gather (several times slower
    on the CPU). Lanes with ``n_sub`` samples or fewer keep all of them. Beyond
    ``SUBSAMPLE_MAX_STRIDES`` strides, a gather: one slice per stride made the program grow
    with n (one muscle of 100,000 samples: 1,563 slices, 23 s of CPU and 3 GB to compile)."""
    n = w.shape[-1]
    if n <= n_sub:
        return arrays, w
    pos = jnp.arange(1, n + 1)
    n_pos = jnp.max(jnp.where(w > 0, pos, 0), axis=-1, keepdims=True)  # (M, 1)
    stride = jnp.maximum((n_pos + n_sub - 1) // n_sub, 1)
    if -(-n // n_sub) > SUBSAMPLE_MAX_STRIDES:
        idx = jnp.arange(n_sub) * stride  # (M, n_sub); past the lane's end: weight 0
        take = lambda a: jnp.where(  # noqa: E731
            idx < n, jnp.take_along_axis(a, jnp.minimum(idx, n - 1), axis=-1), 0.0)
        return tuple(take(a) for a in arrays), take(w)

    def pick(a):
        out = jnp.zeros_like(a[..., :n_sub])
        for s in range(1, -(-n // n_sub) + 1):
            cand = a[..., ::s][..., :n_sub]
            cand = jnp.pad(cand, [(0, 0)] * (a.ndim - 1) + [(0, n_sub - cand.shape[-1])])
            out = jnp.where(stride == s, cand, out)
        return out

    return tuple(pick(a) for a in arrays), pick(w)


def _monomials(p, k, y, w):
    """Per-sample products the scan needs, materialised once (XLA would otherwise recompute
    them inside every sum): w·(p², p, 1, κ·p², κ·p, p·y, y)."""
    wp = w * p
    return jax.lax.optimization_barrier((wp * p, wp, w, wp * k * p, wp * k, wp * y, w * y))


def _fixed_gram(p, k, y, w):
    """Weighted sums that do not depend on a3: Gram entries of the columns (κ·p, p, 1), their
    products with y, and yᵀWy. Returns the 3×3 Gram (M, 3, 3), the vector (M, 3) and yᵀWy."""
    kp = k * p
    s = _reduce_samples(
        [
            w * kp * kp,
            w * kp * p,
            w * kp,
            w * p * p,
            w * p,
            w,
            w * kp * y,
            w * p * y,
            w * y,
            w * y * y,
        ]
    )
    g = jnp.stack(
        [
            jnp.stack([s[0], s[1], s[2]], -1),
            jnp.stack([s[1], s[3], s[4]], -1),
            jnp.stack([s[2], s[4], s[5]], -1),
        ],
        -2,
    )
    return g, jnp.stack(s[6:9], -1), s[9]


def _profile(a3, k, mono, fixed):
    """β(a3) and S(a3) of eq. 2.1 for a3 of shape (M, K): the 5×5 normal equations of the
    columns (p·e, e, κ·p, p, 1), e = exp(a3·κ), equilibrated. Returns β (M, K, 5), S (M, K).

    S = yᵀWy − βᵀΦᵀWy loses digits to cancellation near the optimum: enough to rank grid
    points and place a start, not for the answer (Gauss–Newton gives that)."""
    wpp, wp, w, wkpp, wkp, wpy, wy = mono
    g_fix, b_fix, yy = fixed

    def grid_sums(_, a):
        # One a3 per lane at a time, so that the samples stay in the cache: its e, then the
        # Gram entries of (p·e, e) with themselves and with (κ·p, p, 1), and Φᵀ·W·y.
        e = jax.lax.optimization_barrier(jnp.exp(a[:, None] * k))
        e2 = e * e
        terms = [
            wpp * e2,
            wp * e2,
            w * e2,
            wkpp * e,
            wpp * e,
            wp * e,
            wkp * e,
            w * e,
            wpy * e,
            wy * e,
        ]
        return None, jnp.stack(_reduce_samples(terms), -1)

    _, sums = jax.lax.scan(grid_sums, None, a3.T)  # (K, M, 10)
    sums = jnp.moveaxis(sums, 0, 1)  # (M, K, 10)
    pe2, pe_e, e2, pe_kp, pe_p, pe_1, e_kp, e_1, pe_y, e_y = (sums[..., i] for i in range(10))
    gf = jnp.broadcast_to(g_fix[:, None], (*a3.shape, 3, 3))
    rows = [
        [pe2, pe_e, pe_kp, pe_p, pe_1],
        [pe_e, e2, e_kp, pe_1, e_1],
        [pe_kp, e_kp, gf[..., 0, 0], gf[..., 0, 1], gf[..., 0, 2]],
        [pe_p, pe_1, gf[..., 1, 0], gf[..., 1, 1], gf[..., 1, 2]],
        [pe_1, e_1, gf[..., 2, 0], gf[..., 2, 1], gf[..., 2, 2]],
    ]
    gram = jnp.stack([jnp.stack(r, -1) for r in rows], -2)
    rhs = jnp.concatenate(
        [jnp.stack([pe_y, e_y], -1), jnp.broadcast_to(b_fix[:, None], (*a3.shape, 3))], -1
    )
    beta = solve_scaled(gram, rhs, 1e-13)
    sse = yy[:, None] - jnp.sum(beta * rhs, -1)
    return beta, jnp.where(jnp.isfinite(sse), sse, jnp.inf)


@functools.partial(jax.jit, static_argnames=("grid", "n_sub", "n_refine"))
def sarosi_fast_start(x, y, w, grid=START_GRID, n_sub=START_SAMPLES, n_refine=START_REFINE):
    """Start values for Gauss–Newton: a coarse variable-projection scan on a subsample.

    For each s of ``grid`` (a3 = s/κ_span), the linear constants β = (a1, a2, a4, a5, a6) of
    eq. 2.1 solve the 5×5 normal equations, giving S(a3). The best grid point and its
    neighbours bracket the minimum, which ``n_refine`` steps of safeguarded successive
    parabolic interpolation refine (as in ``_variable_projection.py``); the start is that
    a3 with its β. All on an evenly spaced subsample of at most ``n_sub`` samples per muscle.

    Args:
        x: (pressure_bar, contraction_pct), each (M, n). y: force in N, (M, n).
        w: sample weights (0 for padding), (M, n).

    Returns:
        theta0 (M, 6), ordered a1…a6.
    """
    p, k = x
    span = _span(k, w)
    (p, k, y), w = _subsample((p, k, y), w, n_sub)
    mono = _monomials(p, k, y, w)
    fixed = _fixed_gram(p, k, y, w)
    s = jnp.asarray(grid)
    a_grid = s[None, :] / span[:, None]  # (M, K)
    beta, sse = _profile(a_grid, k, mono, fixed)
    i = jnp.argmin(sse, axis=-1)
    ic = jnp.clip(i, 1, len(grid) - 2)[:, None]
    pick = lambda a, j: jnp.take_along_axis(a, j, axis=1)[:, 0]  # noqa: E731
    lo, mid, hi = pick(a_grid, ic - 1), pick(a_grid, ic), pick(a_grid, ic + 1)
    f_lo, f_mid, f_hi = pick(sse, ic - 1), pick(sse, ic), pick(sse, ic + 1)
    b_mid = jnp.take_along_axis(beta, ic[..., None], axis=1)[:, 0]

    def refine(_, state):
        # Successive parabolic interpolation, safeguarded by golden section; the bracket
        # always holds the best point found, mid, whose β is kept beside it.
        bracket, b_mid = state
        t = _parabolic_trial(*bracket, rel_tol=1e-12)
        b_t, f_t = _profile(t[:, None], k, mono, fixed)
        bracket, better = _shrink_bracket(bracket, t, f_t[:, 0])
        return bracket, jnp.where(better[:, None], b_t[:, 0], b_mid)

    # A loop, not unrolled: the command line traces this function in every process.
    state = ((lo, mid, hi, f_lo, f_mid, f_hi), b_mid)
    (_, mid, *_), b = jax.lax.fori_loop(0, n_refine, refine, state)
    return jnp.stack([b[:, 0], b[:, 1], mid, b[:, 2], b[:, 3], b[:, 4]], -1)


def _pass(theta, step, p, k, y, w, sw, rtol, atol, newton, full=True, curve=None):
    """One pass over the samples at ``theta``: the 15 JᵀWJ entries that depend on the
    constants (rows a1…a3, upper part), JᵀWr, rᵀWr, max_n (|(J·step)_n| − rtol·|r_n|) with
    weighted residuals r, and Σ w·r·∂²F/∂a3∂(a1, a2, a3), the second-order part of the
    Hessian (the other second derivatives of eq. 2.1 vanish; zeros unless ``newton`` > 0).

    ``full=False``: only rᵀWr and the maximum (a pass that only checks convergence); the
    other outputs are zeros. ``curve`` (M, n): also, as a sixth output, the sums of the
    weighted residual's lag-1 autocorrelation within curves, (Σ pair·rₜ·r_{t−1}, Σ rₜ² over
    rows of a curve, pairs) as :func:`pamid._fit._least_squares.lag1_sums` defines them, in
    the same loop over the samples (measured at 100 muscles: +80 µs on this pass's 130; the
    same sums as reductions of their own: +150 µs).
    """
    a1, a2, a3, a4, a5, a6 = (theta[:, i : i + 1] for i in range(6))
    e = jax.lax.optimization_barrier(jnp.exp(a3 * k))
    g = a1 * p + a2
    kp = k * p
    r = g * e + a4 * kp + a5 * p + a6 - y  # unweighted residual, eq. 2.1 − data
    u3 = k * g * e  # ∂F/∂a3; ∂F/∂(a1, a2, a4, a5, a6) = (p·e, e, κ·p, p, 1)
    j_step = sum(c * step[:, i : i + 1] for i, c in enumerate([p * e, e, u3, kp, p, 1.0]))
    # |Δr_n| < atol + rtol·|r_n| for every n ⇔ max_n (|Δr_n| − rtol·|r_n|) < atol.
    excess = sw * (jnp.abs(j_step) - rtol * jnp.abs(r))
    wr = w * r
    zero = jnp.zeros(theta.shape[:1], theta.dtype)
    if not full:
        sse, worst = _reduce_samples([wr * r], [excess])
        return [zero] * 15, jnp.zeros_like(theta), sse, worst, [zero] * 3
    wpe, we = w * p * e, w * e
    terms = [wpe * p * e, wpe * e, wpe * u3, wpe * kp, wpe * p, wpe]
    terms += [we * e, we * u3, we * kp, we, w * u3 * u3, w * u3 * kp, w * u3]
    terms += [wpe * r, we * r, wr * kp, wr * p, wr, wr * r, wr * kp * e, wr * k * e]
    if newton > 0:
        terms += [wr * k * u3]
    n_terms = len(terms)
    if curve is not None:
        swr = sw * r
        prev = jnp.pad(swr[:, :-1], ((0, 0), (1, 0)))  # the row before (row 0: unpaired)
        pair = jnp.pad((curve[:, 1:] == curve[:, :-1]) & (curve[:, 1:] >= 0), ((0, 0), (1, 0)))
        terms += [pair * swr * prev, jnp.where(curve >= 0, swr * swr, 0.0),
                  pair.astype(theta.dtype)]
    out = _reduce_samples(terms, [excess])
    pe_pe, pe_e, pe_u3, pe_kp, pe_p, pe_1, e_e, e_u3, e_kp, e_1, u3_u3, u3_kp, u3_1 = out[:13]
    pe_r, e_r, kp_r, p_r, r_1, sse, kpe_r, ke_r = out[13:21]
    b1, b2 = a1[:, 0], a2[:, 0]
    # Σ w·(κ·g·e)·p = a1·Σ w·κ·p²·e + a2·Σ w·κ·p·e, and likewise (κ·g·e)ᵀWr; Σ w·e·p is
    # Σ w·(p·e)·1: three sums fewer in the loop.
    varying = [
        pe_pe,
        pe_e,
        pe_u3,
        pe_kp,
        pe_p,
        pe_1,
        e_e,
        e_u3,
        e_kp,
        pe_1,
        e_1,
        u3_u3,
        u3_kp,
        b1 * pe_kp + b2 * e_kp,
        u3_1,
    ]
    jtr = jnp.stack([pe_r, e_r, b1 * kpe_r + b2 * ke_r, kp_r, p_r, r_1], -1)
    second = [kpe_r, ke_r, out[21] if newton > 0 else zero]
    if curve is not None:
        return varying, jtr, sse, out[-1], second, tuple(out[n_terms:n_terms + 3])
    return varying, jtr, sse, out[-1], second


def _fixed_jtj(p, k, y, w):
    """JᵀJ entries of the columns (κ·p, p, 1), which do not depend on the constants (the
    last of them is Σw, the sample count), yᵀWy and Σ w·y."""
    kp = k * p
    wy = w * y
    return _reduce_samples([w * kp * kp, w * kp * p, w * kp, w * p * p, w * p, w, wy * y, wy])


def _jtj(varying, fixed):
    """Assemble the symmetric 6×6 JᵀJ (M, 6, 6) from its 15 varying and 6 fixed entries."""
    upper = {}
    it = iter(varying)
    for i in range(3):
        for j in range(i, 6):
            upper[i, j] = next(it)
    it = iter(fixed)
    for i in range(3, 6):
        for j in range(i, 6):
            upper[i, j] = next(it)
    return jnp.stack(
        [jnp.stack([upper[min(i, j), max(i, j)] for j in range(6)], -1) for i in range(6)], -2
    )


def _hessian(jtj, second):
    """The Hessian of rᵀWr/2, JᵀWJ (…, 6, 6) plus the second-order sums of :func:`_pass`:
    Σ w·r·∂²F/∂a3∂(a1, a2, a3), the only second derivatives of eq. 2.1 that do not vanish."""
    hess = jtj.at[..., 0, 2].add(second[0]).at[..., 2, 0].add(second[0])
    hess = hess.at[..., 1, 2].add(second[1]).at[..., 2, 1].add(second[1])
    return hess.at[..., 2, 2].add(second[2])


@functools.partial(jax.jit, static_argnames=("max_steps", "rtol", "atol", "newton", "grow"))
def sarosi_gauss_newton(
    x,
    y,
    w,
    theta0=None,
    max_steps=100,
    rtol=1e-10,
    atol=1e-10,
    newton=NEWTON_BELOW,
    grow=GROW_LIMIT,
):
    """Fit eq. 2.1 to every muscle of a batch by Gauss–Newton.

    Args:
        x: (pressure_bar, contraction_pct), each (M, n). y: force in N, (M, n).
        w: sample weights (0 for padding), (M, n).
        theta0: start values (M, 6); default :func:`sarosi_fast_start`.
        max_steps: passes over the data (function evaluations), as optimistix counts steps.
        rtol, atol: tolerances of the convergence test (see the module docstring).
        newton: relative step size below which Newton steps replace Gauss–Newton steps
            (0: Gauss–Newton throughout).
        grow: SSE growth factor above which a step is halved.

    Returns:
        theta (M, 6), converged (M,) and the number of passes per lane (M,).
    """
    p, k = x
    if theta0 is None:
        theta0 = sarosi_fast_start(x, y, w)
    theta0 = jnp.asarray(theta0, dtype=jnp.float64)
    m = theta0.shape[0]
    sw = jnp.sqrt(w)
    *fixed, yy, _ = _fixed_jtj(p, k, y, w)
    # SSE changes below this are rounding: residuals of 1e-12 of the data (noiseless data
    # reach it at the optimum, where the SSE is rounding noise).
    sse_floor = 1e-24 * yy
    false = jnp.zeros(m, bool)

    def cond(state):
        it, active = state[0], state[6]
        return (it < max_steps) & jnp.any(active)

    def body(state):
        (it, theta, theta_prev, step, sse_prev, has_prev, active, converged, steps, full_next,
         best, best_sse, anchor, stall) = state
        small = jnp.max(jnp.abs(step) / (atol + rtol * jnp.abs(theta)), axis=-1) < 1
        # When the last step of every active lane is below the tolerance, this pass can only
        # confirm convergence: the cheap one (rᵀr and the residual test) does. A lane it
        # does not confirm stays where it is and gets a full pass next.
        check_only = jnp.all(~active | (has_prev & small)) & ~full_next
        varying, jtr, sse, worst, second = jax.lax.cond(
            check_only,
            lambda: _pass(theta, step, p, k, y, w, sw, rtol, atol, newton, full=False),
            lambda: _pass(theta, step, p, k, y, w, sw, rtol, atol, newton),
        )
        # A step that raised the SSE more than ``grow``-fold (or left it non-finite) is
        # halved, from the last point.
        worse = has_prev & ~(sse <= sse_prev * (grow + 1e-10) + sse_floor)
        done = has_prev & ~worse & small & (worst < atol)
        redo = check_only & active & ~done & ~worse
        # The lowest SSE evaluated so far: what a lane that does not converge returns.
        better = active & (sse < best_sse)
        best = jnp.where(better[:, None], theta, best)
        best_sse = jnp.where(better, sse, best_sse)
        # The SSE test (``STALL_RTOL``): accepted passes since the SSE last fell by more than
        # that (a step being halved is not counted: it has not been tried yet).
        fell = best_sse < anchor * (1.0 - STALL_RTOL) - sse_floor
        anchor = jnp.where(active & fell, best_sse, anchor)
        stall = jnp.where(active & fell, 0, stall + (active & ~worse))
        tiny = jnp.max(jnp.abs(step) / (atol + STALL_STEP * jnp.abs(theta)), axis=-1) < 1
        done = done | (active & has_prev & ~worse & (stall >= STALL_PASSES) & tiny)
        jtj = _jtj(varying, fixed)
        new_step = -solve_scaled(jtj, jtr, 1e-14)
        if newton > 0:
            hess = _hessian(jtj, second)
            n_step, pivot = solve_scaled(hess, jtr, 1e-14, with_pivot=True)
            rel = jnp.max(jnp.abs(step) / jnp.maximum(jnp.abs(theta), 1e-300), axis=-1)
            near = has_prev & (rel < newton)
            new_step = jnp.where(((pivot > 0) & near)[:, None], -n_step, new_step)
        stuck = worse & small  # halving cannot help any more
        failed = ~check_only & ~worse & ~done & ~jnp.all(jnp.isfinite(new_step), axis=-1)
        go = active & ~(done | stuck | failed)
        move = go & ~redo
        step_out = jnp.where(worse[:, None], step / 2, new_step)
        base = jnp.where(worse[:, None], theta_prev, theta)
        keep = ~move[:, None]
        return (
            it + 1,
            jnp.where(keep, theta, base + step_out),
            jnp.where(keep, theta_prev, base),
            jnp.where(keep, step, step_out),
            jnp.where(move & ~worse, sse, sse_prev),
            has_prev | move,
            go,
            converged | (active & done),
            steps + active,
            jnp.any(redo),
            best,
            best_sse,
            anchor,
            stall,
        )

    state = (
        jnp.array(0),
        theta0,
        theta0,
        jnp.zeros_like(theta0),
        jnp.full(m, jnp.inf),
        false,
        jnp.all(jnp.isfinite(theta0), axis=-1),
        false,
        jnp.zeros(m, jnp.int32),
        jnp.array(False),
        theta0,
        jnp.full(m, jnp.inf),
        jnp.full(m, jnp.inf),
        jnp.zeros(m, jnp.int32),
    )
    out = jax.lax.while_loop(cond, body, state)
    theta, converged, steps, best = out[1], out[7], out[8], out[10]
    # A lane that has not converged returns the best point it evaluated (never worse than
    # its start), not a trial step that nobody has evaluated or one that raised the SSE.
    theta = jnp.where(converged[:, None], theta, best)
    return theta, converged, steps


@jax.jit
def sarosi_statistics(theta, x, y, w, curve=None):
    """What the intervals need at the fitted constants, from two passes over the samples.

    Returns, per muscle: SSE, (JᵀWJ)⁻¹ (6×6), the correlation R of data and model, the
    sample count Σw, and whether JᵀWJ is positive definite to working precision (the
    constants are determined by the data); with ``curve`` (M, n), also the three sums of
    the residual's lag-1 autocorrelation within curves
    (:func:`pamid._fit._least_squares.lag1_sums`) from the same pass (:func:`_pass`).
    (JᵀWJ)⁻¹ is the inverse of the normal matrix, equilibrated to unit diagonal and
    factorised by an unrolled Cholesky; where its smallest
    pivot is below ``RANK_PIVOT`` (the columns of J are dependent to about 1e-6.5 of their
    length), the muscle is rank-deficient and the inverse is +inf.

    R from the same sums: with the model m = y + r, Σw·r·m = Σ_j θ_j·(Jᵀ W r)_j over the
    columns in which eq. 2.1 is linear, so Σw·r·y = Σw·r·m − rᵀWr.
    """
    p, k = x
    zero = jnp.zeros_like(theta)
    varying, jtr, sse, _, _, *lag1 = _pass(theta, zero, p, k, y, w, jnp.sqrt(w), 0.0, 0.0, 0,
                                           curve=curve)
    *fixed, yy, sum_y = _fixed_jtj(p, k, y, w)
    n = fixed[-1]
    jtj = _jtj(varying, fixed)
    eye = jnp.broadcast_to(jnp.eye(6, dtype=theta.dtype), jtj.shape)
    inv, pivot = solve_scaled(jtj, eye, 0.0, with_pivot=True)
    full_rank = pivot > RANK_PIVOT
    inv = jnp.where(full_rank[:, None, None], 0.5 * (inv + jnp.swapaxes(inv, -1, -2)), jnp.inf)
    lin = jnp.stack([theta[:, 0], theta[:, 1], theta[:, 3], theta[:, 4], theta[:, 5]], -1)
    r_m = jnp.sum(lin * jnp.stack([jtr[:, 0], jtr[:, 1], jtr[:, 3], jtr[:, 4], jtr[:, 5]], -1), -1)
    r_y = r_m - sse
    y_mean, r_mean = sum_y / n, jtr[:, 5] / n
    var_y = yy - n * y_mean**2
    cov_yr = r_y - n * y_mean * r_mean
    var_r = sse - n * r_mean**2
    corr = (var_y + cov_yr) / jnp.sqrt(var_y * (var_y + 2 * cov_yr + var_r))
    return (sse, inv, corr, n, full_rank, *(lag1[0] if lag1 else ()))


def sarosi_derivatives(x, y, w):
    """For Sárosi eq. 2.1, by the written-out sums of this module: a function of θ
    (M, 6) giving S = rᵀWr, g = JᵀWr, the Hessian H of S/2 and JᵀWJ, one pass over the
    samples (the sums that do not depend on θ are made once, here); and one giving S only."""
    p, k = x
    sw = jnp.sqrt(w)
    *fixed, _, _ = _fixed_jtj(p, k, y, w)

    def derivatives(theta):
        varying, jtr, sse, _, second = _pass(
            theta, jnp.zeros_like(theta), p, k, y, w, sw, 0.0, 0.0, 1.0
        )
        jtj = _jtj(varying, fixed)
        return sse, jtr, _hessian(jtj, second), jtj

    def sse_only(theta):
        zero = jnp.zeros_like(theta)
        return _pass(theta, zero, p, k, y, w, sw, 0.0, 0.0, 0.0, full=False)[2]

    return derivatives, sse_only
