"""Solvers as values: what solves a batch of least-squares lanes is an object passed to the
one entry (:func:`pamid._fit._least_squares.solve`, and through it ``fit_least_squares``,
``compare_models`` …), not a name tested in if/elif chains there.

A solver is a small :class:`equinox.Module` (hashable: a static argument of the compiled
solve) with

- ``run(spec, theta0, x, y, w, max_steps, rtol, atol)``: every lane from its start, traced
  inside the compiled batch; returns (theta, converged, steps) per lane;
- ``kernel(spec)``: the model's registered written-out solver of this kind, or None (Sárosi
  registers a Gauss–Newton that brings its own start and statistics:
  :mod:`pamid._fit._gauss_newton`); the entry uses it where the model has one;
- ``check(spec)``: raise ``ValueError`` where the solver cannot fit the model;
- ``restarts``: whether the solver starts from the model's start candidates, several as
  extra lanes, and tries other candidates for lanes one start did not serve (the iterative
  solvers; variable projection scans its own start, jaxopt's path is kept as it was
  measured).

``optimistix`` (the project's named solver library) provides Gauss–Newton and
Levenberg–Marquardt; ``jaxopt``'s Levenberg–Marquardt is kept for comparison only (it is
unmaintained upstream and warns on import). Bounds are not a solver's business here: a fit
within bounds is pamid's one masked loop with projected steps
(:func:`pamid._fit._engine.levenberg_marquardt`). To add a solver: one class here with a
unique ``name`` and one entry in :data:`SOLVER_CLASSES`.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from ._spec import ModelSpec


def residuals(spec: ModelSpec, theta, x, y, w):
    """Weighted residuals w^½·(model − data) of one muscle."""
    return jnp.sqrt(w) * (spec.predict(theta, x) - y)


class Solver(eqx.Module):
    """A least-squares solver for batches of lanes (module docstring)."""

    name: ClassVar[str] = ""
    restarts: ClassVar[bool] = False

    def kernel(self, spec: ModelSpec):
        """The model's written-out solver of this kind (same signature as
        :func:`pamid._fit._gauss_newton.sarosi_gauss_newton`), or None."""
        return None

    def check(self, spec: ModelSpec) -> None:
        """Raise ``ValueError`` where this solver cannot fit ``spec``."""

    def run(self, spec: ModelSpec, theta0, x, y, w, max_steps: int, rtol: float, atol: float):
        raise NotImplementedError


def _optimistix(solver, spec, theta0, x, y, w, max_steps):
    import optimistix as optx  # imported here: the default Sárosi path does not need it

    def one(theta0, x, y, w):
        sol = optx.least_squares(
            lambda th, args: residuals(spec, th, *args), solver, theta0, args=(x, y, w),
            max_steps=max_steps, throw=False)
        return sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]

    return jax.vmap(one)(theta0, x, y, w)


class GaussNewton(Solver):
    """Gauss–Newton: the model's written-out kernel where it registers one (Sárosi eq. 2.1),
    else optimistix's ``GaussNewton(rtol, atol)``."""

    name: ClassVar[str] = "gauss-newton"
    restarts: ClassVar[bool] = True

    def kernel(self, spec):
        return None if spec.fast_path is None else spec.fast_path.gauss_newton

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        import optimistix as optx

        return _optimistix(optx.GaussNewton(rtol=rtol, atol=atol), spec, theta0, x, y, w,
                           max_steps)


class LevenbergMarquardt(Solver):
    """optimistix's ``LevenbergMarquardt(rtol, atol)``."""

    name: ClassVar[str] = "levenberg-marquardt"
    restarts: ClassVar[bool] = True

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        import optimistix as optx

        return _optimistix(optx.LevenbergMarquardt(rtol=rtol, atol=atol), spec, theta0, x, y,
                           w, max_steps)


class VariableProjection(Solver):
    """Variable projection (Golub & Pereyra 1973) for a model with one nonlinear constant:
    its registered profile search (Sárosi eq. 2.1 over a3,
    :mod:`pamid._fit._variable_projection`); ``max_steps`` refinement steps of the bracket,
    converged where it has shrunk to ``rtol`` (at least 1e-8)."""

    name: ClassVar[str] = "variable-projection"

    def check(self, spec):
        fast = spec.fast_path
        if fast is None or fast.variable_projection is None:
            raise ValueError(f"variable projection is written out for the Sárosi model only, "
                             f"not for {spec.name}; use the gauss-newton or "
                             "levenberg-marquardt solver")

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        theta, _, width = spec.fast_path.variable_projection(x, y, w, n_refine=max_steps)
        ok = jnp.all(jnp.isfinite(theta), axis=-1) & (width < jnp.maximum(rtol, 1e-8))
        return theta, ok, jnp.full(theta.shape[0], max_steps)


class JaxoptLevenbergMarquardt(Solver):
    """jaxopt's ``LevenbergMarquardt`` (Madsen–Nielsen stopping test, xtol = rtol,
    gtol = atol), for comparison."""

    name: ClassVar[str] = "jaxopt-levenberg-marquardt"

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        import jaxopt  # imported here: unmaintained upstream, and it warns on import

        def one(theta0, x, y, w):
            lm = jaxopt.LevenbergMarquardt(
                lambda th: residuals(spec, th, x, y, w), stop_criterion="madsen-nielsen",
                maxiter=max_steps, xtol=rtol, gtol=atol)
            out = lm.run(theta0)
            return out.params, out.state.iter_num < max_steps, out.state.iter_num

        return jax.vmap(one)(theta0, x, y, w)


#: The solvers by name (``--solver``, ``solver="…"``): one line per solver class.
SOLVER_CLASSES: dict[str, type[Solver]] = {
    cls.name: cls for cls in (GaussNewton, LevenbergMarquardt, VariableProjection,
                              JaxoptLevenbergMarquardt)
}


def as_solver(solver) -> Solver:
    """A :class:`Solver` from itself or its name."""
    if isinstance(solver, Solver):
        return solver
    if isinstance(solver, str) and solver in SOLVER_CLASSES:
        return SOLVER_CLASSES[solver]()
    raise ValueError(f"unknown solver {solver!r}; choose one of {tuple(SOLVER_CLASSES)} "
                     "or pass a pamid solver object")
