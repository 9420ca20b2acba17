"""Levenberg–Marquardt: pamid's one masked loop with projected bounds, for one lane (batched
by ``jax.vmap``), as the solver value :class:`ProjectedLevenbergMarquardt`, and
:class:`LevenbergMarquardt` (``--solver levenberg-marquardt``), optimistix's, for unbounded
fits.

The one least-squares entry (:func:`pamid._fit._least_squares.least_squares`) runs
:class:`ProjectedLevenbergMarquardt` for every fit with bounds or held constants: the static
fits within bounds, the diagnosis refits (a model with candidate effects,
:func:`~pamid._effects._model.with_effects`, some constants held by a mask so that every
effect set of a batch has the same shape), the free-decay trajectory fits (linear,
:mod:`pamid._decays._analysis`; with friction, :mod:`pamid._decays._coulomb`) and the joint's
decay fits (:mod:`pamid._decays._joint_fit`), the last three in constants divided by a scale
(:class:`~pamid._fit._spec.Scaled`). Each is a model value (a
:class:`~pamid._fit._spec.ModelSpec`, whose ``predict`` and ``value_and_jacobian`` make the
weighted residual) fitted to a lane's data by :func:`fit_lane`.

The method: Levenberg–Marquardt with Marquardt's scaling (the damping proportional to the
diagonal of JᵀJ) and Nielsen's damping update (H. B. Nielsen, "Damping parameter in
Marquardt's method", IMM-REP-1999-05, eq. 2.4): after a step with gain ratio ρ > 0 the
damping is multiplied by max(1/3, 1 − (2ρ − 1)³), after a rejected one by ν, which doubles
each time. It stops when the Gauss–Newton step would lower the weighted sum of squares by
at most ``rtol`` of itself plus ``floor`` (the Newton decrement gᵀ(JᵀJ)⁻¹g; ``floor`` is
for data the model fits exactly).

Masked constants (mask 0) keep their start values: their rows and columns of JᵀJ are
replaced by the identity and their gradient by 0.

Box bounds (optional), as in a projected Newton method (D. P. Bertsekas, "Projected Newton
methods for optimization problems with simple constraints", SIAM J. Control Optim. 20,
1982): a constant on its bound whose gradient points out of the box is held there, as a
masked one, and so is one whose step would leave the box (the others' step is then solved
again without it); the trial point is projected onto the box. The stopping test asks the
decrement of the constants not held by their gradient: a lane ends on a point that
satisfies the Karush–Kuhn–Tucker conditions, and ``Solution.free`` says which constants
were held on a bound there.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import jax
import jax.numpy as jnp

from ._base import CONVERGED, MAX_STEPS, NONFINITE, STALLED, Solution, Solver, optimistix_lanes

#: Damping beyond which no step can lower the sum of squares: the loop has stalled.
MAX_DAMPING = 1e16
#: Relative ridge of the stopping test's Newton decrement (on JᵀJ scaled to unit diagonal):
#: directions the data cannot pin (a candidate effect collinear with the model) have
#: eigenvalues near zero, and a plain solve turns rounding in g into an enormous or NaN
#: decrement, so such a lane never passes the test although no step can lower its SSE.
#: With the ridge, rounding there adds about ε²/RIDGE ≈ 1e-20 of the SSE.
DECREMENT_RIDGE = 1e-12


def restrict(g, h, mask):
    """g and h with the constants where ``mask`` is 0 taken out: g = 0 and h's rows and
    columns the identity's there."""
    both = mask[:, None] * mask[None, :]
    return mask * g, jnp.where(both > 0, h, jnp.eye(mask.shape[0], dtype=h.dtype))


def newton_decrement(g, h):
    """gᵀ(JᵀJ)⁻¹g, the decrease of the SSE that a Gauss–Newton step would give, with
    directions of relative curvature below :data:`DECREMENT_RIDGE` left out (a ridge on
    the diagonal of JᵀJ, relative to that diagonal)."""
    d = jnp.diag(h)
    d = jnp.maximum(d, 1e-300 + 1e-16 * jnp.max(d))
    return g @ jnp.linalg.solve(h + DECREMENT_RIDGE * jnp.diag(d), g)


