"""Issue #16: the effects as objects, the effects real benches show, and physical bounds.

Isometric files as AARL delivers them (valve steps, trials whose clock restarts, ±1 kPa of
pressure noise, 1 N of force noise) with one hidden effect each: the diagnosis must name
it, and leave an error at the level of the same file without the effect (the noise, with
the pressure noise carried through the force law). Small files (1,260 rows), all of one
shape, so that the compiled refits are shared.
"""

from __future__ import annotations

import importlib
import math
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamid
from pamid._decays._coulomb import DECAY_EFFECTS as DECAY_FIT_NAMES
from pamid._diagnose._api import diagnose
from pamid._effects._definitions import DECAY_EFFECT_DEFINITIONS, STATIC_EFFECT_DEFINITIONS
from pamid._effects._drift import InjectedDrift
from pamid._effects._steps import moving_steps, time_since_step
from pamid._effects._temperature import InjectedTemperature
from pamid._effects._transient import _relaxation
from pamid._virtual._isometric import virtual_lab_file
from pamid.report import diagnosis_report

ROWS = 1260  # 105 samples a trial: not in step with the valve (a real logger is not)
CLEAN = {"transient_N_per_kPa": 0.0, "pressure_offset_kPa": 0.0,
         "hysteresis_N_at_3_bar": 0.0, "min_force_N": None}


def _iso(tmp_path, name, drop_direction=True, seed=3, **options):
    frame = virtual_lab_file(jax.random.key(seed), "isometric_stairs", ROWS,
                             **(CLEAN | options))
    if drop_direction:
        frame = frame.drop(columns=["direction"])
    path = tmp_path / f"{name}.csv"
    frame.to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return diagnose(_iso(tmp_path_factory.mktemp("clean"), "clean"))


# -- the registry ------------------------------------------------------------------------------


def _resolve(dotted: str):
    parts = dotted.split(" ")[0].split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(dotted)


def _Named(name):
    return SimpleNamespace(name=name, units=("N/kPa",))


def test_every_effect_names_an_injector_that_exists_and_physical_bounds():
    names = [d.name for d in STATIC_EFFECT_DEFINITIONS]
    assert len(names) == len(set(names))
    assert {"transient", "softening", "sensor_offset", "compliance", "hysteresis"} <= set(names)
    for d in STATIC_EFFECT_DEFINITIONS:
        assert d.injectors
        for injector in d.injectors:
            _resolve(injector)  # raises if the virtual bench has no such injector
        for c in d.constants:
            assert c.lower < c.upper
    bound = {d.name: {c.name: (c.lower, c.upper) for c in d.constants}
             for d in STATIC_EFFECT_DEFINITIONS}
    assert bound["compliance"]["c"] == (0.0, math.inf)
    assert bound["viscous_damping"]["g"][0] == 0.0
    assert bound["softening"]["s"] == (0.0, 1.0)
    transient = next(d for d in STATIC_EFFECT_DEFINITIONS if d.name == "transient")
    assert transient.grid.lower == 0.0  # τ > 0
    # g may be negative (a pneumatic lag), but never a lag of more than the whole step
    muscle = SimpleNamespace(max_dF_dp_N_per_kPa=2.0, step_slope=None)
    assert transient.violation({"g": -0.5}, _Named("transient"), None, muscle) is None
    assert "not physical" in transient.violation({"g": -2.5}, _Named("transient"), None,
                                                 muscle)
    # where the steps are of another input (the rod's position), the slope is the force's
    # along that input, of either sign
    rod = SimpleNamespace(max_dF_dp_N_per_kPa=2.0, step_slope=-4.0)
    assert transient.violation({"g": 3.0}, _Named("transient"), None, rod) is None
    assert "not physical" in transient.violation({"g": 4.5}, _Named("transient"), None, rod)
    # the decay diagnosis reads the same registry
    assert DECAY_FIT_NAMES == {e.name: e.fit_name for e in DECAY_EFFECT_DEFINITIONS}
    friction = next(e for e in DECAY_EFFECT_DEFINITIONS if e.name == "coulomb_friction")
    assert friction.violation(-0.01) is not None and friction.violation(0.01) is None


