"""The registries of candidate effects: one line per effect, its definition in a module of
its own beside its injector (:mod:`pamid._effects._base` says what a definition holds).
Adding an effect is one module and one line here."""

from __future__ import annotations

from ._base import DecayEffect, EffectDefinition
from ._compliance import compliance
from ._coulomb_friction import coulomb_friction
from ._covariate import covariate
from ._drift import decay_drift, drift
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
    return tuple(d for d in STATIC_EFFECT_DEFINITIONS if d.transform)


#: Every candidate effect of a free-decay diagnosis; their order is that of their constants
#: in the decay model (:func:`pamid._decays._coulomb.decay_model`), each wrapping the last.
DECAY_EFFECT_DEFINITIONS: tuple[DecayEffect, ...] = (coulomb_friction(), decay_drift())
