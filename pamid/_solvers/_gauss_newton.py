"""Gauss–Newton as a solver value: the model's registered written-out kernel where it has one
(Sárosi eq. 2.1, :mod:`pamid._solvers._sarosi`), else optimistix's ``GaussNewton``."""

from __future__ import annotations

from typing import ClassVar

from ._base import Solver, optimistix_lanes


class GaussNewton(Solver):
    """Gauss–Newton: the model's written-out kernel where it registers one (Sárosi eq. 2.1),
    else optimistix's ``GaussNewton(rtol, atol)``."""

    name: ClassVar[str] = "gauss-newton"
    restarts: ClassVar[bool] = True

    def kernel(self, spec):
        return None if spec.kernels is None else spec.kernels.gauss_newton

    def run(self, spec, theta0, x, y, w, max_steps, rtol, atol):
        import optimistix as optx

        return optimistix_lanes(optx.GaussNewton(rtol=rtol, atol=atol), spec, theta0, x, y, w,
                                max_steps)
