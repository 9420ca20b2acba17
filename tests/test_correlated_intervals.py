"""Sandwich intervals that hold under correlated residuals (pamid/_fit/_correlated.py).

Known answers: for a linear model with independent noise the sandwich equals the Wald
covariance s²·(XᵀX)⁻¹ in the limit (and HAC with no lags is exactly White's HC1); CR2 and
CR3 computed in the p-dimensional form equal the textbook n_g × n_g formulas; HAC pairs
never cross a group; on AR(1) noise (φ = 0.8) inside curves the cluster interval covers
the true Sárosi constants about 95 % of the time while Wald's does not.
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import pamid
from pamid._fit import _correlated
from pamid._fit._api import bench_to_fit_data, fit_least_squares
from pamid._lanes._batch import FitData
from pamid._models._sarosi import table_3_1
from pamid.report import fit_json


def _linear(key, m, n, p, groups, noise):
    """m replicate linear regressions y = Xβ + e sharing X; J = X, r = Xβ̂ − y."""
    kx, ke = jax.random.split(key)
    x = np.array(jax.random.normal(kx, (n, p)))
    x[:, 0] = 1.0
    e = noise(ke)
    beta = np.linalg.lstsq(x, e.T, rcond=None)[0].T  # true β = 0
    r = beta @ x.T - e
    return np.broadcast_to(x, (m, n, p)).copy(), r, np.broadcast_to(groups, (m, n)).copy()


def test_sandwich_equals_wald_for_iid_noise_in_the_limit():
    m, n, p = 100, 5000, 3
    groups = np.repeat(np.arange(n // 25), 25)  # 200 curves of 25 rows
    jac, r, g = _linear(jax.random.key(0), m, n, p, groups,
                        lambda k: 2.0 * np.asarray(jax.random.normal(k, (m, n))))
    a_inv = np.linalg.inv(jac[0].T @ jac[0])
    s2 = np.sum(r**2, axis=1) / (n - p)
    wald = s2[:, None, None] * a_inv

    def ratio(cov):  # per replicate and constant: sandwich variance / Wald variance
        return np.diagonal(cov, axis1=1, axis2=2) / np.diagonal(wald, axis1=1, axis2=2)

    # HAC with bandwidth ≤ 1 keeps lag 0 only: exactly HC1 = n/(n−p)·A⁻¹(Σ rₜ²xₜxₜᵀ)A⁻¹.
    hc, _ = _correlated.hac_covariance(jac[:3], r[:3], g[:3], bandwidth=1.0)
    hc1 = np.stack([a_inv @ (jac[i].T * r[i] ** 2) @ jac[i] @ a_inv * n / (n - p)
                    for i in range(3)])
    np.testing.assert_allclose(hc, hc1, rtol=1e-10)
    hac, bw = _correlated.hac_covariance(jac, r, g)
    assert np.all(bw < 5)  # Andrews' bandwidth stays small for independent noise
    assert np.all(np.abs(ratio(hac) - 1) < 0.12)
    assert np.all(np.abs(ratio(hac).mean(axis=0) - 1) < 0.03)
    for kind in _correlated.CLUSTER_KINDS:
        cl, n_g = _correlated.cluster_covariance(jac, r, g, kind)
        assert np.all(n_g == 200)
        # one replicate's cluster variance scatters by √(2/G) = 10 %; the mean over 100
        # replicates by 1 %
        assert np.all(np.abs(ratio(cl).mean(axis=0) - 1) < 0.04), (kind, ratio(cl).mean(0))


def test_cr2_cr3_match_the_textbook_formulas():
    m, n, p = 3, 60, 3
    groups = np.repeat(np.arange(6), 10)
    jac, r, g = _linear(jax.random.key(1), m, n, p, groups,
                        lambda k: np.asarray(jax.random.normal(k, (m, n))))
    g[1, -5:] = -1  # padding in one muscle
    jac[1, -5:] = 0.0
    r[1, -5:] = 0.0
    for kind, power in (("CR2", 0.5), ("CR3", 1.0)):
        cov, _ = _correlated.cluster_covariance(jac, r, g, kind)
        for i in range(m):
            a_inv = np.linalg.inv(jac[i].T @ jac[i])
            meat = np.zeros((p, p))
            for c in range(6):
                rows = g[i] == c
                h = jac[i][rows] @ a_inv @ jac[i][rows].T
                adj = scipy.linalg.fractional_matrix_power(np.eye(rows.sum()) - h, -power)
                v = jac[i][rows].T @ np.real(adj) @ r[i][rows]
                meat += np.outer(v, v)
            np.testing.assert_allclose(cov[i], a_inv @ meat @ a_inv, rtol=1e-9)


def test_hac_pairs_never_cross_a_group():
    """Two trials side by side in one lane give the same meat as each trial alone."""
    m, n, p = 1, 80, 2
    groups = np.repeat([0, 1], 40)
    jac, r, g = _linear(jax.random.key(2), m, n, p, groups,
                        lambda k: _correlated.ar1_noise(k, groups, m, 1.0, 0.9))
    rho, p_value, pairs = _correlated.lag1_autocorrelation(r, g)
    assert pairs[0] == 78 and rho[0] > 0.5 and p_value[0] < 1e-3  # AR(1), φ = 0.9
    r[0, 39], r[0, 40] = 50.0, 50.0  # neighbours across the boundary: would dominate
    assert _correlated.lag1_autocorrelation(r, g)[0][0] < 0.2
    assert _correlated.lag1_autocorrelation(r, np.zeros_like(g))[0][0] > 0.4  # if counted
    cov, _ = _correlated.hac_covariance(jac, r, g, bandwidth=10.0)
    a = jac[0].T @ jac[0]
    meat = np.zeros((p, p))
    for c in (0, 1):
        rows = np.flatnonzero(groups == c)
        s = jac[0][rows] * r[0][rows, None]
        meat += s.T @ s
        for lag in range(1, 10):
            gamma = s[lag:].T @ s[:-lag] * (1 - lag / 10.0)
            meat += gamma + gamma.T
    expected = np.linalg.inv(a) @ meat @ np.linalg.inv(a) * n / (n - p)
    np.testing.assert_allclose(cov[0], expected, rtol=1e-10)


def _bench(frame, tmp_path):
    path = tmp_path / "bench.csv"
    frame.to_csv(path, index=False)
    return pamid.load_bench(path)


def test_clusters_never_mix_trials(tmp_path):
    frame = pamid.virtual_lab_file(jax.random.key(3), "isometric_stairs", 1500, n_muscles=2)
    bench = _bench(frame, tmp_path)
    data = bench_to_fit_data(bench, "sarosi")
    trials = _correlated.trial_groups(bench)
    curve = np.asarray(data.curve)
    for i in range(curve.shape[0]):
        for c in np.unique(curve[i][curve[i] >= 0]):
            assert len(np.unique(trials[i][curve[i] == c])) == 1


@pytest.fixture(scope="module")
def ar1_fit():
    """300 replicate muscles at Sárosi's design, AR(1) φ = 0.8 inside every curve."""
    protocol = pamid.SarosiProtocol(noise_sd_N=0.0, force_resolution_N=0.0,
                                    length_resolution_mm=0.0)
    frame = pamid.simulate_sarosi_bench(jax.random.key(4), table_3_1(), protocol)
    from pamid._data._curves import find_curves

    curve = find_curves(frame).curve
    m, n = 300, len(frame)
    e = _correlated.ar1_noise(jax.random.key(5), curve, m, 2.0, 0.8)
    x = (frame["pressure_kPa"].to_numpy() / 100.0, frame["contraction_pct"].to_numpy())
    data = FitData(x=tuple(jnp.asarray(np.broadcast_to(a, (m, n))) for a in x),
                   y=jnp.asarray(frame["force_N"].to_numpy()[None] + e),
                   w=jnp.ones((m, n)), curve=jnp.asarray(np.broadcast_to(curve, (m, n))))
    return fit_least_squares(data, "sarosi", intervals=("wald", "cluster", "hac"))


