"""Issue #5: data with an undeclared effect in it — does ``pamid diagnose`` find it?

The virtual bench hides each effect in a file that does not mention it (a temperature column
is logged, but nothing says the force depends on it). Noise: 2 N per reading, 5 repeats
averaged, so the noise level of the data is 2/√5 ≈ 0.894 N.
"""

from __future__ import annotations

import json
import math

import jax
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid import (
    InjectedCompliance,
    InjectedCovariate,
    InjectedDrift,
    InjectedHysteresis,
    InjectedTemperature,
    InjectedViscousDamping,
)
from pamid._data._curves import find_curves
from pamid._diagnose._api import diagnose
from pamid._diagnose._residual import covariate_dependence, ljung_box, runs_test

NOISE_N = 2.0 / math.sqrt(5.0)
SPEEDS = (1.0, 3.0, 2.0, 1.5)  # seconds per point of successive sweeps


def _bench(tmp_path, effects, seed=1, drop=(), name="bench.csv", **protocol):
    proto = pamid.SarosiProtocol(min_force_N=10.0, effects=effects, **protocol)
    frame = pamid.simulate_sarosi_bench(jax.random.key(seed), pamid.sarosi.table_3_1(), proto)
    path = tmp_path / name
    frame.drop(columns=list(drop)).to_csv(path, index=False)
    return path


# -- the residual tests against known answers --------------------------------------------------


def test_runs_test_known_counts():
    r = np.array([1.0, 1.0, -1.0, -1.0, 1.0, -1.0])  # 4 runs, n1 = n2 = 3
    out = runs_test([r])
    assert out["runs"] == 4
    assert out["expected"] == pytest.approx(2 * 3 * 3 / 6 + 1)


def test_ljung_box_white_and_correlated():
    rng = np.random.default_rng(0)
    white = [rng.normal(size=400) for _ in range(3)]
    walk = [np.cumsum(rng.normal(size=400))]
    assert ljung_box(white)["p_value"] > 0.01
    assert ljung_box(white)["dof"] == 30
    assert ljung_box(walk)["p_value"] < 1e-10


def test_covariate_dependence_finds_a_cubic_and_not_noise():
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 10, 500)
    groups = np.zeros(500)
    noise = rng.normal(size=500)
    assert covariate_dependence(noise, x, groups)["p_value"] > 1e-3
    out = covariate_dependence(noise + 0.05 * (x - 5) ** 3, x, groups)
    assert out["p_value"] < 1e-20
    assert out["explained_fraction"] > 0.5
    assert sum(b["n"] for b in out["bins"]) == 500


def test_direction_from_time_order():
    # one pressure: up 0→3, down 3→0 (the turning point sampled twice); a second pressure:
    # up again. Sweep: +1 while the contraction rises, −1 while it falls.
    x = np.array([0, 1, 2, 3, 3, 2, 1, 0, 0, 1, 2], float)
    p = np.array([100.0] * 8 + [200.0] * 3)
    c = find_curves(pd.DataFrame({"pressure_kPa": p, "contraction_pct": x}))
    np.testing.assert_array_equal(c.direction, [1, 1, 1, 1, -1, -1, -1, -1, 1, 1, 1])
    np.testing.assert_array_equal(c.curve, [0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2])
    assert not c.direction_recorded.any()


# -- each library effect, hidden in the data ---------------------------------------------------

def test_hysteresis_found_in_sweeps_with_noisy_pressure_and_no_direction(tmp_path):
    """Every real bench logs a noisy pressure: ±1 kPa must not make each sample its own
    curve (which hid the loop: the derived direction was +1 everywhere)."""
    proto = pamid.SarosiProtocol(min_force_N=10.0, effects=(InjectedHysteresis(N_at_3_bar=9.0),))
    frame = pamid.simulate_sarosi_bench(jax.random.key(5), pamid.sarosi.table_3_1(), proto)
    rng = np.random.default_rng(0)
    frame = frame.drop(columns=["direction"])
    frame["pressure_kPa"] += rng.normal(0.0, 1.0, len(frame))
    path = tmp_path / "noisy.csv"
    frame.to_csv(path, index=False)
    d = diagnose(path)
    assert d.selected == ["hysteresis"]
    assert d.rmse_after < 0.3 * d.rmse_before


