"""Solvers as values (issue 33): every iterative loop that fits constants is one solver class
in one file of this package, passed to the one least-squares entry
(:func:`pamid._fit._least_squares.least_squares`, which returns a :class:`Solution`) or,
for interval ends, to :func:`pamid._fit._intervals.profile`.

- ``_base.py``: :class:`Solver`, the interface, the weighted residual and what a solve
  ends with, :class:`Solution` and its result codes;
- ``_gauss_newton.py``: :class:`GaussNewton` (optimistix's loop, or the model's written-out
  kernel);
- ``_sarosi.py``: Sárosi eq. 2.1's written-out Gauss–Newton kernel, its start and statistics
  (its own loop: benchmarks/README.md, ``fit_batch.py``);
- ``_levenberg_marquardt.py``: :class:`LevenbergMarquardt` (optimistix's loop), and pamid's
  masked loop with projected bounds, :func:`levenberg_marquardt`, as the solver value
  :class:`ProjectedLevenbergMarquardt` (fits within bounds, diagnosis refits, decay
  trajectory, Coulomb and joint fits, through the one entry);
- ``_variable_projection.py``: :class:`VariableProjection` (its bracket refinement);
- ``_jaxopt.py``: :class:`JaxoptLevenbergMarquardt`, for comparison (jaxopt's loop);
- ``_profile.py``: :class:`ProfileNewton`, the ends of profile intervals (a root finder,
  its own loop).

To add a solver: one class in one file here with a unique ``name``, and one entry in
:data:`SOLVER_CLASSES` below.
"""

import functools

from ._base import (
    CONVERGED,
    MAX_STEPS,
    NONFINITE,
    RESULT_NAMES,
    STALLED,
    Solution,
    Solver,
    optimistix_lanes,
    residuals,
    residuals_and_jacobian,
)
from ._gauss_newton import GaussNewton
from ._jaxopt import JaxoptLevenbergMarquardt
from ._levenberg_marquardt import (
    LevenbergMarquardt,
    ProjectedLevenbergMarquardt,
    fit_lane,
    levenberg_marquardt,
    newton_decrement,
    restrict,
)
from ._profile import ProfileNewton, generic_derivatives
from ._sarosi import (
    sarosi_derivatives,
    sarosi_fast_start,
    sarosi_gauss_newton,
    sarosi_statistics,
    solve_scaled,
)
from ._variable_projection import (
    VariableProjection,
    sarosi_fit_at_a3,
    sarosi_variable_projection,
    sarosi_variable_projection_start,
    small_cholesky_solve,
)

#: The solvers by name (``--solver``, ``solver="…"``): one line per solver class.
SOLVER_CLASSES: dict[str, type[Solver]] = {
    cls.name: cls for cls in (GaussNewton, LevenbergMarquardt, VariableProjection,
                              JaxoptLevenbergMarquardt, ProjectedLevenbergMarquardt)
}


def as_solver(solver) -> Solver:
    """A :class:`Solver` from itself or its name (one instance per name: a solver is an
    immutable value, and making one costs tens of µs of a warm one-muscle fit)."""
    if isinstance(solver, Solver):
        return solver
    if isinstance(solver, str) and solver in SOLVER_CLASSES:
        return _named(solver)
    raise ValueError(f"unknown solver {solver!r}; choose one of {tuple(SOLVER_CLASSES)} "
                     "or pass a pamid solver object")


@functools.cache
def _named(name: str) -> Solver:
    return SOLVER_CLASSES[name]()


__all__ = [
    "CONVERGED", "MAX_STEPS", "NONFINITE", "RESULT_NAMES", "SOLVER_CLASSES", "STALLED",
    "GaussNewton", "JaxoptLevenbergMarquardt", "LevenbergMarquardt", "ProfileNewton",
    "ProjectedLevenbergMarquardt",
    "Solution", "Solver", "VariableProjection", "as_solver", "fit_lane",
    "generic_derivatives", "levenberg_marquardt", "newton_decrement",
    "optimistix_lanes", "residuals", "residuals_and_jacobian", "restrict",
    "sarosi_derivatives", "sarosi_fast_start", "sarosi_fit_at_a3",
    "sarosi_gauss_newton", "sarosi_statistics", "sarosi_variable_projection",
    "sarosi_variable_projection_start", "small_cholesky_solve", "solve_scaled",
]
