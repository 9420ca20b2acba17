"""Closing the loop in every protocol: each effect hidden, found, named and removed.

Two protocols as labs deliver them, neither with a direction column:

* ``sweeps``: Sárosi's sweeps, every cycle its own trial whose clock restarts, ±1 kPa of
  pressure noise, 0.01 % contraction noise, 2 N force noise (``virtual_lab_file``'s
  ``sweeps_noisy``, 1,500 rows);
* ``isometric``: AARL's valve stairs, trials restarting time, noise on every channel
  (±1 kPa, 1 N, 0.01 %) (``isometric_stairs``, 1,260 rows).

Each effect of the library is hidden in turn (hysteresis, transient, softening, sensor
offset, drift, temperature), plus a clean control and one pair of effects per protocol.
The diagnosis must select exactly the hidden effects, name them, find their constants,
and leave an RMSE within 1.1× that of the same file without the effect (the noise, with
the pressure noise carried through the force law). All files of a protocol have one shape
and one seed, so the compiled refits are shared; the clean diagnosis is module scoped.
"""

from __future__ import annotations

import math

import jax
import numpy as np
import pandas as pd
import pytest

from pamid import InjectedDrift, InjectedTemperature
from pamid._diagnose._api import diagnose
from pamid._diagnose._static import ROW_COUNTER_WHY, row_counters
from pamid._effects._definitions import DECAY_EFFECT_DEFINITIONS, STATIC_EFFECT_DEFINITIONS
from pamid._virtual._isometric import virtual_lab_file
from pamid.report import diagnosis_report

SEED = 5
PROTOCOLS = {
    # sweeps end where the true force falls to 10 N: no reading rounds to a censored 0 N
    "sweeps": ("sweeps_noisy", 1500, {"hysteresis_N_per_bar": 0.0, "min_force_N": 10.0}),
    "isometric": ("isometric_stairs", 1500,
                  {"transient_N_per_kPa": 0.0, "pressure_offset_kPa": 0.0,
                   "hysteresis_N_at_3_bar": 0.0, "min_force_N": None}),
}
#: (protocol, effect) → (options that hide it, {constant: (low, high)} it must be found at,
#: or {constant: truth} that its 95 % interval must cover). Products "a*b" are checked
#: where two constants trade off (the transient's g and τ).
HIDDEN = {
    ("sweeps", "hysteresis"): ({"hysteresis_N_per_bar": 3.0},  # h = 3 N/bar · p
                               {"h1": (2.8, 3.2), "h0": (-0.6, 0.6)}),
    ("sweeps", "transient"): ({"transient_N_per_pct": -8.0, "transient_tau_s": 2.0},
                              {"g": (-8.5, -7.5), "tau_s": (1.4, 2.9)}),
    ("sweeps", "softening"): ({"softening": 0.02, "softening_repeats": 1.0},
                              {"s": (0.018, 0.022)}),
    ("sweeps", "sensor_offset"): ({"pressure_offset_kPa": -30.0}, {"delta_kPa": (27.0, 33.0)}),
    ("sweeps", "drift"): ({"effects": (InjectedDrift(N_per_hour=30.0),)},
                          {"delta1": (25.0, 35.0)}),
    ("sweeps", "temperature"): ({"effects": (InjectedTemperature(),)},
                                {"tau0": (-0.7, -0.4), "tau1": (-0.33, -0.27)}),
    # h = 3 N/bar · p. In stairs whose every step is 2·5 % of the range, the jump at the
    # reversal and the slip element of 5 % are the same loop, which the fit may share
    # between them: the loop's half height (their sum) is what is fixed.
    ("isometric", "hysteresis"): ({"hysteresis_N_at_3_bar": 9.0},
                                  {"half_height_at_3bar": (8.1, 9.9)}),
    # g·τ, the relaxation's integral per kPa of step (0.05 N/kPa × 0.3 s), is what the
    # data fix where τ is about a sample interval
    ("isometric", "transient"): ({"transient_N_per_kPa": 0.05, "transient_tau_s": 0.3,
                                  "dwell_s": 1.0},
                                 {"g*tau_s": (0.0115, 0.0195)}),
    ("isometric", "softening"): ({"softening": 0.05, "softening_repeats": 1.0},
                                 {"s": (0.045, 0.055)}),
    ("isometric", "sensor_offset"): ({"pressure_offset_kPa": -30.0},
                                     {"delta_kPa": (27.0, 33.0)}),
    # five minutes of test: δ1 and δ2 trade off; the interval of δ1 must cover the truth
    ("isometric", "drift"): ({"effects": (InjectedDrift(N_per_hour=100.0),)},
                             {"delta1": 100.0}),
    ("isometric", "temperature"): ({"effects": (InjectedTemperature(),)},
                                   {"tau0": (-0.6, -0.4), "tau1": (-0.36, -0.24)}),
}
#: Two effects at once: drift with softening (both slow, one additive in time, one
#: multiplicative in the repeat), hysteresis with a transient (both follow the motion).
PAIRS = {
    "sweeps": ({"softening": 0.02, "softening_repeats": 1.0,
                "effects": (InjectedDrift(N_per_hour=30.0),)}, ["drift", "softening"]),
    "isometric": ({"hysteresis_N_at_3_bar": 9.0, "transient_N_per_kPa": 0.05,
                   "transient_tau_s": 0.3, "dwell_s": 1.0}, ["hysteresis", "transient"]),
}
RMSE_OVER_NOISE = 1.1


