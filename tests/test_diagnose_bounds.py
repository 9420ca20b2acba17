"""Bounds on the model's constants in ``pamid diagnose`` (``--bounds``, ``bounds=``)."""

from __future__ import annotations

import json
import math

import jax
import numpy as np
import pytest

import pamid
from pamid._cli import main
from pamid._diagnose._api import diagnose


@pytest.fixture(scope="module")
def hysteresis_csv(tmp_path_factory):
    proto = pamid.SarosiProtocol(min_force_N=10.0,
                                 effects=(pamid.InjectedHysteresis(N_at_3_bar=9.0),))
    frame = pamid.simulate_sarosi_bench(jax.random.key(5), pamid.sarosi.table_3_1(), proto)
    path = tmp_path_factory.mktemp("bounds") / "hysteresis.csv"
    frame.to_csv(path, index=False)
    return path


def test_cli_bounds_hold_the_baseline_and_every_refit(hysteresis_csv, capsys):
    """Table 3-1's a3 = −0.329 lies outside [−3, −0.5]: the baseline holds a3 on −0.5, and
    the refits with effects keep it there; hysteresis is still found first. (The model
    held away from its optimum leaves more for other effects to take up.)"""
    assert main(["diagnose", str(hysteresis_csv), "--bounds", "a3=-3:-0.5", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["selected"][0] == "hysteresis"
    assert d["constants"][0]["base"]["a3"] == -0.5
    for step in d["steps"]:
        for row in step["candidates"]:
            assert "a3 would need" not in (row.get("unphysical") or "")


def test_a_refit_that_would_leave_the_bounds_holds_the_constant_on_its_bound(tmp_path):
    """A rig with compliance; a1 bounded to a sliver around the baseline's own value. The
    baseline lies inside, but the compliance's refit moves a1 far out (to −4.5 from
    −15.6): that refit is solved again with a1 held on its bound, so no reported constant
    leaves the bounds, no candidate is refused for a1, and the compliance, held to a model
    it cannot bend, gains far less than unbounded (there ΔBIC ≈ −700)."""
    proto = pamid.SarosiProtocol(min_force_N=10.0,
                                 effects=(pamid.InjectedCompliance(mm_per_N=0.002),))
    frame = pamid.simulate_sarosi_bench(jax.random.key(1), pamid.sarosi.table_3_1(), proto)
    path = tmp_path / "compliance.csv"
    frame.to_csv(path, index=False)
    base = pamid.fit_least_squares(pamid.load_bench(path), "sarosi")
    a1 = float(base.theta[0, 0])
    lower, upper = np.full(6, -np.inf), np.full(6, np.inf)
    lower[2], upper[2] = -3.0, 0.0
    lower[0], upper[0] = a1 - 1e-6 * abs(a1), a1 + 1e-6 * abs(a1)
    d = diagnose(path, bounds=(lower, upper))
    for c in d.constants:
        assert lower[0] <= c["base"]["a1"] <= upper[0]
    for step in d.steps:
        for row in step["candidates"]:
            assert "a1 would need" not in (row["unphysical"] or "")
    row = next(r for r in d.steps[0]["candidates"] if r["effect"] == "compliance")
    assert -100.0 < row["delta_bic"] < 0.0


@pytest.mark.parametrize("text", ["zz=1:2", "a3=0:-3", "a3"])
def test_cli_bad_bounds_is_one_line_exit_2(hysteresis_csv, capsys, text):
    assert main(["diagnose", str(hysteresis_csv), "--bounds", text]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--bounds" in err[0]


def test_the_refits_call_size_is_a_setting_of_speed_not_of_results(tmp_path):
    """The refits' lane-samples a call (``pamid.engine.diagnosis_call_lane_samples``) change
    how many lanes share a compiled call, not what the diagnosis finds; the setting is put
    back after its block, and a size below one lane-sample is refused."""
    import jax

    import pamid
    from pamid._diagnose import _static
    from pamid.engine import diagnosis_call_lane_samples

    proto = pamid.SarosiProtocol(min_force_N=10.0, hysteresis_N_per_bar=3.0,
                                 points_per_curve=40)
    frame = pamid.simulate_sarosi_bench(jax.random.key(3), pamid.sarosi.table_3_1(), proto,
                                        muscle_ids=["M1"])
    path = tmp_path / "bench.csv"
    frame.to_csv(path, index=False)
    default = _static.CALL_LANE_SAMPLES, _static.SMALL_CALL_LANE_SAMPLES
    first = pamid.diagnose(path)
    with diagnosis_call_lane_samples(1024):  # 400 rows, the 512-row class: 2 lanes, not 8
        assert _static.CALL_LANE_SAMPLES == _static.SMALL_CALL_LANE_SAMPLES == 1024
        second = pamid.diagnose(path)
    assert (_static.CALL_LANE_SAMPLES, _static.SMALL_CALL_LANE_SAMPLES) == default
    assert second.selected == first.selected == ["hysteresis"]
    assert math.isclose(second.rmse_after, first.rmse_after, rel_tol=1e-9)
    assert math.isclose(second.cv_rmse_after, first.cv_rmse_after, rel_tol=1e-9)
    with pytest.raises(ValueError, match="at least 1 lane-sample"):
        with diagnosis_call_lane_samples(0):
            pass
    assert (_static.CALL_LANE_SAMPLES, _static.SMALL_CALL_LANE_SAMPLES) == default
