"""jaxopt's Levenberg–Marquardt as a solver value, kept for comparison: jaxopt is unmaintained
upstream and warns on import (benchmarks/README.md compares it)."""

from __future__ import annotations

from typing import ClassVar

import jax

from ._base import Solver, residuals


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