LIBRARY = [
    ("hysteresis", (InjectedHysteresis(N_at_3_bar=9.0),), {}),
    ("temperature", (InjectedTemperature(),), {}),
    ("drift", (InjectedDrift(N_per_hour=30.0),), {}),
    ("compliance", (InjectedCompliance(mm_per_N=0.002),), {}),
    ("viscous_damping", (InjectedViscousDamping(N_s_per_mm=2.0),),
     {"sweep_seconds_per_point": SPEEDS}),
]


@pytest.mark.parametrize(("name", "effects", "protocol"), LIBRARY, ids=[e[0] for e in LIBRARY])
def test_library_effect_detected_named_and_removed(tmp_path, name, effects, protocol):
    d = diagnose(_bench(tmp_path, effects, **protocol))
    assert d.selected == [name]
    assert d.rmse_before > 1.05 * d.rmse_after
    # after the fix the error falls to the noise level of the data
    assert d.rmse_after < 1.1 * NOISE_N
    assert d.unexplained == []
    top = d.candidates[0]
    assert {"effect", "covariate", "delta_bic", "cv_rmse", "significant"} <= set(top)


def test_hysteresis_constants_and_intervals(tmp_path):
    d = diagnose(_bench(tmp_path, (InjectedHysteresis(N_at_3_bar=9.0),)))
    h = d.constants[0]["effects"]["hysteresis"]
    # injected: 9 N at 3 bar, linear in p → h0 = 0 N, h1 = 3 N/bar
    assert h["h1"]["ci95"][0] < 3.0 < h["h1"]["ci95"][1]
    # h0 ≥ 0 is held so by the fit: on its bound 0, or an interval that covers 0
    assert h["h0"].get("held_at_bound") or h["h0"]["ci95"][0] < 0.0 < h["h0"]["ci95"][1]
    assert h["h0"]["value"] >= 0.0


def test_direction_derived_when_the_file_has_none(tmp_path):
    d = diagnose(_bench(tmp_path, (InjectedHysteresis(),), drop=("direction",)))
    assert d.selected == ["hysteresis"]


def test_compliance_in_mm_per_N(tmp_path):
    d = diagnose(_bench(tmp_path, (InjectedCompliance(mm_per_N=0.002),)))
    c = d.constants[0]["effects"]["compliance"]["c_mm_per_N"]
    assert c["ci95"][0] < 0.002 < c["ci95"][1]


def test_control_false_positive_rate(tmp_path):
    """No effect at all: nothing selected in at least 95 % of 40 data sets."""
    hits = []
    for seed in range(40):
        d = diagnose(_bench(tmp_path, (), seed=seed, name=f"c{seed}.csv"))
        hits.append(bool(d.selected))
    assert sum(hits) <= 2, f"false positives in {sum(hits)} of 40 data sets"


def test_effect_outside_the_library_traced_to_its_covariate(tmp_path):
    d = diagnose(_bench(tmp_path, (InjectedCovariate(column="humidity_pct"),)))
    assert d.selected == ["covariate:humidity_pct"]
    assert d.rmse_after < 1.1 * NOISE_N


def test_two_effects_at_once(tmp_path):
    d = diagnose(_bench(tmp_path, (InjectedHysteresis(), InjectedTemperature())))
    assert sorted(d.selected) == ["hysteresis", "temperature"]
    assert d.rmse_after < 1.1 * NOISE_N


@pytest.mark.parametrize("form", ["sqrt", "constant", "quadratic"])
def test_hysteresis_of_other_forms_still_detected(tmp_path, form):
    d = diagnose(_bench(tmp_path, (InjectedHysteresis(form=form),)))
    assert d.selected[0] == "hysteresis"
    assert d.rmse_after < 0.2 * d.rmse_before
    if form == "quadratic":
        # h ∝ p² is not h0 + h1·p: the misfit left over is reported, not hidden
        assert d.rmse_after > 1.2 * NOISE_N
        assert d.unexplained or len(d.selected) > 1


def test_cli_json_and_plots(tmp_path, capsys):
    from pamid._cli import main

    path = _bench(tmp_path, (InjectedHysteresis(),))
    out = tmp_path / "diag"
    assert main(["diagnose", str(path), "--json", "--out", str(out)]) == 0
    obj = json.loads(capsys.readouterr().out)
    for key in ("rmse_before", "rmse_after", "selected", "candidates", "unexplained"):
        assert key in obj
    assert obj["selected"] == ["hysteresis"]
    for c in obj["candidates"]:
        assert {"effect", "covariate", "delta_bic", "cv_rmse", "significant"} <= set(c)
    for name in ("diagnosis.json", "report.txt", "residuals_before_after.png",
                 "residual_time_order.png"):
        assert (out / name).stat().st_size > 0
    assert "Unexplained" in (out / "report.txt").read_text()
    assert pd.read_csv(path).shape[0] == 300  # input untouched


