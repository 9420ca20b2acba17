"""Issue #30, item 2: the temperature as a share of the force per kelvin, and the other form
tried where the selected one leaves its covariate behind.

A rubber's modulus changes with temperature — for an ideal network G = N·k·T (entropy
elasticity; Treloar, The Physics of Rubber Elasticity, 3rd ed. 1975, ch. 2 and 4), filled
rubbers soften as they warm instead — so the force of a muscle at a given pressure and
contraction changes by a share of itself per kelvin:

    F = F_static·(1 + (α0 + α1·p)·(T − T_ref))

(:class:`pamid.InjectedRelativeTemperature`; α0 in 1/K, α1 in 1/(bar·K), p in bar), not by
newtons per kelvin as :class:`pamid.InjectedTemperature` adds them. Files as labs deliver
them (``virtual_lab_file``, as in ``test_diagnose_protocols``: sweeps and isometric stairs,
noise on every channel, no direction column, trials restarting time), each sweep or trial at
its own temperature in 20–45 °C, logged in ``temperature_C``. The diagnosis must name the
temperature (``temperature_relative``, the relative form), select no other library effect,
leave an RMSE within 1.1× the noise (the baseline's RMSE on the same file without the
effect), and find the constants; the additive form must still be named ``temperature``.
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import jax
import numpy as np
import pytest

import pamid
from pamid._data._bench import load_bench
from pamid._diagnose._api import diagnose
from pamid._diagnose._forms import form_groups, other_forms
from pamid._diagnose._select import SetFit, forward_select
from pamid._diagnose._static import StaticProblem
from pamid._effects._definitions import STATIC_EFFECT_DEFINITIONS
from pamid._effects._inject import apply_effects
from pamid._effects._temperature import (
    InjectedRelativeTemperature,
    InjectedTemperature,
    _relative_temperature_check,
)
from pamid._fit._spec import get_model
from pamid._virtual._isometric import virtual_lab_file
from pamid.report import diagnosis_report

SEED = 5
PROTOCOLS = {  # as test_diagnose_protocols has them: the same shapes, the same compiled lanes
    "sweeps": ("sweeps_noisy", 1500, {"hysteresis_N_per_bar": 0.0, "min_force_N": 10.0}),
    "isometric": ("isometric_stairs", 1500,
                  {"transient_N_per_kPa": 0.0, "pressure_offset_kPa": 0.0,
                   "hysteresis_N_at_3_bar": 0.0, "min_force_N": None}),
}
RMSE_OVER_NOISE = 1.1
#: −0.2 % of the force per kelvin (a rubber softening as it warms), the law holding at 25 °C
SOFTENING = InjectedRelativeTemperature(per_K=-0.002)
#: −0.05 % per bar and kelvin, the law holding at 20 °C: at the files' mean temperature,
#: about 33 °C, the force is F·(1 − 0.0065·p), a share that grows with the pressure
PER_BAR = InjectedRelativeTemperature(per_K=0.0, per_bar_K=-0.0005, reference_C=20.0)
#: (protocol, name) → (injector, {constant: (low, high)} it must be found in). α relative to
#: the force at T0 (the temperature where the fitted law holds): α/(1 + α·(T0 − T_ref)).
HIDDEN = {
    ("sweeps", "softening"): (SOFTENING, {"alpha0": (-0.0025, -0.0017),
                                          "alpha1": (-0.0002, 0.0002)}),
    ("sweeps", "per_bar"): (PER_BAR, {"alpha1": (-0.00055, -0.00045),
                                      "T0_C": (16.0, 24.0)}),
    ("isometric", "softening"): (SOFTENING, {"alpha0": (-0.0023, -0.0017),
                                             "alpha1": (-0.0001, 0.0001)}),
    ("isometric", "per_bar"): (PER_BAR, {"alpha1": (-0.0006, -0.00045),
                                         "T0_C": (16.0, 26.0)}),
}


def _write(tmp_path, protocol: str, name: str, effects=()) -> str:
    kind, rows, clean = PROTOCOLS[protocol]
    options = dict(clean)
    if effects:
        options["effects"] = tuple(effects)
    frame = virtual_lab_file(jax.random.key(SEED), kind, rows, drop_columns=("direction",),
                             **options)
    path = tmp_path / f"{protocol}_{name}.csv"
    frame.to_csv(path, index=False)
    return path


def _problem(path):
    bench = load_bench(path)
    return StaticProblem(bench, get_model("sarosi", bench.frame))


@pytest.fixture(scope="module")
def noise(tmp_path_factory):
    """Per protocol, the noise: the baseline's RMSE on the same file without the effect
    (the pressure's noise carried through the force law included)."""
    tmp = tmp_path_factory.mktemp("clean")
    out = {}
    for protocol in PROTOCOLS:
        fit = _problem(_write(tmp, protocol, "clean")).baseline
        out[protocol] = math.sqrt(float(np.sum(fit.sse)) / float(np.sum(fit.n)))
    return out


# -- the injector and the physical bound, against known answers -----------------------------


def test_relative_injector_scales_the_force_it_is_given():
    """ΔF = F·(α0 + α1·p)·(T − T_ref) exactly, with the temperature logged per sweep."""
    shape = (1, 1, 2, 1, 4)  # cycle, muscle, pressure, direction, point
    force = np.arange(8.0).reshape(shape) * 50.0
    ctx = {"p_bar": np.broadcast_to(np.array([2.0, 5.0])[None, None, :, None, None], shape),
           "sweep": np.broadcast_to(np.arange(2)[None, None, :, None, None], shape),
           "point_fraction": np.linspace(0.0, 1.0, 4), "rng": np.random.default_rng(0),
           "force_N": force}
    inj = InjectedRelativeTemperature(per_K=-0.003, per_bar_K=0.001, reference_C=25.0)
    added, columns = apply_effects((inj,), ctx, shape)
    t = columns["temperature_C"]
    assert np.all((t >= 20.0) & (t <= 46.0))
    assert len(np.unique(np.round(t[..., 0], 6))) == 2  # one level per sweep
    np.testing.assert_allclose(added, force * (-0.003 + 0.001 * ctx["p_bar"]) * (t - 25.0))


def test_the_two_forms_are_one_effect_and_a_vanishing_force_is_not_physical():
    forms = {d.name: d.form_of for d in STATIC_EFFECT_DEFINITIONS}
    assert forms["temperature_relative"] == "temperature"
    assert forms["temperature"] is None
    relative = next(d for d in STATIC_EFFECT_DEFINITIONS if d.name == "temperature_relative")
    assert [c.unit for c in relative.constants] == ["1/(bar·K)", "1/K"]
    assert relative.grid.lower == -273.15  # T0 above absolute zero
    file = SimpleNamespace(ranges={"pressure_kPa": (0.0, 600.0), "temperature_C": (20.0, 45.0)},
                           temperature_mean_C=32.5)
    # −0.2 %/K: the force falls by 5 % over 25 K
    assert _relative_temperature_check({"alpha0": -0.002, "alpha1": 0.0, "T0_C": 20.0},
                                       file, None) is None
    # −1 %/(bar·K) at 6 bar over 25 K would take the force below zero
    msg = _relative_temperature_check({"alpha0": 0.0, "alpha1": -0.01, "T0_C": 20.0},
                                      file, None)
    assert "not physical" in msg and "T = 45 °C" in msg


def test_forward_selection_never_takes_two_forms_of_one_effect():
    """A fake family where each effect lowers the SSE on its own: without ``forms`` both
    forms of ``a`` are added; with them, one."""
    gain = {"a": 400.0, "a_rel": 300.0, "b": 150.0}

    def evaluate(sets):
        return [SetFit(effects=s, sse=np.array([1000.0 - sum(gain[e] for e in s)]),
                       n=np.array([1000]), k=np.array([6 + 2 * len(s)]),
                       cv_sse=1000.0 - sum(gain[e] for e in s), cv_n=1000,
                       converged=np.array([True])) for s in sets]

    names = list(gain)
    covs = {n: n for n in names}
    assert sorted(forward_select(names, evaluate, covs)["selected"]) == ["a", "a_rel", "b"]
    out = forward_select(names, evaluate, covs, forms={"a_rel": "a"})
    assert sorted(out["selected"]) == ["a", "b"]


def test_the_members_of_a_family_are_not_forms_of_each_other():
    """``covariate:<col>`` of two columns are two effects (a pooled AARL fit selects the
    pressure's and the pressure rate's together): only ``form_of`` joins effects."""
    defs = {d.name: d for d in STATIC_EFFECT_DEFINITIONS}
    effects = [SimpleNamespace(name=n, definition=defs[d]) for n, d in (
        ("temperature", "temperature"), ("temperature_relative", "temperature_relative"),
        ("covariate:pressure_kPa", "covariate"),
        ("covariate:pressure_rate_kPa_s", "covariate"), ("hysteresis", "hysteresis"))]
    groups = form_groups(SimpleNamespace(effects=effects))
    assert groups["temperature_relative"] == groups["temperature"] == "temperature"
    assert groups["covariate:pressure_kPa"] != groups["covariate:pressure_rate_kPa_s"]
    assert groups["hysteresis"] == "hysteresis"


# -- force-scaling temperature hidden in each protocol ---------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(("protocol", "name"), list(HIDDEN),
                         ids=[f"{p}-{n}" for p, n in HIDDEN])