def test_steps_time_since_step_and_relaxation_known_answers():
    # one trial: held at 0, a step of +60 kPa at sample 3, noise of 0.5 kPa elsewhere
    p = np.array([0.0, 0.5, -0.5, 60.0, 60.5, 59.5, 60.0, 0.0])
    t = np.arange(8) * 0.5
    trial = np.zeros(8, int)
    moving = np.ones(8, np.int8)
    steps = moving_steps(p, moving, trial)
    np.testing.assert_allclose(steps, [0, 0, 0, 60.5, 0, 0, 0, -60.0])
    np.testing.assert_allclose(time_since_step(steps, t, trial),
                               [0, 0.5, 1.0, 0, 0.5, 1.0, 1.5, 0])
    tau = 0.5
    y = _relaxation(steps, t, trial, tau)
    # the step is placed halfway between samples 2 and 3: 0.25 s before sample 3
    expect3 = 60.5 * math.exp(-0.25 / tau)
    np.testing.assert_allclose(y[3:7], expect3 * np.exp(-np.arange(4) * 0.5 / tau))
    np.testing.assert_allclose(y[7], y[6] * math.exp(-1.0) - 60.0 * math.exp(-0.5))
    # a new trial starts from rest; a sweep (the contraction moves) has no pressure steps
    assert not moving_steps(p, np.zeros(8, np.int8), trial).any()


def test_compliance_force_and_its_derivatives_are_those_of_the_fixed_point(theta31):
    """F = F_model(p, κ + c·F) (Sárosi eq. 2.1 with a rig in series): the diagnosis' force
    solves the fixed point, and its derivatives in (a1…a6, c) are the implicit function's,
    dF/dq = (∂F_model/∂q) / (1 − c·∂F_model/∂κ), against a plain bisection here."""
    from pamid._effects._definitions import transforms
    from pamid._effects._model import with_effects
    from pamid._fit._spec import get_model

    spec = get_model("sarosi")
    theta = np.asarray(theta31, float)
    p_bar = np.array([1.0, 2.5, 4.0, 6.0])
    kappa = np.array([2.0, 8.0, 15.0, 20.0])
    x = spec.to_x(p_bar * 100.0, kappa)
    c = 0.004  # %/N: 600 N shift the contraction by 2.4 %
    slot = [d.name for d in transforms()].index("compliance")

    def force(q):  # the refit model with no linear slot: (a1…a6, the transforms' constants)
        tv = jax.numpy.zeros(len(transforms())).at[slot].set(q[6])
        return with_effects(spec, True, 0).predict(jax.numpy.concatenate([q[:6], tv]),
                                                   (*x, np.zeros((len(p_bar), 0))))

    def fixed_point(q):  # bisection on F − F_model(p, κ + c·F), one sample at a time
        out = []
        for pi, ki in zip(p_bar, kappa, strict=True):
            lo, hi = -2000.0, 5000.0
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                f_model = float(spec.predict(q[:6], spec.to_x(np.array([pi * 100.0]),
                                                               np.array([ki + q[6] * mid])))[0])
                lo, hi = (mid, hi) if mid - f_model < 0 else (lo, mid)
            out.append(0.5 * (lo + hi))
        return np.array(out)

    q = np.concatenate([theta, [c]])
    np.testing.assert_allclose(force(jax.numpy.asarray(q)), fixed_point(q), rtol=1e-10)
    jac = np.asarray(jax.jacfwd(force)(jax.numpy.asarray(q)))
    for j in range(7):
        h = 1e-6 * max(abs(q[j]), 1e-3)
        up, down = q.copy(), q.copy()
        up[j] += h
        down[j] -= h
        np.testing.assert_allclose(jac[:, j], (fixed_point(up) - fixed_point(down)) / (2 * h),
                                   rtol=1e-5, atol=1e-6)