def levenberg_marquardt(linearise: Callable, p0, mask, *, max_steps: int, rtol: float,
                        floor=0.0, damping0: float = 1e-3, bounds=None) -> Solution:
    """Minimise ‖r(p)‖² for one lane from ``p0``, holding the constants where ``mask`` is 0.

    Args:
        linearise: ``p -> (r, J)``, the (weighted) residual vector and its Jacobian in p;
            rows of weight 0 must be zero in both (padding, held-out samples).
        p0: start values (inside ``bounds``); mask: 1.0 for a free constant, 0.0 for a
            held one.
        max_steps: the step budget; rtol, floor: the stopping test (module docstring).
        bounds: ``(lower, upper)``, arrays of ``p0``'s shape (±inf where unbounded), or
            None (module docstring).
    """
    mask = jnp.asarray(mask, dtype=p0.dtype)

    def lin(p):
        r, jac = linearise(p)
        jac = jac * mask[None, :]
        g, h = jac.T @ r, jac.T @ jac  # g = ½·∂SSE/∂p
        free = mask
        if bounds is not None:  # a constant on its lower bound with g > 0 wants out
            out = ((p <= bounds[0]) & (g > 0)) | ((p >= bounds[1]) & (g < 0))
            free = jnp.where(out, 0.0, mask)
        g, h = restrict(g, h, free)
        return r, jac, g, h, r @ r, free

    def small(g, h, sse):
        return newton_decrement(g, h) <= rtol * sse + floor

    # The loop carries only what is the size of the constants: the residual and the
    # Jacobian (samples × constants) are computed again once at the end. Carrying them
    # cost a select over both in every step, a large share of a step with many samples.
    _, _, g, h, sse, free = lin(p0)
    state = (p0, g, h, sse, free, jnp.asarray(damping0, p0.dtype),
             jnp.asarray(2.0, p0.dtype), 0, small(g, h, sse) | ~jnp.isfinite(sse))

    def cond(s):
        return (~s[-1]) & (s[7] < max_steps)

    def damped_step(g, h, lam):
        d = jnp.diag(h)
        return -jnp.linalg.solve(h + lam * jnp.diag(jnp.maximum(d, 1e-12 * jnp.max(d))), g)

    def body(s):
        p, g, h, sse, free, lam, nu, k, _ = s
        step = damped_step(g, h, lam)
        if bounds is not None:
            # A constant on its bound whose step would leave the box is held for this step
            # too, and the others' step solved again without it: clipping it instead would
            # bend the step of every constant it is correlated with.
            out = ((p <= bounds[0]) & (step < 0)) | ((p >= bounds[1]) & (step > 0))
            step = damped_step(*restrict(g, h, jnp.where(out, 0.0, free)), lam)
            step = jnp.clip(p + step, *bounds) - p
        p_new = p + step
        predicted = -(g @ step + 0.5 * step @ h @ step)
        _, _, g_n, h_n, sse_n, free_n = lin(p_new)
        rho = 0.5 * (sse - sse_n) / jnp.maximum(predicted, 1e-300)
        ok = jnp.isfinite(sse_n) & (rho > 1e-4)
        lam = jnp.where(ok, lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3),
                        lam * nu)
        nu = jnp.where(ok, 2.0, 2.0 * nu)
        p, g, h, sse, free = (
            jnp.where(ok, a, b)
            for a, b in ((p_new, p), (g_n, g), (h_n, h), (sse_n, sse), (free_n, free))
        )
        done = small(g, h, sse) | (lam > MAX_DAMPING)
        return p, g, h, sse, free, lam, nu, k + 1, done

    p, g, h, sse, free, lam, _, k, _ = jax.lax.while_loop(cond, body, state)
    r, jac, *_ = lin(p)
    jac = jac * free[None, :]
    finite = jnp.isfinite(sse) & jnp.all(jnp.isfinite(p))
    result = jnp.where(
        ~finite, NONFINITE,
        jnp.where(small(g, h, sse), CONVERGED, jnp.where(lam > MAX_DAMPING, STALLED, MAX_STEPS)))
    return Solution(p, r, jac, sse, result, k, free, decrement=newton_decrement(g, h))