def test_cluster_interval_covers_under_ar1_noise(ar1_fit, theta31):
    ok = ar1_fit.converged
    assert ok.mean() > 0.99

    def cover(ci):
        return np.mean((ci[ok, :, 0] <= theta31) & (theta31 <= ci[ok, :, 1]))

    # binomial sd of one constant's coverage over 300 muscles: 1.26 %; ±3.5 sd
    assert abs(cover(ar1_fit.ci95_cluster) - 0.95) < 0.045
    assert cover(ar1_fit.ci95) < 0.80  # Wald: far too narrow (≈ 0.62 measured)
    assert cover(ar1_fit.ci95_hac) > cover(ar1_fit.ci95) + 0.1
    assert np.median(ar1_fit.residual_lag1) > 0.6


def test_json_says_which_interval_is_shown_and_why(ar1_fit):
    payload = json.loads(json.dumps(ar1_fit.to_dict()))
    assert json.loads(fit_json(ar1_fit)) == payload  # the fast writer says the same
    muscle = payload["muscles"][0]
    assert set(muscle["params"]["a1"]) >= {"ci95", "ci95_cluster", "ci95_hac"}
    assert muscle["residual_lag1"] == pytest.approx(ar1_fit.residual_lag1[0])
    assert payload["interval_shown"] == "cluster"
    assert "too narrow" in muscle["interval_note"] and "ci95_cluster" in muscle["interval_note"]
    # a packed batch has curves but no trials: HAC sums within curves there
    assert payload["interval_groups"] == {"cluster": "curve", "hac": "curve"}


