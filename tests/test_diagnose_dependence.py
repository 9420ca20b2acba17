"""Issue #30 item 4: selection calibrated on residuals that are not white.

A real bench's residual wanders slowly (lag-1 autocorrelation 0.985 on AARL's isometric
tests): every sample counted as independent, the BIC finds anything significant. Here an
AR(1) force error (ρ = 0.98 per sample, 3 N, from a seeded NumPy Generator) is added to a
virtual isometric file (3,000 rows, 1 N of white force noise and 1 kPa of pressure noise
besides): with no hidden effect nothing may be selected, and with one it is found and
nothing is added and then dropped. Before the selection used the effective sample size
and one judge for both passes, the same files gave ``transient`` added and dropped again
(``dropped == ["transient"]``), beside ``sensor_offset`` in the second file.
"""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from pamid._diagnose._api import diagnose
from pamid._diagnose._residual import autocorrelation_time, effective_sample_size
from pamid._diagnose._select import SetFit, delta_bic, forward_select, judge
from pamid._virtual._isometric import virtual_lab_file
from pamid.report import diagnosis_report

ROWS = 3000
RHO = 0.98
SIGMA_N = 3.0  # the AR(1) error's standard deviation
CLEAN = {"transient_N_per_kPa": 0.0, "pressure_offset_kPa": 0.0,
         "hysteresis_N_at_3_bar": 0.0, "min_force_N": None}


def _ar1(rng: np.random.Generator, n: int, rho: float, sigma: float) -> np.ndarray:
    e = rng.normal(size=n) * sigma * math.sqrt(1.0 - rho**2)
    x = np.empty(n)
    x[0] = rng.normal() * sigma
    for i in range(1, n):
        x[i] = rho * x[i - 1] + e[i]
    return x


def _iso(tmp_path, name, sigma=SIGMA_N, **options):
    frame = virtual_lab_file(jax.random.key(3), "isometric_stairs", ROWS, **(CLEAN | options))
    if sigma:
        frame["force_N"] += _ar1(np.random.default_rng(20261127), len(frame), RHO, sigma)
    path = tmp_path / f"{name}.csv"
    frame.to_csv(path, index=False)
    return path


# -- the effective sample size against known answers -------------------------------------------


def test_white_residual_keeps_every_sample():
    rng = np.random.default_rng(1)
    for n in (200, 3000, 50_000):
        tau, rho1 = autocorrelation_time(rng.normal(size=n))
        assert tau == 1.0 and abs(rho1) < 3.0 / math.sqrt(n)
        assert effective_sample_size(n, tau) == n
    assert effective_sample_size(1000, math.nan) == 1000  # no time order: n


@pytest.mark.parametrize("rho", [0.5, 0.9, 0.98])
def test_ar1_autocorrelation_time_is_its_closed_form(rho):
    """τ = (1 + ρ)/(1 − ρ) for AR(1) (Bayley and Hammersley, 1946)."""
    x = _ar1(np.random.default_rng(7), 200_000, rho, 1.0)
    tau, rho1 = autocorrelation_time(x)
    assert abs(rho1 - rho) < 0.01
    assert tau == pytest.approx((1 + rho) / (1 - rho), rel=0.15)
    assert effective_sample_size(len(x), tau) == pytest.approx(len(x) / tau)


def test_white_plus_slow_wander_is_not_taken_for_ar1_of_its_lag1():
    """Mostly white noise plus a slow AR(1): ρ_1 is small, τ long (the sum, not ρ_1)."""
    rng = np.random.default_rng(11)
    x = rng.normal(size=100_000) * 2.0 + _ar1(rng, 100_000, 0.98, 1.0)
    tau, rho1 = autocorrelation_time(x)
    expect = 1.0 + 2.0 * (1.0 / 5.0) * 0.98 / (1.0 - 0.98)  # 1 + 2·Σρ_k, ρ_k = 0.2·0.98^k
    assert (1 + rho1) / (1 - rho1) < 2.0 < 0.7 * expect < tau < 1.3 * expect


def _fit(sse, n, k, tau=None, cv=(1.0, 1.0)):
    return SetFit(effects=(), sse=np.array(sse, float), n=np.array(n), k=np.array(k),
                  cv_sse=cv[0], cv_n=1, converged=np.ones(len(n), bool),
                  tau=None if tau is None else np.array(tau, float))


def test_delta_bic_is_the_plain_bic_for_white_residuals_and_shrinks_with_tau():
    small, large = _fit([1000.0, 900.0], [1000, 800], [6, 6]), _fit([950.0, 880.0],
                                                                    [1000, 800], [7, 7])
    assert delta_bic(small, large) == pytest.approx(large.bic - small.bic, rel=1e-12)
    large.tau = np.array([1.0, 1.0])
    assert delta_bic(small, large) == pytest.approx(large.bic - small.bic, rel=1e-12)
    large.tau = np.array([100.0, 80.0])
    n_eff = np.array([10.0, 10.0])
    want = float(np.sum(n_eff * np.log([0.95, 880 / 900]) + np.log(n_eff)))
    assert delta_bic(small, large) == pytest.approx(want, rel=1e-12)