def fit_lane(model, theta0, x, y, w, mask=None, *, max_steps: int, rtol: float,
             floor_per_sample: float = 0.0, bounds=None, damping0: float = 1e-3) -> Solution:
    """The least-squares fit of one lane (batched by ``jax.vmap``): ``model`` (a model value,
    :class:`pamid._fit._spec.ModelSpec`: ``predict`` and ``jacobian``) fitted to the data
    ``(x, y, w)`` from ``theta0``, the constants where ``mask`` is 0 held (default: none),
    within ``bounds`` where given, by :func:`levenberg_marquardt` on the weighted residual
    w^½·(model − y). It stops where a Gauss–Newton step would lower the SSE by at most
    ``rtol`` of itself plus ``floor_per_sample`` (an absolute tolerance squared) per sample
    of weight > 0. One lane of :class:`ProjectedLevenbergMarquardt`, which the one entry
    batches. Rows of weight 0 never count, even where the model is not finite there
    (padding)."""
    sw = jnp.sqrt(w)
    on = w > 0

    def linearise(p):
        value, jac = model.value_and_jacobian(p, x)
        return (jnp.where(on, sw * (value - y), 0.0),
                jnp.where(on[:, None], jac * sw[:, None], 0.0))

    mask = jnp.ones_like(theta0) if mask is None else mask
    return levenberg_marquardt(linearise, theta0, mask, max_steps=max_steps, rtol=rtol,
                               floor=jnp.sum(on) * floor_per_sample, bounds=bounds,
                               damping0=damping0)


class ProjectedLevenbergMarquardt(Solver):
    """pamid's own loop, :func:`levenberg_marquardt`, as a solver value: the one that holds
    constants (a mask) and keeps them within box bounds, which the one entry
    (:func:`pamid._fit._least_squares.least_squares`) runs for every fit with bounds or
    held constants, and for any fit it is given to (``--solver
    projected-levenberg-marquardt``).

    Its tolerances are its fields, as optimistix's solvers' are (the entry's ``rtol`` and
    ``atol`` are not used); the defaults are those of every fit within bounds.

    Attributes:
        rtol: the stopping test: a Gauss–Newton step would lower the SSE by at most ``rtol``
            of itself plus ...
        floor_per_sample: ... this per sample of weight > 0 (an absolute tolerance
            squared: for data the model fits exactly).
        damping0: the first step's damping, relative to the diagonal of JᵀJ.
    """

    name: ClassVar[str] = "projected-levenberg-marquardt"
    restarts: ClassVar[bool] = True
    rtol: float = 1e-12
    floor_per_sample: float = 1e-20
    damping0: float = 1e-3

    def lane(self, spec, theta0, x, y, w, mask=None, bounds=None, *,
             max_steps: int) -> Solution:
        """One lane (:func:`fit_lane`), batched by the entry with ``jax.vmap``."""
        return fit_lane(spec, theta0, x, y, w, mask, max_steps=max_steps, rtol=self.rtol,
                        floor_per_sample=self.floor_per_sample, bounds=bounds,
                        damping0=self.damping0)

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        sol = jax.vmap(lambda t0, x, y, w: self.lane(spec, t0, x, y, w,
                                                     max_steps=max_steps))(theta0, x, y, w)
        return sol.params, sol.result == CONVERGED, sol.steps


class LevenbergMarquardt(Solver):
    """optimistix's ``LevenbergMarquardt(rtol, atol)`` (a fit within bounds runs
    :class:`ProjectedLevenbergMarquardt` above, whatever the solver)."""

    name: ClassVar[str] = "levenberg-marquardt"
    restarts: ClassVar[bool] = True

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        import optimistix as optx

        return optimistix_lanes(optx.LevenbergMarquardt(rtol=rtol, atol=atol), spec, theta0,
                                x, y, w, max_steps)
