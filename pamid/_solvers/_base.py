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
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp


def residuals(spec, theta, x, y, w):
    """Weighted residuals w^½·(model − data) of one muscle."""
    return jnp.sqrt(w) * (spec.predict(theta, x) - y)


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