def test_a_model_with_effects_is_a_model_the_one_entry_fits(theta31):
    """The diagnosis's refit model is the base model wrapped in each effect, each a model
    (``with_effects``: the linear slots around the sensor offset around the compliance
    around Sárosi eq. 2.1): a ModelSpec with names, units and the base's and effects'
    bounds, whose structured Jacobian is that of its prediction, and which
    ``pamid.engine.solve`` fits like any model: noise-free Sárosi data with a rig in series
    (c), a pressure-sensor offset (δ) and a linear drift (φ) give back every constant from
    a start 2 % off."""

    from pamid._effects._compliance import Compliance
    from pamid._effects._model import with_effects
    from pamid._effects._sensor_offset import SensorOffset
    from pamid._effects._wrappers import LinearTerms
    from pamid._fit._spec import SAROSI, ModelSpec

    model = with_effects(SAROSI, True, 1)
    assert isinstance(model, ModelSpec) and isinstance(model, LinearTerms)
    assert isinstance(model.base, SensorOffset) and isinstance(model.base.base, Compliance)
    assert model.base.base.base is SAROSI and model.base.base.implicit
    assert not with_effects(SAROSI, False, 1).base.base.implicit
    assert model is with_effects(SAROSI, True, 1)  # one per arguments: programs reused
    assert model.param_names == (*SAROSI.param_names, "c", "delta_kPa", "phi0")
    assert model.param_units["c"] == "%/N" and model.param_units["delta_kPa"] == "kPa"
    assert model.bounds[0][2] == -3.0 and model.bounds[1][-1] == np.inf
    assert model.bounds[0][6] == 0.0  # a spring in series: c ≥ 0
    # one effect alone is a model too: Sárosi eq. 2.1 with a rig in series
    alone = Compliance.wrap(SAROSI, implicit=True)
    assert alone.param_names == (*SAROSI.param_names, "c") and alone.bounds[0][-1] == 0.0

    rng = np.random.default_rng(3)
    n = 400
    p_kpa = rng.uniform(100.0, 600.0, n)
    kappa = rng.uniform(0.0, 22.0, n)
    hours = np.linspace(0.0, 2.0, n)
    truth = np.concatenate([theta31, [0.002, -6.0, 4.0]])
    x = (*SAROSI.to_x(p_kpa, kappa), hours[:, None])
    y = np.asarray(model.predict(jnp.asarray(truth), x))
    np.testing.assert_allclose(model.jacobian(jnp.asarray(truth), x),
                               jax.jacfwd(lambda q: model.predict(q, x))(jnp.asarray(truth)),
                               rtol=1e-10, atol=1e-8)
    data = pamid.FitData(x=tuple(jnp.asarray(a)[None] for a in x), y=jnp.asarray(y)[None],
                         w=jnp.ones((1, n)), curve=jnp.zeros((1, n), jnp.int32))
    theta, ok, _ = pamid.engine.solve(model, data, solver="levenberg-marquardt",
                                      theta0=truth[None] * 1.02, max_steps=200)
    assert ok[0]
    np.testing.assert_allclose(theta[0], truth, rtol=1e-6)
    # the compliance alone, through the one entry
    truth = truth[:7]
    y = np.asarray(alone.predict(jnp.asarray(truth), x[:-1]))
    sol = pamid.engine.least_squares(
        alone, data._replace(x=data.x[:-1], y=jnp.asarray(y)[None]),
        solver="levenberg-marquardt", theta0=truth[None] * 1.02, max_steps=200)
    assert sol.converged[0]
    np.testing.assert_allclose(sol.params[0], truth, rtol=1e-6)


