"""The ``drift`` effects: the load cell's zero moving with time (a static test: its
definition and injector), and a free decay's equilibrium moving with time (the effect as a
model that wraps the oscillator, :class:`DecayDrift`, and its definition)."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._base import Constant, DecayEffect, EffectDefinition
from ._inject import Injected, _check_form
from ._wrappers import EffectWrapper, FeatureEffect


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Drift(FeatureEffect):
    """A force law with the load cell's zero drifting: F_base + δ1·t + δ2·t², t in hours
    from the start of the muscle's test (:func:`drift`)."""

    constants: ClassVar[tuple[Constant, ...]] = (Constant("delta1", "N/h"),
                                                 Constant("delta2", "N/h²"))

    @staticmethod
    def features(muscle, col, grid_value, effect=None):
        h = col("elapsed_s") / 3600.0
        return [h, h**2]


def drift() -> EffectDefinition:
    """Load-cell zero drift: δ1·t + δ2·t², t in hours from the start of the muscle's test.

    Physical reason: a strain-gauge bridge's zero moves as it warms and creeps (any load
    cell's datasheet states a zero drift per hour and per kelvin); it is additive and does
    not depend on the load. Injector: :class:`pamid._effects._drift.InjectedDrift`.
    """
    return EffectDefinition(
        name="drift", covariates=("elapsed_s",), constants=Drift.constants,
        injector="pamid._effects._drift.InjectedDrift", model=Drift)


@dataclasses.dataclass(frozen=True)
class InjectedDrift(Injected):
    """A slow change of the force reading with time: load-cell zero drift.

    ``linear``: ``N_per_hour`` per hour from the start of the test; ``exponential``: the zero
    settles towards ``N_per_hour`` with the time constant ``time_constant_s`` (a strain gauge
    warming up), i.e. N_per_hour·(1 − e^(−t/τ)).
    """

    N_per_hour: float = 20.0
    form: str = "linear"
    time_constant_s: float = 600.0

    def __post_init__(self):
        _check_form(self.form, ("linear", "exponential"), "drift")

    def force_N(self, ctx):
        t = ctx["time_s"]
        if self.form == "linear":
            return self.N_per_hour * t / 3600.0
        return self.N_per_hour * (1.0 - np.exp(-t / self.time_constant_s))


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class DecayDrift(EffectWrapper):
    """A free decay about an equilibrium that moves linearly in time, β_eq(t) = β_eq + r·t
    (a slow leak, a creeping set point, an encoder drifting with temperature): ``theta`` =
    (θ of the base decay, r in rad/s), ``x`` = (time since the start, s,).
    ``DecayDrift.wrap(base)``.

    The angle is β(t) = r·t + the base's decay of the displacement from the moving centre,
    started from β(0) and the rate β̇(0) − r: the base's constants with its
    ``rate0_rad_s`` lowered by r. Without friction this is the exact solution of
    J·β̈ + c·β̇ + k·(β − β_eq − r_sp·t) = 0 (a set point moving at r_sp = r, which the arm
    follows c·r/k behind; β_eq here is the centre at t = 0, not the set point). Around
    :class:`~pamid._effects._coulomb_friction.CoulombFriction`, the friction's sign
    follows the rate about the moving centre instead of β̇: exact for r = 0, and the
    switching instants are off by about r/(ω_n²·amplitude) otherwise. Either sign of r is
    physical.
    """

    constants: ClassVar[tuple[Constant, ...]] = (Constant("drift_rad_s", "rad/s"),)

    def predict(self, theta, x):
        theta_b, r = self.split(theta)
        rate = self.base.param_names.index("rate0_rad_s")
        return self.base.predict(theta_b.at[rate].add(-r[0]), x) + r[0] * x[0]


def decay_drift() -> DecayEffect:
    """The ``drift`` effect of a free decay (:class:`DecayDrift`)."""
    return DecayEffect(
        "drift", "elapsed_s", "drift_rad_s", DecayDrift.constants[0],
        "pamid._virtual._decay.simulate_decays (drift_rad_s=)",
        "An equilibrium that moves with time, β_eq + r·t (a slow leak); either sign.",
        model=DecayDrift)