def test_cli_bad_input_names_file_column_row(tmp_path, capsys):
    from pamid._cli import main

    path = tmp_path / "bad.csv"
    path.write_text("pressure_kPa,contraction_pct,force_N\n100,1,50\n100,x,40\n")
    assert main(["diagnose", str(path)]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and "contraction_pct" in err and "row 2" in err


# -- decay files: the oscillator model ---------------------------------------------------------

J_DECAY = 0.05  # kg·m²
DECAY_NOISE = 0.0005  # rad, before the 12-bit encoder


def _decays(tmp_path, seed, coulomb_Nm=0.0, name="decay.csv", n_trials=3):
    osc = pamid.DampedOscillator.from_modal(0.05, 2.0, J_DECAY)
    proto = pamid.DecayProtocol(n_trials=n_trials, deflections_deg=(3.0, 5.0, 8.0),
                                noise_sd_rad=DECAY_NOISE)
    frame = pamid.simulate_decays(jax.random.key(seed), osc, proto, coulomb_Nm=coulomb_Nm)
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


def test_decay_coulomb_friction_found_and_sized(tmp_path):
    d = diagnose(_decays(tmp_path, 2, coulomb_Nm=0.005), inertia_kg_m2=J_DECAY)
    assert d.kind == "decay"
    assert d.selected == ["coulomb_friction"]
    # noise level: sensor noise and the encoder's rounding, √(σ² + q²/12)
    q = 2 * math.pi / 4096
    level = math.sqrt(DECAY_NOISE**2 + q**2 / 12)
    assert d.rmse_after < 1.05 * level < d.rmse_before
    for g in d.constants:
        lo, hi = g["effects"]["coulomb_friction"]["coulomb_Nm"]["ci95"]
        assert lo < 0.005 < hi


def test_decay_control_selects_nothing(tmp_path):
    hits = [bool(diagnose(_decays(tmp_path, s, name=f"d{s}.csv"),
                          inertia_kg_m2=J_DECAY).selected) for s in range(5)]
    assert not any(hits)


def test_decay_needs_inertia(tmp_path, capsys):
    from pamid._cli import main

    assert main(["diagnose", str(_decays(tmp_path, 1))]) == 2
    assert "--inertia" in capsys.readouterr().err


def test_decay_file_recognised_without_a_trial_column(tmp_path, capsys):
    from pamid._cli import main
    from pamid._diagnose._api import _is_decay_file

    frame = pd.read_csv(_decays(tmp_path, 1, n_trials=1))
    path = tmp_path / "one_decay.csv"
    frame.drop(columns=["trial"]).to_csv(path, index=False)
    assert _is_decay_file(path)
    assert not _is_decay_file(_bench(tmp_path, ()))
    assert main(["diagnose", str(path)]) == 2  # read as a decay file: it asks for J
    assert "--inertia" in capsys.readouterr().err


def test_too_few_rows_for_a_diagnosis_is_said_not_crashed(tmp_path):
    """One or two rows ended in an IndexError inside the lane fit (exit 3)."""
    path = tmp_path / "two.csv"
    path.write_text("pressure_kPa,force_N,contraction_pct\n100,5,1\n175,5,1\n")
    with pytest.raises(pamid.BenchDataError, match="needs at least 8 rows per muscle"):
        diagnose(path)


def test_a_baseline_the_data_cannot_determine_is_not_diagnosed(tmp_path):
    """One pressure level: the fit says NOT CONVERGED, and diagnose printed a residual RMSE
    of 4e-14 with nothing unexplained (exit 0). Now it says why and refuses (exit 1)."""
    path = tmp_path / "one_pressure.csv"
    rng = np.random.default_rng(0)
    k = np.arange(20.0)
    pd.DataFrame({"pressure_kPa": 300.0, "force_N": 800 - 30 * k + rng.normal(0, 1, 20),
                  "contraction_pct": k}).to_csv(path, index=False)
    with pytest.raises(pamid.UntrustedResultError, match="cannot determine all 6 constants"):
        diagnose(path)
    from pamid._cli import main

    assert main(["diagnose", str(path), "--json"]) == 1
