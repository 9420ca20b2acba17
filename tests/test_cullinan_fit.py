"""Fitting Cullinan's eq. 3 (A–E, and G with velocity) through the shared batched path."""

from __future__ import annotations

import json
import subprocess
import sys

import jax
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._fit._spec import CULLINAN, CULLINAN_DYNAMIC

TRUE = np.array([-50.0, 3.0, 5.0, 0.02, 0.05, 0.3])  # A, B, C, D, E (N, kPa, mm) and G (N·s/mm)
PRESSURES = (100.0, 200.0, 300.0, 414.0)


def _design(rng, velocity=False):
    p = np.repeat(PRESSURES, 20)
    y = np.tile(np.linspace(0.0, 45.0, 20), len(PRESSURES))
    v = rng.normal(0.0, 20.0, p.size) if velocity else np.zeros_like(p)
    return p, y, v


def _force(theta, p, y, v):
    return np.asarray(pamid.cullinan.cullinan_force(pamid.Cullinan.from_vector(theta), p, y, v))


def test_gauss_newton_path_equals_the_exact_linear_solution():
    """Eq. 3 is linear in A–E (and G): the shared nonlinear path must land on lstsq's answer."""
    rng = np.random.default_rng(0)
    groups, exact = [], []
    for _ in range(5):
        p, y, v = _design(rng, velocity=True)
        f = _force(TRUE, p, y, v) + rng.normal(0.0, 2.0, p.size)
        groups.append(((p, y, v), f))
        design = np.stack([np.ones_like(p), p, -y, -p * y, -y * y, -v], axis=1)
        exact.append(np.linalg.lstsq(design, f, rcond=None)[0])
    result = pamid.fit_least_squares(pamid.pack_muscles(groups), CULLINAN_DYNAMIC)
    assert result.converged.all()
    np.testing.assert_allclose(result.theta, np.array(exact), rtol=1e-9, atol=1e-12)


def test_static_fit_from_a_bench_file(tmp_path):
    rng = np.random.default_rng(1)
    p, y, _ = _design(rng)
    f = _force(TRUE[:5], p, y, 0.0) + rng.normal(0.0, 1.0, p.size)
    path = tmp_path / "static.csv"
    pd.DataFrame({"pressure_kPa": p, "contraction_mm": y, "force_N": f}).to_csv(path, index=False)
    result = pamid.fit_least_squares(pamid.load_bench(path), "cullinan")
    assert result.param_names == ("A", "B", "C", "D", "E")
    assert result.to_dict()["units"] == {"force": "N", "pressure": "kPa", "contraction": "mm",
                                         "time": "s"}
    lo, hi = result.ci95[0, :, 0], result.ci95[0, :, 1]
    assert np.all((lo < TRUE[:5]) & (TRUE[:5] < hi))
    assert isinstance(result.params(0), pamid.Cullinan)


def test_velocity_column_adds_g(tmp_path):
    rng = np.random.default_rng(2)
    p, y, v = _design(rng, velocity=True)
    f = _force(TRUE, p, y, v) + rng.normal(0.0, 1.0, p.size)
    path = tmp_path / "dynamic.csv"
    pd.DataFrame({"pressure_kPa": p, "contraction_mm": y, "velocity_mm_s": v,
                  "force_N": f}).to_csv(path, index=False)
    result = pamid.fit_least_squares(pamid.load_bench(path), "cullinan")
    assert result.param_names[-1] == "G"
    lo, hi = result.ci95[0, 5]
    assert lo < TRUE[5] < hi


def test_coverage_of_the_intervals():
    """95% intervals of A–E cover the truth 95% ± 1.5% of the time over 2000 data sets."""
    n_sets = 2000
    key = jax.random.key(4)
    p, y, v = _design(np.random.default_rng(0))
    noise = 2.0 * np.asarray(jax.random.normal(key, (n_sets, p.size)))
    f = _force(TRUE[:5], p, y, 0.0)[None, :] + noise
    groups = [((p, y), f[i]) for i in range(n_sets)]
    result = pamid.fit_least_squares(pamid.pack_muscles(groups), CULLINAN)
    covered = (result.ci95[..., 0] < TRUE[:5]) & (TRUE[:5] < result.ci95[..., 1])
    coverage = covered.mean(axis=0)
    assert np.all(np.abs(coverage - 0.95) <= 0.015), coverage


def test_contraction_converts_between_percent_and_mm(tmp_path):
    path = tmp_path / "len.csv"
    pd.DataFrame({"pressure_kPa": [300.0, 300.0], "length_mm": [190.0, 171.0],
                  "l0_mm": [190.0, 190.0], "force_N": [900.0, 500.0]}).to_csv(path, index=False)
    frame = pamid.load_bench(path).frame
    np.testing.assert_allclose(frame["contraction_mm"], [0.0, 19.0])
    np.testing.assert_allclose(frame["contraction_pct"], [0.0, 10.0])


def test_cullinan_needs_contraction_in_mm(tmp_path):
    path = tmp_path / "pct_only.csv"
    pd.DataFrame({"pressure_kPa": [300.0] * 8, "contraction_pct": np.linspace(0, 10, 8),
                  "force_N": np.linspace(900, 400, 8)}).to_csv(path, index=False)
    with pytest.raises(pamid.BenchDataError, match=r"pct_only.csv.*column 'contraction_mm'.*"
                                                   r"cullinan model needs contraction_mm"):
        pamid.fit_least_squares(pamid.load_bench(path), "cullinan")


def test_contraction_mm_outside_the_physical_range_names_the_row(tmp_path):
    path = tmp_path / "bad.csv"
    pd.DataFrame({"pressure_kPa": [300.0, 300.0], "contraction_mm": [10.0, 120.0],
                  "l0_mm": [190.0, 190.0], "force_N": [900.0, 500.0]}).to_csv(path, index=False)
    with pytest.raises(pamid.BenchDataError, match=r"column 'contraction_mm', row 2.*63.16 %"):
        pamid.load_bench(path)


def test_cli_fit_cullinan_json(tmp_path):
    rng = np.random.default_rng(5)
    p, y, _ = _design(rng)
    path = tmp_path / "bench.csv"
    pd.DataFrame({"muscle": "T1", "pressure_kPa": p, "contraction_mm": y,
                  "force_N": _force(TRUE[:5], p, y, 0.0) + rng.normal(0, 1, p.size)}).to_csv(
        path, index=False)
    res = subprocess.run([sys.executable, "-m", "pamid._cli", "fit", str(path), "--model",
                          "cullinan", "--json", "--intervals", "wald"],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    payload = json.loads(res.stdout)
    assert payload["model"] == "cullinan" and payload["units"]["contraction"] == "mm"
    muscle = payload["muscles"][0]
    assert muscle["muscle"] == "T1" and list(muscle["params"]) == ["A", "B", "C", "D", "E"]
    assert muscle["params"]["B"]["unit"] == "N/kPa"