def test_a_feature_effect_alone_is_a_model_fitted_through_the_one_entry(theta31):
    """Hysteresis(SAROSI): Sárosi eq. 2.1 with the jump at a reversal, −d·(h0 + h1·p), its
    columns made by the effect's own features (those the diagnosis puts in its slots), its
    constants named with their units and the bounds that dissipation sets (h0, h1 ≥ 0)."""
    from types import SimpleNamespace

    Hysteresis, FeatureEffect, LinearTerms = (pamid.engine.Hysteresis,
                                              pamid.engine.FeatureEffect,
                                              pamid.engine.LinearTerms)
    SAROSI = pamid.engine.get_model("sarosi")
    model = Hysteresis.wrap(SAROSI)
    assert isinstance(model, FeatureEffect) and isinstance(model, LinearTerms)
    assert model.param_names == (*SAROSI.param_names, "h0", "h1")
    assert model.param_units["h1"] == "N/bar" and model.bounds[0][-2:] == (0.0, 0.0)
    assert [d.model.__name__ for d in STATIC_EFFECT_DEFINITIONS] == [
        "Hysteresis", "Temperature", "RelativeTemperature", "Drift", "ViscousDamping",
        "Transient", "Softening", "Covariate", "Compliance", "SensorOffset"]

    rng = np.random.default_rng(5)
    n = 300
    p_kpa = rng.uniform(100.0, 600.0, n)
    kappa = rng.uniform(0.0, 22.0, n)
    direction = np.where(rng.uniform(size=n) < 0.5, -1.0, 1.0)
    # no time order: the jump alone, no slip elements
    muscle = SimpleNamespace(p_bar=p_kpa / 100.0, file=SimpleNamespace(step_input=None))
    features = np.column_stack(Hysteresis.features(
        muscle, {"direction": direction}.__getitem__, None))
    truth = np.concatenate([theta31, [3.0, 1.5]])
    x = (*SAROSI.to_x(p_kpa, kappa), features)
    y = np.asarray(model.predict(jnp.asarray(truth), x))
    np.testing.assert_allclose(
        y, np.asarray(SAROSI.predict(jnp.asarray(theta31), x[:-1]))
        - direction * (3.0 + 1.5 * p_kpa / 100.0), rtol=1e-12)
    data = pamid.FitData(x=tuple(jnp.asarray(a)[None] for a in x), y=jnp.asarray(y)[None],
                         w=jnp.ones((1, n)), curve=jnp.zeros((1, n), jnp.int32))
    sol = pamid.engine.least_squares(model, data, solver="levenberg-marquardt",
                                     theta0=truth[None] * 1.02, max_steps=200)
    assert sol.converged[0]
    np.testing.assert_allclose(sol.params[0], truth, rtol=1e-6)


def test_a_decay_effect_is_a_model_that_wraps_the_oscillator():
    """The free decays' effects wrap the linear oscillator as the static effects wrap a
    force law: the decay diagnosis's model is DecayDrift(CoulombFriction(Trajectory)), in
    the registry's order; one effect alone is fitted through the one entry; and the Coulomb
    friction's response is the NumPy reference's (the virtual bench's injector)."""
    from pamid._decays._analysis import TRAJECTORY
    from pamid._decays._coulomb import FIT_NAMES
    from pamid._virtual._decay import coulomb_decay

    CoulombFriction, DecayDrift, decay_model = (pamid.engine.CoulombFriction,
                                                pamid.engine.DecayDrift,
                                                pamid.engine.decay_model)

    model = decay_model(32)
    assert isinstance(model, DecayDrift) and isinstance(model.base, CoulombFriction)
    assert model.base.base is TRAJECTORY.base and model.param_names == FIT_NAMES
    assert [e.model for e in DECAY_EFFECT_DEFINITIONS] == [CoulombFriction, DecayDrift]

    # Cullinan's arm (ζ = 0.05, f_n = 2.2 Hz), released from 0.15 rad with T_c/k = 4 mrad
    zeta, omega, a0, r0, eq, uc = 0.05, 2 * np.pi * 2.2, 0.15, 0.1, 0.01, 0.004
    t = np.linspace(0.0, 3.0, 751)
    alone = CoulombFriction.wrap(TRAJECTORY.base, n_half=32)
    assert alone.param_names == (*TRAJECTORY.base.param_names, "coulomb_shift_rad")
    truth = np.array([zeta, omega, a0, r0, eq, uc])
    y = np.asarray(alone.predict(jnp.asarray(truth), (jnp.asarray(t),)))
    # J = 1, k = ω_n², c = 2ζω_n: the NumPy reference with the friction torque T_c = u_c·k
    ref = coulomb_decay(1.0, omega**2, 2 * zeta * omega, eq, uc * omega**2, a0, r0, t)
    np.testing.assert_allclose(y, ref, atol=1e-12)
    # with the drift: the wrapped decay started at the rate β̇(0) − r, plus r·t
    both = decay_model(32)
    r = 0.002
    lowered = truth.copy()
    lowered[3] -= r
    np.testing.assert_allclose(
        both.predict(jnp.asarray([*truth, r]), (jnp.asarray(t),)),
        alone.predict(jnp.asarray(lowered), (jnp.asarray(t),)) + r * t, atol=1e-15)

    # the friction alone, fitted through the one entry from a start 2 % off
    data = pamid.FitData(x=(jnp.asarray(t)[None],), y=jnp.asarray(y)[None],
                         w=jnp.ones((1, t.size)), curve=jnp.zeros((1, t.size), jnp.int32))
    sol = pamid.engine.least_squares(alone, data, solver="levenberg-marquardt",
                                     theta0=truth[None] * 1.02, max_steps=200)
    assert sol.converged[0]
    np.testing.assert_allclose(sol.params[0], truth, rtol=1e-6)


