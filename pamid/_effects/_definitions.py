"""The registries of candidate effects: one line per effect, its definition in a module of
its own beside its injector (:mod:`pamid._effects._base` says what a definition holds).
Adding an effect is one module and one line here."""

from __future__ import annotations

from ._base import Constant, DecayEffect, EffectDefinition
from ._compliance import compliance
from ._covariate import covariate
from ._drift import drift
from ._hysteresis import hysteresis
from ._sensor_offset import sensor_offset
from ._softening import softening
from ._temperature import temperature, temperature_relative
from ._transient import transient
from ._viscous_damping import viscous_damping

__all__ = ["DECAY_EFFECT_DEFINITIONS", "STATIC_EFFECT_DEFINITIONS", "transforms"]

#: Every candidate effect of a static diagnosis, in the order they are listed.
STATIC_EFFECT_DEFINITIONS: tuple[EffectDefinition, ...] = (
    hysteresis(), temperature(), temperature_relative(), drift(), viscous_damping(),
    transient(), softening(), covariate(), compliance(), sensor_offset(),
)


def transforms() -> tuple[EffectDefinition, ...]:
    """The effects that transform the model's inputs, in the order of their constants in
    the lanes' parameter layout."""
    return tuple(d for d in STATIC_EFFECT_DEFINITIONS if d.model is not None)


DECAY_EFFECT_DEFINITIONS: tuple[DecayEffect, ...] = (
    DecayEffect(
        "coulomb_friction", "velocity_rad_s", "coulomb_shift_rad", "coulomb_Nm",
        Constant("coulomb_Nm", "N·m", lower=0.0),
        "pamid._virtual._decay.simulate_decays (coulomb_Nm=)",
        "A constant friction torque T_c·sign(β̇) (the sliding seal, the cable over the "
        "pulley): the amplitude falls linearly instead of geometrically; T_c ≥ 0 "
        "(dissipation)."),
    DecayEffect(
        "drift", "elapsed_s", "drift_rad_s", "drift_rad_s", Constant("drift_rad_s", "rad/s"),
        "pamid._virtual._decay.simulate_decays (drift_rad_s=)",
        "An equilibrium that moves with time, β_eq + r·t (a slow leak); either sign."),
)
