"""Per-muscle result codes of a fit (``FitResult.status``), physical bounds, ``--bounds``.

Virtual muscles of Sárosi eq. 2.1 (Table 3-1 constants) built to produce each status: a
well-designed map (converged), three contraction levels whose intercepts no exponential
fits (a3 runs off: not_identifiable, held on its bound), five rows for six constants
(too_few_rows), NaN forces (nonfinite), a bound that excludes the optimum (at_bound), a
step budget of one (max_steps).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from sarosi_np import force_np

from pamid._fit._api import STATUSES, _statuses, fit_least_squares
from pamid._fit._least_squares import _take_lanes, fit_lanes, solve, statistics
from pamid._fit._spec import SAROSI
from pamid._inference import RANK_RTOL, null_direction, undetermined
from pamid._lanes._batch import pack
from pamid.report import fit_json

PRESSURES_BAR = np.linspace(1.0, 6.0, 26)


def _muscle(theta, levels, offsets=None, noise=1.0, seed=0):
    """Every pressure at every contraction level, force of eq. 2.1 plus normal noise; the
    force of level j shifted by ``offsets[j]`` N."""
    rng = np.random.default_rng(seed)
    p, k = (a.ravel() for a in np.meshgrid(PRESSURES_BAR, np.asarray(levels, float)))
    y = force_np(theta, p, k) + noise * rng.normal(size=p.size)
    for level, off in zip(levels, offsets or [0.0] * len(levels)):
        y[k == level] += off
    return (p, k), y


@pytest.fixture(scope="module")
def designs(theta31):
    groups = {
        "well designed": _muscle(theta31, [0, 5, 10, 15, 20], seed=1),
        # Intercepts at three levels that no exponential fits (the middle one 60 N low):
        # the best fit without bounds sends a3 off to −∞.
        "three levels": _muscle(theta31, [0, 10, 20], offsets=[0.0, -60.0, 0.0], seed=2),
        "five rows": ((np.array([1.0, 2, 3, 4, 5]), np.array([0.0, 5, 10, 15, 20])),
                      np.array([1.0, 2, 3, 4, 5])),
        "nan force": _muscle(theta31, [0, 5, 10, 15, 20], seed=3),
    }
    groups["nan force"][1][7] = np.nan
    names = tuple(groups)
    return names, pack(list(groups.values()))


@pytest.fixture(scope="module")
def result(designs):
    names, data = designs
    return fit_least_squares(data, muscles=names)


def _status(result, name):
    i = result.muscles.index(name)
    return result.status[i], result.message(i), i


def test_every_status_is_a_known_code(result):
    assert set(result.status) <= set(STATUSES)
    np.testing.assert_array_equal(result.converged,
                                  np.isin(result.status, ("converged", "at_bound")))


def test_a_well_designed_muscle_converges_to_its_constants(result, theta31):
    status, message, i = _status(result, "well designed")
    assert status == "converged" and message is None
    assert np.all((result.ci95[i, :, 0] <= theta31) & (theta31 <= result.ci95[i, :, 1]))


def test_three_levels_that_no_exponential_fits_name_a3_and_hold_it_on_its_bound(result):
    status, message, i = _status(result, "three levels")
    assert status == "not_identifiable"
    assert not result.converged[i]
    lower, upper = SAROSI.bounds
    assert result.theta[i, 2] == pytest.approx(lower[2], abs=1e-12)  # a3 = −3, on its bound
    assert message.startswith("a3 is not determined by these data (3 distinct "
                              "contraction_pct values)")
    assert "ran off to a3 = -" in message
    assert "best fit within bounds: a3 = -3 (at its lower bound)" in message
    # Never a runaway value as the result: every constant within the model's bounds.
    assert np.all(np.isfinite(result.theta[i]))


def test_too_few_rows(result):
    status, message, _ = _status(result, "five rows")
    assert status == "too_few_rows"
    assert message.startswith("too few rows: 5 for the 6 constants")


def test_nan_in_the_force_is_nonfinite_and_named(result):
    status, message, _ = _status(result, "nan force")
    assert status == "nonfinite"
    assert "NaN or ±inf (in force_N)" in message


def test_a_bound_that_excludes_the_optimum_is_at_bound(designs, theta31):
    names, data = designs
    free = fit_least_squares(data, muscles=names)
    i = names.index("well designed")
    upper = np.full(6, np.inf)
    upper[0] = free.theta[i, 0] - 2.0  # a1 two units below its unbounded optimum
    fit = fit_least_squares(data, muscles=names, bounds=(np.full(6, -np.inf), upper))
    assert fit.status[i] == "at_bound" and fit.converged[i]
    assert fit.theta[i, 0] == pytest.approx(upper[0], rel=1e-12)
    assert "a1 = " in fit.message(i) and "(at its upper bound)" in fit.message(i)
    assert fit.sse[i] > free.sse[i]
    # Its intervals are cut at the bound (Wald's centred on it would reach past it), and say
    # so, in the result and in the JSON.
    assert fit.ci95[i, 0, 1] == upper[0] and fit.ci95[i, 0, 0] < upper[0]
    assert fit.interval_cut[i, 0] and not fit.interval_cut[i, 1:].any()
    doc = json.loads(fit_json(fit))
    entry = doc["muscles"][i]["params"]
    assert entry["a1"]["ci95_cut_at_bound"] is True and entry["a2"]["ci95_cut_at_bound"] is False
    assert entry["a1"]["ci95_wald"][1] == upper[0]
    # The same optimum SciPy finds within the same bounds.
    import scipy.optimize

    (p, k), y = (tuple(np.asarray(a[i])[np.asarray(data.w[i]) > 0] for a in data.x),
                 np.asarray(data.y[i])[np.asarray(data.w[i]) > 0])
    start = np.minimum(free.theta[i], upper - 1e-6)
    ref = scipy.optimize.least_squares(lambda t: force_np(t, p, k) - y, start,
                                       bounds=(np.full(6, -np.inf), upper), method="trf",
                                       xtol=1e-14, ftol=1e-14, gtol=1e-14)
    assert fit.sse[i] == pytest.approx(np.sum(ref.fun**2), rel=1e-8)


def test_bounds_are_never_exceeded(designs):
    names, data = designs
    lower = np.array([-5.0, 270.0, -0.5, -9.3, 290.0, -270.0])
    upper = np.array([0.0, 285.0, -0.2, -9.2, 300.0, -262.0])
    fit = fit_least_squares(data, muscles=names, bounds=(lower, upper))
    for i, name in enumerate(names):
        if fit.status[i] in ("too_few_rows", "nonfinite"):
            continue
        assert np.all((lower <= fit.theta[i]) & (fit.theta[i] <= upper)), name
        on_bound = np.isclose(fit.theta[i], lower, rtol=1e-9) | np.isclose(
            fit.theta[i], upper, rtol=1e-9)
        if on_bound.any() and fit.status[i] != "not_identifiable":
            assert fit.status[i] == "at_bound", name


def test_one_step_is_max_steps(designs):
    names, data = designs
    lanes = fit_lanes(SAROSI, data, max_steps=1, starts=1)
    sse, _, _, n, full_rank = statistics(SAROSI, lanes.theta, data)
    se = np.zeros_like(lanes.theta)
    status, messages = _statuses(SAROSI, data, lanes, n, full_rank, se, sse)
    i = names.index("well designed")
    assert status[i] == "max_steps"
    assert "stopped after 1 steps" in messages[i]


def test_the_rank_criterion_names_the_constant_the_data_do_not_see():
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(50, 4))
    jac[:, 2] = 3.0 * jac[:, 0]  # c is 3·a: the direction (1, 0, -1/3, 0) changes nothing
    ratio, v = null_direction(jac)
    assert ratio < RANK_RTOL
    np.testing.assert_allclose(np.abs(v), [1.0, 0.0, 1.0, 0.0], atol=1e-9)  # unit columns
    assert set(undetermined(jac, ["a", "b", "c", "d"])) == {"a", "c"}
    jac[:, 2] += 1e-3 * rng.normal(size=50)  # determined, if poorly
    assert undetermined(jac, ["a", "b", "c", "d"]) == ()


def test_json_has_status_and_message(result):
    doc = json.loads(fit_json(result))
    by_name = {m["muscle"]: m for m in doc["muscles"]}
    assert by_name["well designed"]["status"] == "converged"
    assert by_name["well designed"]["message"] is None
    assert by_name["three levels"]["status"] == "not_identifiable"
    assert by_name["three levels"]["converged"] is False
    assert "a3" in by_name["three levels"]["message"]
    assert doc == json.loads(json.dumps(result.to_dict()))


@pytest.fixture(scope="module")
def three_level_csv(theta31, tmp_path_factory):
    (p, k), y = _muscle(theta31, [0, 10, 20], offsets=[0.0, -60.0, 0.0], seed=2)
    path = tmp_path_factory.mktemp("status") / "three_levels.csv"
    path.write_text("pressure_kPa,contraction_pct,force_N\n" + "".join(
        f"{100 * float(a)!r},{float(b)!r},{float(c)!r}\n" for a, b, c in zip(p, k, y)))
    return path


def test_cli_json_status_and_bounds(pamid_cli, three_level_csv):
    out = pamid_cli(["fit", three_level_csv, "--json", "--intervals", "wald",
                     "--bounds", "a3=-2:0"])
    assert out.returncode == 1, out.stderr
    muscle = json.loads(out.stdout)["muscles"][0]
    assert muscle["status"] == "not_identifiable"
    assert muscle["params"]["a3"]["value"] == pytest.approx(-2.0, abs=1e-12)
    assert "a3 = -2 (at its lower bound)" in muscle["message"]
    table = pamid_cli(["fit", three_level_csv, "--intervals", "wald"])
    assert "NOT CONVERGED: not_identifiable" in table.stdout


@pytest.mark.parametrize(("text", "match"), [
    ("a9=-3:0", "sarosi has no constant 'a9'"),
    ("a3=-3", "'a3=-3' is not NAME=LOW:HIGH"),
    ("a3=x:0", "a3: 'x:0' is not LOW:HIGH with numbers"),
    ("a3=0:-3", "a3: the lower bound 0 must be below the upper bound -3"),
])
def test_bad_bounds_text_is_one_line_naming_the_constant(pamid_cli, three_level_csv, text,
                                                          match):
    out = pamid_cli(["fit", three_level_csv, "--bounds", text])
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and match in lines[0], out.stderr


def test_parse_bounds_keeps_the_models_own_elsewhere():
    from pamid._commands._model import parse_bounds

    lower, upper = parse_bounds("a1=:0, a3=-2:", SAROSI)
    assert upper[0] == 0.0 and lower[0] == -np.inf
    assert lower[2] == -2.0 and upper[2] == np.inf
    assert parse_bounds(None, SAROSI) is None
    with pytest.raises(ValueError, match="sarosi has no constant 'b1'"):
        parse_bounds("b1=0:1", SAROSI)


def test_profile_intervals_end_at_the_bounds(small_bench):
    """A profile end past its constant's bound is the bound (a value the physics forbids is
    no possible value of the constant); the other end and the other constants do not move."""
    data = small_bench.data
    free = fit_least_squares(data, intervals=("wald", "profile"))
    a1, (lo, hi) = free.theta[0, 0], free.ci95_profile[0, 0]
    assert lo < a1 < hi
    cap = a1 + 0.5 * (hi - a1)  # above the estimate, below the profile's upper end
    upper = np.full(6, np.inf)
    upper[0] = cap
    bounded = fit_least_squares(data, intervals=("wald", "profile"),
                                bounds=(np.full(6, -np.inf), upper))
    # muscle 0 is inside the bound: the same fit, its upper profile end cut at the bound
    np.testing.assert_allclose(bounded.theta[0], free.theta[0], rtol=1e-9)
    assert bounded.ci95_profile[0, 0, 1] == cap
    np.testing.assert_allclose(bounded.ci95_profile[0, 0, 0], lo, rtol=1e-9)
    np.testing.assert_allclose(bounded.ci95_profile[0, 1:], free.ci95_profile[0, 1:], rtol=1e-9)
    # no muscle's interval reaches past the bound, whether its fit ended on it or not
    ends = bounded.ci95_profile[:, 0, :]
    assert np.all(ends[np.isfinite(ends)] <= cap)


def test_the_solve_s_statistics_are_those_at_its_constants(designs):
    """The statistics that the registered kernel's program returns with its solve equal
    those of the statistics' own program at the same constants."""
    _, data = designs
    theta, ok, steps, stats = solve(SAROSI, data, with_statistics=True)
    alone = solve(SAROSI, data)
    np.testing.assert_allclose(theta, alone[0], rtol=1e-12)
    np.testing.assert_array_equal(ok, alone[1])
    ref = statistics(SAROSI, theta, data, lag1=True)
    assert len(stats) == len(ref) == 8
    for got, want in zip(stats, ref, strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0.0, equal_nan=True)
    with pytest.raises(ValueError, match="without bounds"):
        solve(SAROSI, data, with_statistics=True, bounds=(np.full(6, -np.inf), np.full(6, np.inf)))


