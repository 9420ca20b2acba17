"""A user's model of many constants fits in seconds (issue 32, item 4).

A ``pamid.ForceModel`` of 40 constants, a sum of simple terms, linear in all of them: its
start (the linear constants solved for trial values of the others, ``pamid._fit._start``)
is a program whose size grows about linearly with the constants, not as their cube (a
written-out Cholesky of 50 constants did not finish tracing and compiling in 120 s), and the
fit recovers the constants of noise-free data.
"""

from __future__ import annotations

import jax
import numpy as np
import pandas as pd

import pamid
from pamid._fit._spec import spec_from_model


def many_source(n: int) -> str:
    """A model file of class ``Many``: F = Σ cᵢ·T_a(p̃)·T_b(κ̃), Chebyshev polynomials of the
    scaled pressure (degree 0–4) and contraction."""
    lines = ["import pamid", "", "", "def cheb(x, degree):", "    out = [x * 0 + 1, x]",
             "    while len(out) <= degree:", "        out.append(2 * x * out[-1] - out[-2])",
             "    return out", "", "", "class Many(pamid.ForceModel):"]
    lines += [f"    c{i}: float = 0.0" for i in range(n)]
    lines += [f"    units = {({f'c{i}': 'N' for i in range(n)})!r}",
              '    inputs = ("pressure_bar", "contraction_pct")', "",
              "    def __call__(self, pressure_bar, contraction_pct):",
              "        tp = cheb((pressure_bar - 3.5) / 2.5, 4)",
              f"        tk = cheb((contraction_pct - 15.0) / 15.0, {n // 5})",
              "        return (0.0"]
    lines += [f"                + self.c{i} * tp[{i % 5}] * tk[{i // 5}]" for i in range(n)]
    lines[-1] += ")"
    return "\n".join(lines) + "\n"


def many_class(n: int) -> type:
    namespace: dict = {}
    exec(compile(many_source(n), f"<many{n} model file>", "exec"), namespace)
    return namespace["Many"]


def _equations(jaxpr) -> int:
    """Equations of a jaxpr, those of the programs it calls included."""
    count = 0
    for eqn in jaxpr.eqns:
        count += 1
        for value in eqn.params.values():
            for sub in value if isinstance(value, (tuple, list)) else (value,):
                inner = getattr(sub, "jaxpr", sub)
                if hasattr(inner, "eqns"):
                    count += _equations(inner)
    return count


def _start_size(n: int, rows: int = 60) -> int:
    spec = spec_from_model(many_class(n))
    x = tuple(np.linspace(1.0, 6.0, rows)[None] for _ in spec.columns)
    y, w = np.ones((1, rows)), np.ones((1, rows))
    assert np.all(spec.linear())  # found outside the trace, as a fit finds them first
    return _equations(jax.make_jaxpr(lambda x, y, w: spec.candidates(x, y, w))(x, y, w).jaxpr)


def test_start_of_many_constants_grows_about_linearly():
    small, large = _start_size(10), _start_size(40)
    # Written out, the Cholesky of the normal equations was n³/6 products, twice (about
    # 45,000 equations at 40 constants, 50 times those at 10); by LAPACK, one call.
    assert large < 8 * small, (small, large)


def test_many_constants_fit_recovers_them(tmp_path):
    n = 40
    rng = np.random.default_rng(3)
    p = rng.uniform(1.0, 6.0, 300)
    k = rng.uniform(0.0, 30.0, 300)
    truth = rng.normal(0.0, 10.0, n)
    model = many_class(n)(**{f"c{i}": float(c) for i, c in enumerate(truth)})
    force = np.asarray(model(p, k))
    path = tmp_path / "bench.csv"
    pd.DataFrame({"pressure_bar": p, "contraction_pct": k, "force_N": force}).to_csv(
        path, index=False)
    fit = pamid.fit_least_squares(pamid.load_bench(path), many_class(n), intervals=("wald",))
    assert bool(fit.converged[0])
    got = np.array([float(getattr(fit.params(0), f"c{i}")) for i in range(n)])
    np.testing.assert_allclose(got, truth, rtol=1e-6, atol=1e-6)
