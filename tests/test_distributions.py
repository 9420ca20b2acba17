"""pamid's Student-t quantile and normal tail (pamid/_inference/_distributions.py) against
SciPy's, and a fit that no longer imports SciPy."""

from __future__ import annotations

import math
import subprocess
import sys
from statistics import NormalDist

import numpy as np
import pytest
from scipy import special

from pamid._inference import normal_upper_tail, t_critical
from pamid._inference._distributions import EXPANSION_DOF, t_upper_quantile

#: Degrees of freedom: every whole number up to past the expansion's threshold, a geometric
#: sweep to 10¹², and fractions (Newton from the normal quantile there).
DOFS = np.unique(np.concatenate([
    np.arange(1.0, EXPANSION_DOF + 50), np.geomspace(1.0, 1e12, 400), [1.25, 1.5, 2.5, 7.3]]))


@pytest.mark.parametrize("level", [0.2, 0.5, 0.68, 0.9, 0.95, 0.99, 0.999, 0.99999])
def test_t_quantile_is_scipys(level):
    q = 0.5 + level / 2
    got, want = t_upper_quantile(DOFS, q), special.stdtrit(DOFS, q)
    np.testing.assert_allclose(got, want, rtol=2e-13, atol=0)


@pytest.mark.parametrize("level", [1e-3, 0.01])
def test_t_quantile_of_a_small_level_has_the_tail_asked_for(level):
    """Near the median SciPy's ``stdtrit`` is itself off at ν = 4 (7.5e-13 at level 0.01,
    1e-4 at level 1e-6, where its quantile's tail is 0.49999949995, not 0.4999995); the
    known answer there is the distribution function at the quantile."""
    q = 0.5 + level / 2
    t = t_upper_quantile(DOFS, q)
    np.testing.assert_allclose(special.stdtr(DOFS, t), q, rtol=0, atol=3e-15)


def test_t_quantile_known_values_and_shapes():
    q = 0.975
    assert t_upper_quantile(1.0, q) == pytest.approx(math.tan(math.pi * (q - 0.5)), rel=1e-15)
    assert t_upper_quantile(2.0, q) == pytest.approx(
        (2 * q - 1) / math.sqrt(2 * q * (1 - q)), rel=1e-15)
    assert t_upper_quantile(math.inf, q) == NormalDist().inv_cdf(q)
    assert t_upper_quantile(12.0, 0.5) == 0.0
    got = t_upper_quantile(np.array([[1.0, np.nan], [30.0, 30.0]]), q)
    assert got.shape == (2, 2) and np.isnan(got[0, 1]) and got[1, 0] == got[1, 1]
    assert t_upper_quantile(np.array([]), q).shape == (0,)
    for bad in (1.0, 0.4, math.nan):
        with pytest.raises(ValueError, match="probability"):
            t_upper_quantile(5.0, bad)


def test_t_critical_is_nan_without_degrees_of_freedom():
    got = t_critical(np.array([0, -3, 1, 10]), 0.95)
    assert np.isnan(got[:2]).all()
    np.testing.assert_allclose(got[2:], special.stdtrit([1, 10], 0.975), rtol=1e-14)
    assert float(t_critical(math.inf, 0.95)) == NormalDist().inv_cdf(0.975)


def test_normal_upper_tail_is_scipys_and_keeps_the_far_tail():
    z = np.concatenate([np.linspace(-8, 8, 161), [np.nan, np.inf, -np.inf]])
    np.testing.assert_allclose(normal_upper_tail(z), special.ndtr(-z), rtol=5e-14, atol=0)
    assert normal_upper_tail(30.0) == pytest.approx(special.ndtr(-30.0), rel=1e-13)
    assert normal_upper_tail(30.0) > 0  # 1 − Φ(30) would round to 0


def test_a_fit_read_from_the_cache_imports_neither_scipy_nor_pandas(tmp_path, pamid_cli,
                                                                    cli_env):
    """The fit's quantiles are pamid's and its programs call no LAPACK, so a fit whose
    programs are in the cache (the first run here compiles them, and JAX's lowering binds
    LAPACK from SciPy then) never imports SciPy: 0.1-0.15 s of a one-muscle fit. Its file
    is read, and its JSON written, without pandas (0.2 s)."""
    code = (
        "import jax, pamid\n"
        "frame = pamid.simulate_sarosi_bench(jax.random.key(3), pamid.sarosi.table_3_1(),\n"
        "    pamid.SarosiProtocol(points_per_curve=40), muscle_ids=['M1'])\n"
        f"frame.to_csv(r'{tmp_path / 'one.csv'}', index=False)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=600)
    first = pamid_cli(["fit", tmp_path / "one.csv", "--json"])
    assert first.returncode == 0, first.stderr[-2000:]
    probe = (
        "import contextlib, io, sys\n"
        "from pamid._cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    code = main(['fit', r'{tmp_path / 'one.csv'}', '--json'])\n"
        "print(code, 'scipy' in sys.modules, 'pandas' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         env=cli_env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "0 False False"
