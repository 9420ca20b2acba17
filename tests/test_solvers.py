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
    for name, cls in SOLVER_CLASSES.items():
        assert as_solver(name) == cls() and as_solver(cls()) == cls() and cls.name == name
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


def test_every_own_loop_fit_is_a_model_value_through_fit_lane():
    """Outside ``pamid/_solvers/`` nothing calls the masked loop with a residual function
    of its own (``levenberg_marquardt(``, ``linearised(``): the bounded fits, the
    diagnosis refits and the decays' trajectory, friction and joint fits pass a model value
    (a ModelSpec) to ``fit_lane``."""
    import re
    from pathlib import Path

    root = Path(pamid.__file__).parent
    direct = re.compile(r"\b(levenberg_marquardt|linearised)\(")
    found = [f"{p.relative_to(root)}:{i}" for p in sorted(root.rglob("*.py"))
             if p.parent.name != "_solvers"
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if direct.search(line)]
    assert found == [], found
    users = {p.relative_to(root).as_posix() for p in root.rglob("*.py")
             if "fit_lane(" in p.read_text(encoding="utf-8") and p.parent.name != "_solvers"}
    assert users == {"_fit/_least_squares.py", "_diagnose/_static.py",
                     "_decays/_analysis.py", "_decays/_coulomb.py", "_decays/_joint_fit.py"}