def test_no_note_for_independent_noise(tmp_path):
    frame = pamid.simulate_sarosi_bench(jax.random.key(6), table_3_1(),
                                        pamid.SarosiProtocol())
    bench = _bench(frame, tmp_path)
    result = fit_least_squares(bench, "sarosi", intervals=("wald", "cluster"))
    payload = result.to_dict()
    assert payload["muscles"][0]["interval_note"] is None
    assert payload["interval_shown"] == "wald-t"
    with pytest.raises(ValueError, match="unknown interval kinds"):
        fit_least_squares(bench, "sarosi", intervals=("wald", "sandwich"))


def test_table_names_the_interval_and_why(ar1_fit):
    from pamid._commands.fit import fit_table as _format_table

    table = _format_table(ar1_fit)
    first = table.split("\n\n")[0]
    assert "cluster low" in first and "HAC high" in first
    assert "  intervals: residual lag-1 autocorrelation" in first
    assert "cluster: cluster-robust (CR3 by curve" in table


def _sarosi_bench(tmp_path, phi):
    """A virtual Sárosi bench file with 2 N of noise, AR(1) with ``phi`` inside every curve
    (0: white)."""
    from pamid._data._curves import find_curves

    protocol = pamid.SarosiProtocol(noise_sd_N=0.0, force_resolution_N=0.0,
                                    length_resolution_mm=0.0)
    frame = pamid.simulate_sarosi_bench(jax.random.key(8), table_3_1(), protocol)
    curve = find_curves(frame).curve
    frame["force_N"] += pamid.engine.ar1_noise(jax.random.key(9), curve, 1, 2.0, phi)[0]
    return _bench(frame, tmp_path)


def test_correlated_residual_shows_the_cluster_interval_by_default(tmp_path):
    """Issue 32, item 11: with the default intervals, a muscle whose residual is correlated
    shows the cluster interval (the JSON's ci95 and se, the table's first columns) and
    says so; Wald's stays in the JSON as ci95_wald and se_wald."""
    from pamid._commands.fit import fit_table as _format_table

    result = fit_least_squares(_sarosi_bench(tmp_path, 0.8), "sarosi")
    assert result.interval_of == ("cluster",) and result.interval_shown == "cluster"
    payload = json.loads(fit_json(result))
    assert payload == json.loads(json.dumps(result.to_dict()))
    assert payload["interval"] == "cluster"
    muscle = payload["muscles"][0]
    assert muscle["interval"] == "cluster" and "shown as ci95" in muscle["interval_note"]
    for j, name in enumerate(result.param_names):
        entry = muscle["params"][name]
        assert entry["ci95"] == entry["ci95_cluster"] == result.ci95_cluster[0, j].tolist()
        assert entry["ci95_wald"] == result.ci95[0, j].tolist()
        assert entry["se_wald"] == result.se[0, j] and entry["se"] == result.se_cluster[0, j]
        assert entry["se"] > entry["se_wald"]  # φ = 0.8: Wald's is far too narrow
    table = _format_table(result)
    assert table.index("cluster low") < table.index("cluster high") < table.index("Wald low")
    assert "Wald low/high: Wald intervals" in table
    # Asked for Wald's: shown, with the note that it is too narrow.
    wald = fit_least_squares(_sarosi_bench(tmp_path, 0.8), "sarosi", show="wald")
    assert wald.interval_of == ("wald-t",) and wald.ci95_cluster is None
    entry = wald.to_dict()["muscles"][0]
    assert entry["params"]["a1"]["ci95"] == entry["params"]["a1"]["ci95_wald"]
    assert "too narrow" in entry["interval_note"]


def test_white_residual_shows_wald_by_default(tmp_path):
    result = fit_least_squares(_sarosi_bench(tmp_path, 0.0), "sarosi")
    assert result.interval_of == ("wald-t",) and result.ci95_cluster is None
    payload = json.loads(fit_json(result))
    assert payload["interval"] == payload["interval_shown"] == "wald-t"
    muscle = payload["muscles"][0]
    assert muscle["interval"] == "wald-t" and muscle["interval_note"] is None
    assert muscle["params"]["a1"]["ci95"] == muscle["params"]["a1"]["ci95_wald"]
    assert "ci95_cluster" not in muscle["params"]["a1"]
    from pamid._commands.fit import fit_table as _format_table

    table = _format_table(result)
    assert "95% low" in table and "Wald low" not in table and "cluster low" not in table
