"""The residual tests' p-values (``pamid/_diagnose/_residual.py``) are scipy.stats's, computed
without importing scipy.stats (0.6 s of a warm ``pamid diagnose``)."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest
from scipy import stats

from pamid._diagnose._residual import (
    covariate_dependence,
    ljung_box,
    runs_test,
    signed_rank_greater,
)


def _wilcoxon(d):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy's small-sample warnings
        return stats.wilcoxon(d, alternative="greater").pvalue


@pytest.mark.parametrize("case", ["exact", "ties_small", "ties", "large", "one_sign", "tiny"])
def test_signed_rank_equals_scipys_wilcoxon(case):
    """Every branch of scipy's "auto" rule: exact without ties (n ≤ 50), the permutation
    test with ties (n ≤ 13), the normal approximation with ties or n > 50; both tails."""
    rng = np.random.default_rng(7)
    for _ in range(60):
        n = {"exact": rng.integers(5, 51), "ties_small": rng.integers(2, 14),
             "ties": rng.integers(14, 51), "large": rng.integers(51, 400),
             "one_sign": rng.integers(5, 60), "tiny": rng.integers(1, 5)}[case]
        d = rng.normal(rng.normal(0.0, 0.7), 1.0, int(n))
        if case.startswith("ties"):
            d = np.round(d, 1)
        if case == "one_sign":
            d = np.abs(d) * rng.choice([-1.0, 1.0])
        d = d[d != 0]
        if len(d) == 0:
            continue
        assert signed_rank_greater(d) == pytest.approx(_wilcoxon(d), rel=1e-12, abs=0.0)


def test_signed_rank_of_nothing_is_nan():
    assert np.isnan(signed_rank_greater(np.zeros(4)))


def test_residual_p_values_equal_scipy_stats():
    rng = np.random.default_rng(3)
    r = [np.cumsum(rng.normal(size=200)) * 0.1 + rng.normal(size=200) for _ in range(3)]
    runs = runs_test(r)
    assert runs["p_value"] == pytest.approx(2 * stats.norm.sf(abs(runs["z"])), rel=1e-14)
    lb = ljung_box(r)
    assert lb["p_value"] == pytest.approx(stats.chi2.sf(lb["q"], lb["dof"]), rel=1e-14)
    x = rng.uniform(0, 10, 600)
    dep = covariate_dependence(np.concatenate(r) + 0.05 * x**2, x, np.repeat([0, 1, 2], 200))
    f, (d1, d2) = dep["f"], dep["dof"]
    assert dep["p_value"] == pytest.approx(stats.f.sf(f, d1, d2), rel=1e-12)


def test_a_diagnosis_does_not_import_scipy_stats(tmp_path):
    """The selection's tests do not load scipy.stats (it is 0.6 s of start-up)."""
    code = (
        "import sys, jax, pamid\n"
        "frame = pamid.simulate_sarosi_bench(jax.random.key(0), pamid.sarosi.table_3_1(),\n"
        "    pamid.SarosiProtocol(points_per_curve=40, hysteresis_N_per_bar=3.0),\n"
        "    muscle_ids=['M1'])\n"
        f"frame.to_csv(r'{tmp_path / 'b.csv'}', index=False)\n"
        f"pamid.diagnose(r'{tmp_path / 'b.csv'}')\n"
        "print('scipy.stats' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "False"
