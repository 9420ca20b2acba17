"""Solvers are values (``pamid._solvers``): a name and its object give the same fit, a
solver written by a user (one class) fits through the one entry, and names that are not
solvers are refused with the list of those that are."""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pytest

import pamid
from pamid._solvers import (
    SOLVER_CLASSES,
    GaussNewton,
    LevenbergMarquardt,
    Solver,
    as_solver,
    optimistix_lanes,
)


class Dogleg(Solver):
    """optimistix's Dogleg trust region: a solver pamid does not ship, in one class."""

    name: ClassVar[str] = "dogleg"
    restarts: ClassVar[bool] = True

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        import optimistix as optx

        return optimistix_lanes(optx.Dogleg(rtol=rtol, atol=atol), spec, theta0, x, y, w, max_steps)


def test_names_and_objects_are_one_solver():
    from pamid._commands.fit import SOLVER_NAMES

    for name, cls in SOLVER_CLASSES.items():
        assert as_solver(name) == cls() and as_solver(cls()) == cls() and cls.name == name
    assert SOLVER_NAMES == tuple(SOLVER_CLASSES)  # every solver is a choice of --solver
    assert hash(GaussNewton()) == hash(as_solver("gauss-newton"))  # a static jit argument
    with pytest.raises(ValueError, match="unknown solver 'newton'.*gauss-newton"):
        as_solver("newton")


def test_an_object_fits_as_its_name_does(small_bench):
    data = small_bench.data
    by_name = pamid.fit_least_squares(data, solver="levenberg-marquardt")
    by_value = pamid.fit_least_squares(data, solver=LevenbergMarquardt())
    np.testing.assert_array_equal(by_value.theta, by_name.theta)
    assert by_value.solver == by_name.solver == "levenberg-marquardt"


def test_a_users_solver_reaches_the_same_optimum(small_bench):
    data = small_bench.data
    ref = pamid.fit_least_squares(data)  # Sárosi's written-out Gauss–Newton
    fit = pamid.fit_least_squares(data, solver=Dogleg())
    assert fit.solver == "dogleg" and np.all(fit.converged)
    np.testing.assert_allclose(fit.theta, ref.theta, rtol=1e-6)
    np.testing.assert_allclose(fit.sse, ref.sse, rtol=1e-9)


def test_every_fitting_loop_is_a_solvers():
    """The iterative loops that fit constants live in ``pamid/_solvers/``, one per solver
    class's file (issue 33): none in the fits, intervals, diagnosis, decays or pooled fits,
    which pass solver values instead. (Simulators' ``lax.scan`` over time are not fits.)"""
    import re
    from pathlib import Path

    root = Path(pamid.__file__).parent
    loop = re.compile(r"lax\.(while_loop|fori_loop)\(")
    for package in ("_fit", "_diagnose", "_decays", "_pooled", "_inference", "_sampling"):
        found = [f"{p.relative_to(root)}:{i}" for p in sorted((root / package).rglob("*.py"))
                 for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
                 if loop.search(line)]
        assert found == [], found
    owners = {p.name for p in (root / "_solvers").glob("*.py")
              if loop.search(p.read_text(encoding="utf-8"))}
    assert owners == {"_levenberg_marquardt.py", "_sarosi.py", "_variable_projection.py",
                      "_profile.py"}


def test_every_own_loop_fit_goes_through_the_one_entry():
    """Outside ``pamid/_solvers/`` nothing calls the masked loop with a residual function
    of its own (``levenberg_marquardt(``, ``linearised(``) nor one lane of it
    (``fit_lane(``): the bounded fits, the diagnosis refits (a lane view), the decays'
    trajectory, friction and joint fits pass a model value to the one entry,
    ``least_squares(model, data, solver=ProjectedLevenbergMarquardt(…))``."""
    import re
    from pathlib import Path

    root = Path(pamid.__file__).parent
    direct = re.compile(r"\b(levenberg_marquardt|linearised|fit_lane)\(")
    found = [f"{p.relative_to(root)}:{i}" for p in sorted(root.rglob("*.py"))
             if p.parent.name != "_solvers"
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if direct.search(line)]
    assert found == [], found
    users = {p.relative_to(root).as_posix() for p in root.rglob("*.py")
             if re.search(r"\bleast_squares\(", p.read_text(encoding="utf-8"))}
    assert {"_diagnose/_static.py", "_decays/_analysis.py", "_decays/_coulomb.py",
            "_decays/_joint_fit.py", "_fit/_intervals.py"} <= users