def test_force_scaling_temperature_named_and_removed(tmp_path, noise, protocol, name):
    injector, constants = HIDDEN[(protocol, name)]
    d = diagnose(_write(tmp_path, protocol, name, (injector,)))
    assert d.selected == ["temperature_relative"]  # no softening, compliance, offset …
    assert d.rmse_after <= RMSE_OVER_NOISE * noise[protocol], (d.rmse_after, noise[protocol])
    assert d.rmse_before > 2.0 * noise[protocol]  # the effect was there to be found
    assert "temperature_C" not in d.unexplained and d.unexplained == []
    assert d.forms == []  # the right form was chosen: nothing left to try
    found = d.constants[0]["effects"]["temperature_relative"]
    got = {k: v["value"] for k, v in found.items()}
    for pname, (lo, hi) in constants.items():
        assert lo < got[pname] < hi, (pname, got)
    assert found["T0_C"]["chosen_over"] == "grid"


@pytest.mark.slow
def test_additive_temperature_still_named_temperature(tmp_path, noise):
    d = diagnose(_write(tmp_path, "sweeps", "additive", (InjectedTemperature(),)))
    assert d.selected == ["temperature"]
    assert d.rmse_after <= RMSE_OVER_NOISE * noise["sweeps"]
    got = {k: v["value"] for k, v in d.constants[0]["effects"]["temperature"].items()}
    assert -0.7 < got["tau0"] < -0.4 and -0.33 < got["tau1"] < -0.27
    rows = {r["effect"]: r for r in d.candidates}
    assert rows["temperature_relative"]["delta_bic"] > rows["temperature"]["delta_bic"] + 100
    assert d.forms == []


