"""The solver interface: what solves a batch of least-squares lanes is a value passed to the
one entry (:func:`pamid._fit._least_squares.solve`, and through it ``fit_least_squares``,
``compare_models`` …), not a name tested in if/elif chains there.

A solver is a small :class:`equinox.Module` (hashable: a static argument of the compiled
solve) with

- ``run(spec, theta0, x, y, w, max_steps, rtol, atol)``: every lane from its start, traced
  inside the compiled batch; returns (theta, converged, steps) per lane;
- ``kernel(spec)``: the model's registered written-out solver of this kind, or None (Sárosi
  registers a Gauss–Newton that brings its own start and statistics:
  :mod:`pamid._solvers._sarosi`); the entry uses it where the model has one;
- ``check(spec)``: raise ``ValueError`` where the solver cannot fit the model;
- ``restarts``: whether the solver starts from the model's start candidates, several as
  extra lanes, and tries other candidates for lanes one start did not serve (the iterative
  solvers; variable projection scans its own start, jaxopt's path is kept as it was
  measured).

``spec`` is the fitting code's view of a model (:class:`pamid._fit._spec.ModelSpec`): a
solver calls only its ``predict(theta, x)`` and ``kernels``.

What a fit ends with is a :class:`Solution`, one type for one lane (pamid's own loop,
:func:`pamid._solvers.fit_lane`) and for a batch (the one entry,
:func:`pamid._fit._least_squares.least_squares`: the same fields with a leading lane axis).
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

#: Result codes, the same names as ``FitResult.status``.
CONVERGED, MAX_STEPS, NONFINITE, STALLED = 0, 1, 2, 3
RESULT_NAMES = ("converged", "max_steps", "nonfinite", "stalled")


class Solution(NamedTuple):
    """The end of a solve: of one lane, or of a batch with a leading lane axis on every
    field.

    Attributes:
        params: the constants (masked ones at their start values).
        residual: the weighted residual w^½·(model − data) at ``params`` (None where the
            batched entry was not asked for it).
        jac: its Jacobian there, masked and held columns zero (None likewise).
        sse: the sum of squares of ``residual``; None where the solver does not give it.
        result: a result code (:data:`RESULT_NAMES`).
        steps: the number of steps taken.
        free: the mask at the end: 0 for the masked constants and for those held on a
            bound (box bounds only; otherwise the mask itself); None where every constant
            was free.
        statistics: the statistics at ``params`` where the batched entry computed them
            (``pamid._fit._least_squares.statistics``' tuple), else None.
        prediction: the model at ``params`` on every sample, also those of weight 0 (a
            fold's held-out rows), where the batched entry was asked for it; else None.
        decrement: the Newton decrement gᵀ(JᵀJ)⁻¹g at ``params`` (the decrease of the SSE
            a Gauss–Newton step would still give) where the solver gives it; else None.
    """

    params: jax.Array
    residual: jax.Array | None
    jac: jax.Array | None
    sse: jax.Array | None
    result: jax.Array
    steps: jax.Array
    free: jax.Array | None
    statistics: tuple | None = None
    prediction: jax.Array | None = None
    decrement: jax.Array | None = None

    @property
    def converged(self):
        """Whether each lane converged (result ``converged``)."""
        return self.result == CONVERGED

    @property
    def status(self) -> np.ndarray:
        """Each lane's result as its name (:data:`RESULT_NAMES`), on the host."""
        return np.asarray(RESULT_NAMES, dtype=object)[np.asarray(self.result)]


def residuals(spec, theta, x, y, w):
    """Weighted residuals w^½·(model − data) of one muscle."""
    return jnp.sqrt(w) * (spec.predict(theta, x) - y)


def residuals_and_jacobian(spec, theta, x, y, w):
    """The weighted residuals of :func:`residuals` and their Jacobian in ``theta`` (n × p),
    from the model's own ``value_and_jacobian`` (one forward-mode pass, or the structured
    derivatives a model knows): the statistics, the sandwich intervals and the profile's
    derivatives take theirs from here."""
    sw = jnp.sqrt(w)
    value, jac = spec.value_and_jacobian(theta, x)
    return sw * (value - y), jac * sw[:, None]


class Solver(eqx.Module):
    """A least-squares solver for batches of lanes (module docstring)."""

    name: ClassVar[str] = ""
    restarts: ClassVar[bool] = False

    def kernel(self, spec):
        """The model's written-out solver of this kind (same signature as
        :func:`pamid._solvers._sarosi.sarosi_gauss_newton`), or None."""
        return None

    def check(self, spec) -> None:
        """Raise ``ValueError`` where this solver cannot fit ``spec``."""

    def run(self, spec, theta0, x, y, w, max_steps: int, rtol: float, atol: float):
        raise NotImplementedError


def optimistix_lanes(solver, spec, theta0, x, y, w, max_steps):
    """Every lane solved by an optimistix least-squares solver (vmapped): (theta, converged,
    steps)."""
    import optimistix as optx  # imported here: the default Sárosi path does not need it

    def one(theta0, x, y, w):
        sol = optx.least_squares(
            lambda th, args: residuals(spec, th, *args), solver, theta0, args=(x, y, w),
            max_steps=max_steps, throw=False)
        return sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]

    return jax.vmap(one)(theta0, x, y, w)