# -- physical bounds ---------------------------------------------------------------------------


def test_a_rig_that_shortens_under_load_never_reports_a_negative_compliance(tmp_path):
    """The encoder reads a contraction that grows with the force (κ_read = κ + a·F): the
    force law would need F = F_model(p, κ_read − a·F), a compliance c = −a < 0."""
    proto = pamid.SarosiProtocol(min_force_N=10.0)
    frame = pamid.simulate_sarosi_bench(jax.random.key(2), pamid.sarosi.table_3_1(), proto)
    a_mm_per_N = 0.004
    frame["contraction_pct"] = frame["contraction_pct"] + 100.0 * a_mm_per_N * frame[
        "force_N"] / frame["l0_mm"]
    frame = frame.drop(columns=[c for c in ("length_mm",) if c in frame])
    path = tmp_path / "shortens.csv"
    frame.to_csv(path, index=False)
    d = diagnose(path)
    assert "compliance" not in d.selected
    row = next(r for r in d.candidates if r["effect"] == "compliance")
    assert row["delta_bic"] < -10  # the data would support it ...
    assert not row["significant"]  # ... but it is not physical
    assert "compliance would need c = -" in row["unphysical"]
    assert "mm/N" in row["unphysical"] and "not physical" in row["unphysical"]
    assert "compliance would need c = -" in diagnosis_report(d)
    assert "not selected" in diagnosis_report(d)


# -- detection in isometric files ---------------------------------------------------------------

HIDDEN = [
    # g and τ trade off where τ is about a sample interval: their product, the relaxation's
    # integral per kPa of step (0.05 N/kPa × 0.3 s), is what the data fix.
    ("transient", {"transient_N_per_kPa": 0.05, "transient_tau_s": 0.3, "dwell_s": 1.0},
     {"g*tau_s": (0.0115, 0.0195), "tau_s": (0.15, 0.6)}),
    ("softening", {"softening": 0.05, "softening_repeats": 1.0}, {"s": (0.045, 0.055)}),
    ("sensor_offset", {"pressure_offset_kPa": -30.0}, {"delta_kPa": (27.0, 33.0)}),
    ("drift", {"effects": (InjectedDrift(N_per_hour=100.0),)}, {}),
    ("temperature", {"effects": (InjectedTemperature(),)},
     {"tau0": (-0.6, -0.4), "tau1": (-0.36, -0.24)}),
]


def test_clean_isometric_file_selects_nothing(clean):
    assert clean.selected == []


