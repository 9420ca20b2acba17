"""The fitting path of ``pamid fit`` without per-muscle work: the vectorised packer, the
curve ids, the profile intervals by Newton's method, and what the command imports.

References: the per-muscle packing and curve ids as they were written before (a loop over
muscles, kept here as plain NumPy), and profile-t interval ends found by SciPy (refits with
``least_squares`` and a root search with ``brentq``).
"""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pandas as pd
import pytest
import scipy.optimize
import scipy.stats

import pamid
from pamid._data._curves import find_curves
from pamid._fit._api import bench_to_fit_data
from pamid._lanes._batch import pack_rows

# ----------------------------------------------------------------------------------------
# Reference: the per-muscle packer and curve ids (one muscle at a time)
# ----------------------------------------------------------------------------------------


def pack_loop(groups, curves=None):
    """Padded arrays muscle by muscle: padding repeats the first sample in x, y = 0, w = 0,
    curve −1; curve ids made dense per muscle with np.unique."""
    n_x, m = len(groups[0][0]), len(groups)
    # the longest muscle's rows, padded to their size class (pamid.engine.padded_rows)
    n_max = pamid.engine.padded_rows(max(len(y) for _, y in groups), m)
    xs = np.zeros((n_x, m, n_max))
    y = np.zeros((m, n_max))
    w = np.zeros((m, n_max))
    curve = np.full((m, n_max), -1, dtype=np.int64)
    for i, (x_i, y_i) in enumerate(groups):
        n = len(y_i)
        for j in range(n_x):
            xs[j, i, :n] = x_i[j]
            xs[j, i, n:] = x_i[j][0] if n else 0.0
        y[i, :n] = y_i
        w[i, :n] = 1.0
        if curves is None:
            curve[i, :n] = 0
        else:
            curve[i, :n] = np.unique(np.asarray(curves[i]), return_inverse=True)[1]
    return xs, y, w, curve


def assert_same_bits(data, ref):
    xs, y, w, curve = ref
    for a, b in zip((*data.x, data.y, data.w, data.curve), (*xs, y, w, curve), strict=True):
        a = np.asarray(a)
        assert a.dtype == b.dtype and a.shape == b.shape
        assert np.array_equal(a, b)


def ragged_groups(rng, sizes):
    groups, curves = [], []
    for n in sizes:
        x = (rng.uniform(0, 6, n), rng.uniform(0, 25, n))
        groups.append((x, rng.normal(300, 50, n)))
        curves.append(rng.integers(3, 40, n) * 7)  # sparse, unsorted ids
    return groups, curves


def test_pack_equals_the_per_muscle_loop_on_ragged_muscles():
    rng = np.random.default_rng(11)
    groups, curves = ragged_groups(rng, [5, 1, 17, 0, 9, 17, 2])
    assert_same_bits(pamid.pack_muscles(groups, curves), pack_loop(groups, curves))
    assert_same_bits(pamid.pack_muscles(groups), pack_loop(groups))


def test_pack_rows_with_interleaved_muscles_equals_the_loop():
    """Rows of the muscles interleaved in the table (not one block each): the packer keeps
    each muscle's rows in table order."""
    rng = np.random.default_rng(5)
    codes = rng.integers(0, 4, 60)
    p, k, y = rng.uniform(0, 6, 60), rng.uniform(0, 25, 60), rng.normal(0, 9, 60)
    curve = rng.integers(0, 5, 60)
    groups = [((p[codes == i], k[codes == i]), y[codes == i]) for i in range(4)]
    ref = pack_loop(groups, [curve[codes == i] for i in range(4)])
    assert_same_bits(pack_rows(codes, (p, k), y, curve), ref)


