"""Issue #30, item 3: the force law's shape before effects.

A virtual muscle whose force follows Tondu and Lopez's law with a pressure-dependent
correction (``tondu_lopez_kp``: α0 = 23°, a_k = 2, b_k = 1.5, Festo 10 mm radius), logged
as Sárosi's sweeps (five pressures, out and back, time and direction columns), 1.5 N of
noise: eq. 2.1's misfit on the noiseless forces is 1.32 N RMSE, ≈ 0.9σ. Before, the
diagnosis selected ``drift`` (the pressure levels follow each other in time) — on another
such file ``compliance`` — while ``pamid compare`` ranked ``tondu_lopez_kp`` first at the
noise level. Now it says the misfit is the force law's shape, names that law, selects no
library effect in its place, and agrees with ``compare``.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

import pamid
from pamid._diagnose._api import diagnose
from pamid._models._published import TonduLopezPressure
from pamid.report import diagnosis_report

SIGMA_N = 1.5


@pytest.fixture(scope="module")
def tondu_lopez_file(tmp_path_factory):
    proto = pamid.SarosiProtocol(noise_sd_N=0.0, force_resolution_N=0.0, min_force_N=-1e9,
                                 kappa_max_pct=20.0,
                                 pressures_kPa=(200.0, 300.0, 400.0, 500.0, 600.0))
    frame = pamid.simulate_sarosi_bench(jax.random.key(1), pamid.sarosi.table_3_1(), proto)
    law = TonduLopezPressure(alpha0_deg=23.0, a_k=2.0, b_k=1.5)
    force = np.asarray(law(frame["pressure_kPa"].to_numpy(),
                           frame["contraction_pct"].to_numpy() / 100.0))
    frame["force_N"] = np.round(force + np.random.default_rng(1).normal(0.0, SIGMA_N,
                                                                        len(force)), 2)
    path = tmp_path_factory.mktemp("shape") / "tondu_lopez.csv"
    frame[force > 10.0].to_csv(path, index=False)
    return path


def test_another_force_law_is_named_and_no_effect_stands_in_for_it(tondu_lopez_file):
    d = diagnose(tondu_lopez_file)
    shape = d.force_law_shape
    assert shape is not None and shape["law"] == "tondu_lopez_kp"
    assert shape["model"] == "sarosi" and d.model_requested == "sarosi"
    assert d.model == "tondu_lopez_kp"  # the effects are diagnosed on top of it
    assert d.selected == []  # no library effect in the law's place
    assert shape["cv_rmse_law_N"] < 1.1 * SIGMA_N < shape["cv_rmse_model_N"]
    assert d.rmse_after < 1.1 * SIGMA_N
    out = d.to_dict()
    assert out["force_law_shape"]["law"] == "tondu_lopez_kp"
    assert out["model_requested"] == "sarosi"
    assert "the force law's shape" in diagnosis_report(d)
    # pamid compare on the same file ranks the same law first
    comparison = pamid.compare_models(pamid.load_bench(tondu_lopez_file))
    assert comparison.best(0) == "tondu_lopez_kp"
    assert shape["laws"][0]["model"] == "tondu_lopez_kp"