def test_the_fit_keeps_the_solve_s_statistics_only_where_no_lane_changed(designs):
    names, data = designs
    lanes = fit_lanes(SAROSI, data, with_statistics=True)
    # "three levels" left the bounds and was refitted within them: not the solve's constants.
    assert lanes.left_bounds[names.index("three levels")] and lanes.statistics is None
    good = _take_lanes(data, np.array([names.index("well designed")]))
    lanes = fit_lanes(SAROSI, good, with_statistics=True)
    assert lanes.statistics is not None
    for got, want in zip(lanes.statistics, statistics(SAROSI, lanes.theta, good, lag1=True),
                         strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0.0)
    assert fit_lanes(SAROSI, good).statistics is None  # not asked for


def test_no_interval_reaches_past_a_physical_bound(tmp_path):
    """Chou–Hannaford's wall thickness (0 ≤ t ≤ 5 mm) fitted to the bundled file ends on 0;
    none of its intervals says it may be negative (or thicker than the law allows), and
    the table says which were cut. A fit whose intervals lie within the bounds has no
    flag at all (the JSON of every other fit is as it was)."""
    from pathlib import Path

    import pamid
    from pamid._commands.fit import fit_table

    bench = pamid.load_bench(Path(__file__).resolve().parents[1] / "pamid" / "data"
                             / "sarosi_dmsp20_400_virtual.csv")
    fit = fit_least_squares(bench, model="chou_hannaford", intervals=("wald", "cluster"))
    j = fit.param_names.index("t_mm")
    assert fit.theta[0, j] == pytest.approx(0.0, abs=1e-9)
    for ci in (fit.ci95, fit.ci95_cluster, fit.shown_intervals()[0]):
        assert 0.0 <= ci[0, j, 0] <= ci[0, j, 1] <= 5.0
    assert fit.interval_cut[0, j]
    assert "intervals cut at the constants' bounds: t_mm" in fit_table(fit)
    plain = fit_least_squares(bench)  # Sárosi: a3's intervals well inside [-3, 0]
    assert plain.interval_cut is None
    assert "ci95_cut_at_bound" not in json.dumps(plain.to_dict())