def test_bench_to_fit_data_equals_the_per_muscle_loop(tmp_path):
    """A bench file with ragged muscles whose rows are interleaved, cycles and directions:
    the same arrays, bit for bit, as packing each muscle's frame on its own."""
    rng = np.random.default_rng(3)
    rows = []
    for m, n in (("B", 23), ("A", 7), ("C", 31)):
        p = np.repeat([100.0, 300.0, 500.0], -(-n // 3))[:n] + rng.normal(0, 0.5, n)
        rows.append(pd.DataFrame({
            "muscle": m,
            "pressure_kPa": p,
            "contraction_pct": rng.uniform(0, 20, n),
            "force_N": rng.uniform(10, 900, n),
            "direction": rng.choice([-1, 1], n),
            "cycle": np.sort(rng.integers(0, 3, n)),
        }))
    frame = pd.concat(rows, ignore_index=True).sample(frac=1.0, random_state=1)
    path = tmp_path / "ragged.csv"
    frame.to_csv(path, index=False)
    bench = pamid.load_bench(path)
    assert bench.muscles == tuple(pd.unique(frame["muscle"]))
    assert not frame["muscle"].is_monotonic_increasing  # interleaved, not sorted
    groups, curves = [], []
    for m in bench.muscles:
        f = bench.for_muscle(m)
        groups.append(((f["pressure_kPa"].to_numpy() / 100.0, f["contraction_pct"].to_numpy()),
                       f["force_N"].to_numpy()))
        curves.append(find_curves(f).curve)  # the one curve definition, muscle by muscle
    assert_same_bits(bench_to_fit_data(bench), pack_loop(groups, curves))


def test_packed_curves_are_the_files_curves_and_restart_in_every_muscle(tmp_path):
    frame = pd.DataFrame({
        "muscle": ["A"] * 4 + ["B"] * 4,
        "pressure_kPa": [100.0, 100.0, 300.0, 300.0, 100.0, 100.0, 500.0, 500.0],
        "contraction_pct": [0.0, 5.0, 0.0, 5.0, 0.0, 5.0, 0.0, 5.0],
        "force_N": [500.0, 300.0, 900.0, 700.0, 500.0, 300.0, 900.0, 700.0],
    })
    path = tmp_path / "two.csv"
    frame.to_csv(path, index=False)
    bench = pamid.load_bench(path)
    data = bench_to_fit_data(bench)
    np.testing.assert_array_equal(np.asarray(data.curve)[:, :4], [[0, 0, 1, 1], [0, 0, 1, 1]])
    assert (np.asarray(data.curve)[:, 4:] == -1).all()  # the padding to the size class
    np.testing.assert_array_equal(bench.curves.curve, [0, 0, 1, 1, 0, 0, 1, 1])
    assert (np.asarray(bench_to_fit_data(bench, curves=False).curve)[:, :4] == 0).all()


# ----------------------------------------------------------------------------------------
# Profile intervals against SciPy
# ----------------------------------------------------------------------------------------


def _sarosi(theta, p, k):
    a1, a2, a3, a4, a5, a6 = theta
    return (a1 * p + a2) * np.exp(a3 * k) + a4 * k * p + a5 * p + a6


def scipy_profile_end(p, k, y, theta_hat, sse_min, t2s2, j, side, half):
    """The end of the profile-t interval of constant j on one side, by SciPy: S(v) is the
    least-squares refit with θ_j = v (``least_squares``, lm, analytic Jacobian), and the end
    is the root of S(v) − S_min − t²·s² (``brentq``, bracketed by stepping out)."""
    free = [i for i in range(6) if i != j]

    def sse(v):
        def res(q):
            th = np.empty(6)
            th[free], th[j] = q, v
            return _sarosi(th, p, k) - y

        def jac(q):
            th = np.empty(6)
            th[free], th[j] = q, v
            a1, a2, a3 = th[:3]
            e = np.exp(a3 * k)
            cols = np.stack([p * e, e, (a1 * p + a2) * k * e, k * p, p, np.ones_like(p)], 1)
            return cols[:, free]

        sol = scipy.optimize.least_squares(res, theta_hat[free], jac=jac, method="lm",
                                           xtol=1e-15, ftol=1e-15, gtol=1e-15)
        return float(np.sum(sol.fun**2)) - sse_min - t2s2

    far = theta_hat[j] + side * half
    while sse(far) < 0:
        far = theta_hat[j] + 2 * (far - theta_hat[j])
    return scipy.optimize.brentq(sse, theta_hat[j], far, xtol=1e-13 * abs(half), rtol=1e-15)


@pytest.mark.parametrize("noise_N", [2.0, 40.0])
def test_profile_ends_equal_scipys_profile(small_bench, split_frame, noise_N):
    """Every end of every constant of three muscles, at Sárosi's noise and at 20× it (where
    a3's interval is visibly lopsided): within 1e-6 of the interval's width of SciPy's."""
    import jax

    protocol = pamid.SarosiProtocol(min_force_N=10.0, noise_sd_N=noise_N)
    frame = pamid.simulate_sarosi_bench(jax.random.key(4), pamid.Sarosi.from_vector(
        small_bench.theta), protocol)
    groups = split_frame(frame)
    fit = pamid.fit_least_squares(pamid.pack_muscles(groups), intervals=("wald", "profile"))
    assert np.all(fit.profile_ok)
    for i, ((p, k), y) in enumerate(groups):
        s2 = fit.sse[i] / fit.dof[i]
        t2s2 = scipy.stats.t.ppf(0.975, fit.dof[i]) ** 2 * s2
        for j in range(6):
            lo, hi = fit.ci95_profile[i, j]
            half = fit.ci95[i, j, 1] - fit.theta[i, j]
            for side, end in ((-1, lo), (1, hi)):
                ref = scipy_profile_end(p, k, y, fit.theta[i], fit.sse[i], t2s2, j, side, half)
                assert abs(end - ref) <= 1e-6 * (hi - lo), (i, j, side, end, ref)


def test_profile_is_lopsided_where_the_model_is_curved(small_bench, split_frame):
    """At 40 N of noise the profile interval of a3 differs from the Wald interval by more
    than the tolerance above: the comparison with SciPy is not one of Wald with Wald."""
    import jax

    protocol = pamid.SarosiProtocol(min_force_N=10.0, noise_sd_N=40.0)
    frame = pamid.simulate_sarosi_bench(jax.random.key(4), pamid.Sarosi.from_vector(
        small_bench.theta), protocol)
    fit = pamid.fit_least_squares(pamid.pack_muscles(split_frame(frame)),
                                  intervals=("wald", "profile"))
    width = fit.ci95[..., 1] - fit.ci95[..., 0]
    assert np.max(np.abs(fit.ci95_profile - fit.ci95) / width[..., None]) > 1e-3


def test_profile_without_the_covariance_starts_in_the_constant_alone(small_bench):
    """Started at θ̂ ± t·se in each constant alone (no (JᵀJ)⁻¹ given), the iteration reaches
    the same ends."""
    from pamid._fit import _intervals

    fit = pamid.fit_least_squares(small_bench.data, intervals=("wald", "profile"))
    s2 = fit.sse / fit.dof
    lo, hi, ok = _intervals.profile(fit.spec, small_bench.data, fit.theta, fit.se, s2, fit.sse,
                                    fit.dof)
    assert np.all(ok)
    width = fit.ci95_profile[..., 1] - fit.ci95_profile[..., 0]
    np.testing.assert_array_less(np.abs(lo - fit.ci95_profile[..., 0]), 1e-6 * width)
    np.testing.assert_array_less(np.abs(hi - fit.ci95_profile[..., 1]), 1e-6 * width)



def test_profile_settings_are_the_solvers(small_bench):
    """The profile's Newton iteration is a solver value: ``solver=ProfileNewton(max_steps=…)``
    gives the same ends as the deprecated keyword, which warns."""
    from pamid._fit import _intervals
    from pamid._solvers import ProfileNewton

    fit = pamid.fit_least_squares(small_bench.data, intervals=("wald",))
    s2 = fit.sse / fit.dof
    args = (fit.spec, small_bench.data, fit.theta, fit.se, s2, fit.sse, fit.dof)
    lo, hi, ok = _intervals.profile(*args, solver=ProfileNewton(max_steps=30))
    with pytest.warns(DeprecationWarning, match="solver=ProfileNewton"):
        lo2, hi2, ok2 = _intervals.profile(*args, max_steps=30)
    assert np.all(ok) and np.array_equal(ok, ok2)
    np.testing.assert_array_equal(lo, lo2)
    np.testing.assert_array_equal(hi, hi2)

# ----------------------------------------------------------------------------------------
# What the command imports
# ----------------------------------------------------------------------------------------


def test_fit_help_does_not_import_the_sampler():
    code = (
        "import sys\n"
        "from pamid._cli import main\n"
        "try:\n"
        "    main(['fit', '--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "heavy = [m for m in ('pamid._commands.mcmc', 'pamid._sampling._mcmc', 'arviz', "
        "'emcee', 'matplotlib') if m in sys.modules]\n"
        "print('HEAVY', heavy)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert "--walkers" in out.stdout  # the MCMC options are still offered
    assert "HEAVY []" in out.stdout, out.stdout[-500:]


def test_to_dict_writes_every_number_as_the_element_wise_conversion(small_bench):
    """The JSON document made from whole arrays at once holds, entry by entry, what
    converting each element did: the same floats, and None for NaN and ±inf."""
    import dataclasses

    from pamid._fit._api import _num, _pair

    fit = pamid.fit_least_squares(small_bench.data, intervals=("wald", "profile"))
    se = fit.se.copy()
    se[1, 2], se[2, 0] = np.nan, np.inf
    prof = fit.ci95_profile.copy()
    prof[0, 3, 1] = np.nan
    fit = dataclasses.replace(fit, se=se, ci95_profile=prof)
    doc = fit.to_dict()
    assert doc["muscles"][1]["params"]["a3"]["se"] is None
    assert doc["muscles"][0]["params"]["a4"]["ci95_profile"] == [float(prof[0, 3, 0]), None]
    for i, muscle in enumerate(doc["muscles"]):
        assert muscle["n"] == int(fit.n[i]) and type(muscle["n"]) is int
        assert muscle["rmse_N"] == _num(fit.rmse_N[i]) and muscle["r"] == _num(fit.r[i])
        assert muscle["converged"] is bool(fit.converged[i])
        for j, name in enumerate(fit.param_names):
            entry = muscle["params"][name]
            assert entry["value"] == _num(fit.theta[i, j])
            assert entry["se"] == _num(fit.se[i, j])
            assert entry["ci95"] == _pair(fit.ci95[i, j])
            assert entry["ci95_profile"] == _pair(fit.ci95_profile[i, j])
            assert all(type(v) in (float, type(None)) for v in entry["ci95"] + [entry["se"]])


def test_fit_json_writes_the_text_json_dumps_writes(small_bench):
    """``pamid.report.fit_json`` (what ``pamid fit --json`` prints) is ``json.dumps`` of
    ``to_dict`` with the command's own keys, character for character: NaN, ±inf, names
    with quotes, '%' and non-ASCII letters, messages, both optional interval kinds."""
    import dataclasses
    import json

    import jax

    from pamid.report import fit_json

    fit = pamid.fit_least_squares(small_bench.data, intervals=("wald", "profile", "bootstrap"),
                                  key=jax.random.key(0), n_bootstrap=20)
    theta = fit.theta.copy()
    theta[0, 1], theta[-1, 5] = np.nan, -np.inf
    names = tuple(['M "1" %s', None, "Düse 5 %"][i % 3] for i in range(fit.n_muscles))
    messages = tuple("why 100 %" if i % 2 else None for i in range(fit.n_muscles))
    fit = dataclasses.replace(fit, theta=theta, muscles=names, messages=messages)
    extra = {"source": "a.csv", "n_censored_dropped": 2, "seconds": 0.5, "plots": ["f.png"]}
    assert fit_json(fit, **extra) == json.dumps({**fit.to_dict(), **extra})
    assert json.loads(fit_json(fit))["muscles"][0]["params"]["a2"]["value"] is None


def test_the_json_floats_are_python_floats_repr_at_every_magnitude():
    """The column-wise float writer of ``fit_json`` gives ``json.dumps``'s text of every
    float64: shortest digits, Python's exponent style, '.0' on whole numbers, -0.0, the
    edges of the range pyarrow writes, subnormals, and null for NaN and ±inf."""
    import json

    from pamid._report._fit import _json_floats

    rng = np.random.default_rng(7)
    mantissa = np.array([round(m, int(d)) for m, d in zip(rng.uniform(1, 10, 4000),
                                                          rng.integers(0, 17, 4000))])
    values = np.concatenate([
        mantissa * 10.0 ** rng.integers(-12, 20, 4000),
        -mantissa * 10.0 ** rng.integers(-330, 300, 4000),
        rng.normal(size=2000) * np.exp(rng.normal(size=2000) * 10),
        [0.0, -0.0, 1e-4, np.nextafter(1e-4, 0), 1e10, np.nextafter(1e10, 0), 100.0,
         -3.0, 5e-324, 1e16, 123456789.0, np.nan, np.inf, -np.inf],
    ])
    expected = [json.dumps(float(v)) if np.isfinite(v) else "null" for v in values]
    assert _json_floats(values).to_pylist() == expected


@pytest.mark.parametrize(("rows", "why"), [
    ("".join(f"{100 * (1 + k % 3)},{800 - 30 * k},{k}\n" for k in range(5)), "too few rows: 5"),
    ("300,500,5\n" * 20, "cannot determine all 6 constants"),
])
def test_a_fit_that_cannot_be_trusted_says_why(tmp_path, rows, why):
    path = tmp_path / "bad.csv"
    path.write_text("pressure_kPa,force_N,contraction_pct\n" + rows)
    with warnings.catch_warnings():  # no raw NumPy warning ("invalid value in multiply")
        warnings.simplefilter("error", RuntimeWarning)
        fit = pamid.fit_least_squares(pamid.load_bench(path), intervals=("wald", "profile"))
    assert not fit.converged[0]
    assert why in fit.message(0)
    assert why in fit.to_dict()["muscles"][0]["message"]


def test_the_t_quantile_is_scipys_for_every_shape_of_dof():
    """One Student-t quantile per muscle, computed once when all share a dof; NaN where
    no degree of freedom is left."""
    from scipy.stats import t as student_t

    from pamid._fit._intervals import t_critical

    for dof in ([294.0] * 5, [3.0, 3.0, 0.0, -1.0, np.nan, 10.5], [[1.0, 2.0], [2.0, 1.0]],
                7.0, [], [np.nan, np.nan]):
        dof = np.asarray(dof, dtype=float)
        with np.errstate(invalid="ignore"):
            expected = np.where(dof > 0, student_t.ppf(0.975, np.maximum(dof, 1)), np.nan)
        got = t_critical(dof, 0.95)
        assert got.shape == dof.shape
        np.testing.assert_allclose(got, expected, rtol=1e-12)