# -- the other form tried where the selected one leaves its covariate -------------------------


def _select_without(problem, form):
    forms = form_groups(problem)

    def select(candidates):
        return forward_select(candidates, problem.evaluate, problem.covariate_of,
                              unphysical=problem.unphysical, refresh=problem.refresh_grids,
                              forms=forms)

    first = select([c for c in problem.candidate_names if c != form])
    return first, select


@pytest.mark.slow
def test_additive_form_leaving_temperature_is_replaced_by_the_relative_one(tmp_path, noise):
    """Offered only the additive form, the selection takes it and a compliance beside it,
    leaving the temperature in proportion to the force; tried in its place, the relative
    form wins and the selection, run again, keeps it alone."""
    problem = _problem(_write(tmp_path, "sweeps", "per_bar", (PER_BAR,)))
    first, select = _select_without(problem, "temperature_relative")
    assert "temperature" in first["selected"]
    result, records = other_forms(problem, first, select)
    assert result["selected"] == ["temperature_relative"]
    assert result["final"].rmse <= RMSE_OVER_NOISE * noise["sweeps"]
    (r,) = records
    assert r["effect"] == "temperature" and r["tried"] == "temperature_relative"
    assert r["kept"] == "temperature_relative"
    assert r["left"]["p_value"] < 1e-3 and r["left"]["explained_fraction"] >= 0.02
    assert r["left_by_tried"]["p_value"] > 1e-3
    assert r["delta_bic"] < -10 and r["cv_rmse_N"][1] < r["cv_rmse_N"][0]
    assert "kept temperature_relative" in r["why"]

    # as the diagnosis reports it: the JSON and the text say which form was kept and why
    d = diagnose(problem.bench.path)
    d.forms = records
    obj = json.loads(json.dumps(d.to_dict()))
    assert obj["forms"][0]["kept"] == "temperature_relative"
    assert "form: temperature left temperature_C in the residual" in diagnosis_report(d)


@pytest.mark.slow
def test_relative_form_with_a_generic_beside_it_is_replaced_by_the_additive_one(tmp_path):
    """The reverse: additive temperature, only the relative form offered; a smooth function
    of the temperature is selected beside it (what the form left): the additive form, tried
    in its place, is kept."""
    problem = _problem(_write(tmp_path, "sweeps", "additive", (InjectedTemperature(),)))
    first, select = _select_without(problem, "temperature")
    assert "temperature_relative" in first["selected"]
    result, records = other_forms(problem, first, select)
    assert result["selected"] == ["temperature"]
    (r,) = records
    assert r["kept"] == "temperature"
    if "covariate:temperature_C" in first["selected"]:
        assert r["left"]["generic_selected"] == "covariate:temperature_C"


def test_public_name():
    assert pamid.InjectedRelativeTemperature is InjectedRelativeTemperature