@pytest.mark.parametrize(("name", "options", "constants"), HIDDEN, ids=[h[0] for h in HIDDEN])
def test_effect_detected_named_and_removed_in_isometric_file(tmp_path, clean, name, options,
                                                             constants):
    d = diagnose(_iso(tmp_path, name, **options))
    assert d.selected == [name]
    assert d.rmse_after < 1.05 * clean.rmse_before  # down to the noise
    got = {k: v["value"] for k, v in d.constants[0]["effects"][name].items()}
    for pname, (lo, hi) in constants.items():
        value = math.prod(got[p] for p in pname.split("*"))
        assert lo < value < hi, (pname, got)


def test_hysteresis_in_isometric_file_and_told_from_transient(tmp_path, clean):
    """Inflating below, deflating above (with the valve's direction logged): hysteresis,
    not a transient; a transient read as hysteresis would need h < 0 (a loop run
    backwards), which the fit never reaches (every element of the loop is held ≥ 0)."""
    d = diagnose(_iso(tmp_path, "hyst", drop_direction=False, hysteresis_N_at_3_bar=9.0))
    assert d.selected == ["hysteresis"]
    assert d.rmse_after < 1.05 * clean.rmse_before
    h = d.constants[0]["effects"]["hysteresis"]
    assert h["h1"]["ci95"][0] < 3.0 < h["h1"]["ci95"][1]  # 9 N at 3 bar, linear in p


def test_two_effects_together_softening_and_transient(tmp_path, clean):
    d = diagnose(_iso(tmp_path, "two", softening=0.05, softening_repeats=1.0,
                      transient_N_per_kPa=0.05, transient_tau_s=0.3, dwell_s=1.0))
    assert sorted(d.selected) == ["softening", "transient"]
    assert d.rmse_after < 1.05 * clean.rmse_before


def test_the_terms_a_model_already_contains_are_found_from_the_model_not_its_name():
    """Sárosi eq. 2.1 and Cullinan eq. 3 are affine in the pressure, Cullinan quadratic in
    y: those Legendre terms are not offered as effects. Found from the Jacobian's span, so
    a user's model gets the same treatment."""
    import pandas as pd

    from pamid._diagnose._static import degrees_in_model
    from pamid._fit._spec import CULLINAN, SAROSI, get_model

    rng = np.random.default_rng(3)
    p = rng.uniform(100.0, 600.0, 200)
    k = rng.uniform(0.0, 20.0, 200)
    frame = pd.DataFrame({"pressure_kPa": p, "contraction_pct": k, "contraction_mm": 2.5 * k})
    ranges = {c: (float(frame[c].min()), float(frame[c].max())) for c in frame}
    sarosi = degrees_in_model(SAROSI, np.array([-4.4, 281.0, -0.33, -9.3, 302.0, -264.0]),
                              (p / 100.0, k), frame, ["pressure_kPa", "contraction_pct"],
                              ranges)
    assert sarosi == {"pressure_kPa": (1,), "contraction_pct": ()}
    cullinan = degrees_in_model(CULLINAN, np.array([10.0, 1.0, 2.0, 0.01, 0.1]),
                                (p, 2.5 * k), frame, ["pressure_kPa", "contraction_mm"], ranges)
    assert cullinan == {"pressure_kPa": (1,), "contraction_mm": (1, 2)}

    from force_models import Plane

    plane = degrees_in_model(get_model(Plane), np.array([0.0, 1.0, -10.0]), (p, k), frame,
                             ["pressure_kPa", "contraction_pct"], ranges)
    assert plane == {"pressure_kPa": (1,), "contraction_pct": (1,)}


def test_a_length_per_newton_is_stated_once_through_l0():
    """A constant in % of l0 per newton is also a length per newton, for a muscle whose l0
    is known: one table (``pamid._units.L0_UNITS``), used by the diagnosis's JSON and its
    report alike."""
    from pamid._units import per_l0

    assert per_l0("%/N", 250.0) == ("mm/N", 2.5)
    assert per_l0("%/N", 0.0) is None and per_l0("%/N", float("nan")) is None
    assert per_l0("N", 250.0) is None