def test_the_judge_refuses_an_effect_below_the_effect_size_floor():
    """In-sample ΔBIC far past the threshold, held-out error 1 % lower: not an effect."""
    small = _fit([1000.0], [10_000], [6], cv=(1.0, 1.0))
    large = _fit([900.0], [10_000], [7], cv=(0.99, 1.0))
    v = judge(small, large)
    assert v["delta_bic"] < -100 and not v["supported"]
    assert v["decided_by"] == "held_out_share"
    large.cv_sse = 0.9
    assert judge(small, large)["supported"]


# -- forward and backward consistent: a fake family of known SSEs ------------------------------


def _family(sse: dict[frozenset, float]):
    """A fake family: each set of effects has a known SSE on 1,000 white rows (and the same
    held-out error), each effect two constants."""
    def evaluate(sets):
        return [SetFit(effects=s, sse=np.array([sse[frozenset(s)]]), n=np.array([1000]),
                       k=np.array([6 + 2 * len(s)]), cv_sse=sse[frozenset(s)], cv_n=1000,
                       converged=np.array([True])) for s in sets]
    return evaluate


def test_an_effect_added_after_a_generic_term_is_not_dropped_without_it():
    """The AARL file under Cullinan's model (experiments/README §10): a generic contraction
    term first, hysteresis on top of it, then a pressure term; the backward pass judged the
    hysteresis among the library effects alone — against the baseline, where it had never been
    supported — and dropped it. Judged in the context it was added in, it stays."""
    L, G, H = "hysteresis", "covariate:x", "covariate:y"
    f = frozenset
    sse = {f(): 1000.0, f({L}): 995.0, f({G}): 800.0, f({H}): 900.0, f({G, L}): 700.0,
           f({G, H}): 750.0, f({L, H}): 650.0, f({G, L, H}): 600.0}
    out = forward_select([L, G, H], _family(sse), {L: "direction", G: "x", H: "y"})
    assert [s["added"] for s in out["steps"]][:3] == [G, L, H]
    assert out["dropped"] == [] and out["selected"] == [G, L, H]


def test_a_library_effect_is_not_dropped_for_a_generic_term_added_after_it():
    """The rule the consistency keeps: a library effect added first and a generic term that
    holds it in another form (without it, the generic term alone nearly as good): the
    library effect stays, and the generic term with it."""
    L, G = "sensor_offset", "covariate:x"
    f = frozenset
    sse = {f(): 1000.0, f({L}): 900.0, f({G}): 810.0, f({L, G}): 800.0}
    # given the generic term the offset would not be supported: ΔBIC = +1.4
    assert not judge(*_family(sse)([(G,), (G, L)]))["supported"]
    out = forward_select([L, G], _family(sse), {L: "pressure", G: "x"})
    assert out["selected"] == [L, G] and out["dropped"] == []


# -- whole diagnoses ---------------------------------------------------------------------------


def test_autocorrelated_error_alone_selects_nothing(tmp_path):
    d = diagnose(_iso(tmp_path, "ar"))
    assert d.selected == [] and d.dropped == []
    sel = d.to_dict()["selection"]
    # the dependence was seen: far fewer effective samples than rows
    assert sel["n_eff_baseline"][0] < 0.2 * sel["n"][0]
    assert all(c["decided_by"] and c["n_eff"] < 0.2 * sel["n"][0] for c in d.candidates)
    # the report says on how many effective samples, and what refused each candidate
    text = diagnosis_report(d)
    assert f"n_eff = {sum(sel['n_eff_baseline']):.0f} of {sum(sel['n']):.0f} rows" in text
    assert "significant = ΔBIC < −10 on the effective sample size" in text
    refused = {"bic": "no (ΔBIC)", "held_out_share": "no (held-out gain too small)",
               "held_out_test": "no (held-out units not better)"}
    for c in d.candidates:
        if c["decided_by"] in refused and not c.get("unphysical"):
            assert any(line.lstrip().startswith(c["effect"] + " ")
                       and line.rstrip().endswith(refused[c["decided_by"]])
                       for line in text.splitlines()), c["effect"]


def test_a_real_effect_under_an_autocorrelated_error_is_found_and_nothing_dropped(tmp_path):
    d = diagnose(_iso(tmp_path, "ar_offset", pressure_offset_kPa=-30.0))
    assert d.selected == ["sensor_offset"]
    assert d.dropped == []
    delta = d.constants[0]["effects"]["sensor_offset"]["delta_kPa"]["value"]
    assert 20.0 < delta < 40.0


def test_white_noise_file_is_judged_with_every_sample(tmp_path):
    d = diagnose(_iso(tmp_path, "white", sigma=0.0))
    assert d.selected == [] and d.dropped == []
    sel = d.to_dict()["selection"]
    assert sel["n_eff_baseline"] == sel["n"]