def _frame(protocol: str, **options) -> pd.DataFrame:
    kind, rows, clean = PROTOCOLS[protocol]
    return virtual_lab_file(jax.random.key(SEED), kind, rows, drop_columns=("direction",),
                            **(clean | options))


def _diagnose(tmp_path, protocol: str, name: str, **options):
    path = tmp_path / f"{protocol}_{name}.csv"
    _frame(protocol, **options).to_csv(path, index=False)
    return diagnose(path)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """The control of each protocol: the clean file's diagnosis (its RMSE is the noise)."""
    tmp = tmp_path_factory.mktemp("clean")
    return {p: _diagnose(tmp, p, "clean") for p in PROTOCOLS}


# -- the registry and the command's help --------------------------------------------------------


def test_every_effect_names_an_injector_in_each_protocol_where_it_is_physical():
    from test_diagnose_effects import _resolve

    for d in STATIC_EFFECT_DEFINITIONS:
        for name in d.injectors:
            _resolve(name)
    # the effects with a protocol field of their own name one in each protocol
    modules = {d.name: {n.split(".")[2] for n in d.injectors} for d in STATIC_EFFECT_DEFINITIONS}
    for name in ("transient", "softening", "sensor_offset", "hysteresis"):
        assert {"_sweeps", "_isometric"} <= modules[name], name
    drift = next(e for e in DECAY_EFFECT_DEFINITIONS if e.name == "drift")
    assert drift.injector is not None and "drift_rad_s" in drift.injector


def test_diagnose_help_lists_every_candidate_of_the_registry(capsys):
    from pamid._cli import main

    with pytest.raises(SystemExit) as e:
        main(["diagnose", "--help"])
    assert e.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for d in STATIC_EFFECT_DEFINITIONS:
        assert (f"{d.name}:<column>" if d.family is not None else d.name) in text
    for e in DECAY_EFFECT_DEFINITIONS:
        assert e.name in text
    assert "not offered as a covariate" in text


# -- controls -----------------------------------------------------------------------------------


@pytest.mark.parametrize("protocol", list(PROTOCOLS))
def test_clean_file_of_each_protocol_selects_nothing(clean, protocol):
    d = clean[protocol]
    assert d.selected == []
    assert d.unexplained == []


# -- each effect hidden in each protocol --------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(("protocol", "effect"), list(HIDDEN),
                         ids=[f"{p}-{e}" for p, e in HIDDEN])
def test_effect_found_named_and_removed(tmp_path, clean, protocol, effect):
    options, constants = HIDDEN[(protocol, effect)]
    d = _diagnose(tmp_path, protocol, effect, **options)
    assert d.selected == [effect]
    assert d.rmse_after < RMSE_OVER_NOISE * clean[protocol].rmse_before
    assert d.rmse_after < d.rmse_before
    found = d.constants[0]["effects"][effect]
    got = {k: v["value"] for k, v in found.items()}
    for pname, want in constants.items():
        if isinstance(want, float):
            lo, hi = found[pname]["ci95"]
            assert lo < want < hi, (pname, found[pname])
            continue
        value = math.prod(got[p] for p in pname.split("*"))
        assert want[0] < value < want[1], (pname, got)