def test_the_one_entry_returns_a_solution_with_a_result_per_lane(small_bench):
    """``least_squares(model, data, solver=…)`` is the one batched entry: a ``Solution`` of
    NumPy arrays with a leading lane axis (the type a lane of pamid's own loop ends with),
    a result code per lane, and ``solve`` the same as a tuple."""
    from pamid._lanes._batch import pack_rows
    from pamid.engine import RESULT_NAMES, Solution, get_model, least_squares, solve

    spec, data = get_model("sarosi"), small_bench.data
    sol = least_squares(spec, data, with_statistics=True)
    assert isinstance(sol, Solution) and sol.params.shape == (3, 6)
    assert list(sol.status) == ["converged"] * 3 and sol.converged.all()
    np.testing.assert_allclose(sol.sse, sol.statistics[0])
    theta, ok, steps = solve(spec, data)
    np.testing.assert_array_equal(theta, sol.params)
    np.testing.assert_array_equal(steps, sol.steps)

    # A budget of one step from a start far off: every lane says it ran out of steps.
    far = np.asarray(sol.params) * 1.5
    short = least_squares(spec, data, solver="levenberg-marquardt", theta0=far, max_steps=1)
    assert list(short.status) == ["max_steps"] * 3 and set(short.status) <= set(RESULT_NAMES)

    # Weights multiply the data's own: ones change nothing (padding keeps weight 0) ...
    lm = least_squares(spec, data, solver="levenberg-marquardt")
    ones = least_squares(spec, data, solver="levenberg-marquardt",
                         weights=np.ones(np.shape(data.w)))
    np.testing.assert_array_equal(ones.params, lm.params)
    # ... and 0 on a fold's rows fits the rest: the fit of the data without those rows.
    w, curve = np.asarray(data.w), np.asarray(data.curve)
    held = curve == 1
    fold = least_squares(spec, data, solver="levenberg-marquardt",
                         weights=np.where(held, 0.0, 1.0))
    keep = (w > 0) & ~held
    codes = np.nonzero(keep)[0]
    rest = pack_rows(codes, tuple(np.asarray(a)[keep] for a in data.x),
                     np.asarray(data.y)[keep], n_muscles=3)
    alone = least_squares(spec, rest, solver="levenberg-marquardt")
    assert fold.converged.all() and alone.converged.all()
    np.testing.assert_allclose(fold.params, alone.params, rtol=1e-7)
    assert not np.allclose(fold.params, lm.params, rtol=1e-7)  # the fold did leave rows out

    with pytest.raises(ValueError, match="weights of shape"):
        least_squares(spec, data, weights=np.ones(3))
    with pytest.raises(ValueError, match="finite and ≥ 0"):
        least_squares(spec, data, weights=-np.ones(np.shape(data.w)))


def test_a_lane_of_the_own_loop_ends_with_the_same_solution_type():
    import jax.numpy as jnp

    from pamid._solvers import CONVERGED, Solution, fit_lane
    from pamid.engine import get_model

    spec = get_model("sarosi")
    p, k = np.meshgrid(np.linspace(1, 6, 8), np.linspace(0, 25, 12))
    x = spec.to_x(p.ravel() * 100.0, k.ravel())
    truth = jnp.asarray([21.0, 276.0, -0.31, -6.0, 120.0, -194.0])
    y = spec.predict(truth, x)
    sol = fit_lane(spec, truth * 1.01, x, y, jnp.ones_like(y), max_steps=100, rtol=1e-12,
                   floor_per_sample=1e-20)  # exact data: an absolute floor on the decrement
    assert isinstance(sol, Solution) and int(sol.result) == CONVERGED and sol.statistics is None
    np.testing.assert_allclose(sol.params, truth, rtol=1e-8)