@pytest.mark.slow
@pytest.mark.parametrize("protocol", list(PROTOCOLS))
def test_two_effects_together_are_both_found(tmp_path, clean, protocol):
    options, expected = PAIRS[protocol]
    d = _diagnose(tmp_path, protocol, "pair", **options)
    assert sorted(d.selected) == expected
    assert d.rmse_after < RMSE_OVER_NOISE * clean[protocol].rmse_before


def test_isometric_hysteresis_without_direction_column_follows_the_valve():
    """The derived direction turns where the pressure leaves the top of the stairs, not
    before it: it agrees with the valve's on every row of a clean stairs file."""
    from pamid._data._curves import find_curves

    frame = virtual_lab_file(jax.random.key(SEED), "isometric_stairs", 1500,
                             **PROTOCOLS["isometric"][2])
    c = find_curves(frame.drop(columns=["direction"]))
    np.testing.assert_array_equal(c.direction, frame["direction"].to_numpy(float))


# -- columns that only count rows ---------------------------------------------------------------


def test_row_counters_are_found_by_measurement_not_by_name():
    trials = [np.array([0, 0, 0, 1, 1, 1])]
    frame = pd.DataFrame({
        "src_row": [0, 10, 30, 3, 4, 90],  # rises within each trial, gaps allowed
        "humidity_pct": [40, 41, 40, 42, 43, 44],  # whole numbers, not monotonic
        "sample": [0.0, 0.5, 1.0, 0.0, 0.5, 1.0],  # rises, not whole numbers
        "tick": [5, 5, 6, 1, 2, 3],  # repeats a value: not a counter
    })
    got = row_counters([frame], trials, list(frame.columns))
    assert got == {"src_row": ROW_COUNTER_WHY}
    renamed = row_counters([frame.rename(columns={"src_row": "x"})], trials, ["x"])
    assert renamed == {"x": ROW_COUNTER_WHY}


def test_a_row_number_column_is_not_offered_as_a_covariate(tmp_path):
    """A source file's row number (every 10th row kept, some dropped) beside a real
    covariate that is also whole numbers: the first is left out and said so, the second
    kept."""
    frame = _frame("sweeps")
    rng = np.random.default_rng(0)
    frame["src_row"] = np.cumsum(rng.integers(1, 20, len(frame))) * 10
    frame["humidity_pct"] = rng.integers(30, 70, len(frame))
    path = tmp_path / "rows.csv"
    frame.to_csv(path, index=False)
    d = diagnose(path)
    effects = {r["effect"] for r in d.candidates}
    assert "covariate:src_row" not in effects
    assert "covariate:humidity_pct" in effects
    assert d.covariates_not_used == [{"column": "src_row", "why": ROW_COUNTER_WHY}]
    assert "src_row" not in d.residual_before["covariates"]
    assert d.to_dict()["covariates_not_used"][0]["column"] == "src_row"
    assert "Not used as a covariate: src_row" in diagnosis_report(d)
    assert d.selected == []


# -- free decays: the drift injector ------------------------------------------------------------


def test_decay_drift_injected_is_found(tmp_path):
    from pamid._sim._oscillator import DampedOscillator
    from pamid._virtual._decay import DecayProtocol, simulate_decays

    osc = DampedOscillator.from_modal(0.05, 2.0, 0.05)  # ζ, f_n (Hz), J (kg·m²)
    proto = DecayProtocol(n_trials=3, duration_s=3.0, sample_rate_Hz=200.0,
                          encoder_bits=None, noise_sd_rad=2e-4)
    frame = simulate_decays(jax.random.key(1), osc, proto, drift_rad_s=0.004)
    path = tmp_path / "decay.csv"
    frame.to_csv(path, index=False)
    d = diagnose(path, inertia_kg_m2=0.05)
    assert d.selected == ["drift"]
    for c in d.constants:
        lo, hi = c["effects"]["drift"]["drift_rad_s"]["ci95"]
        assert lo < 0.004 < hi
