"""The ``viscous_damping`` effect: a force opposing the rate of contraction; its definition
and injector."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from ._base import Constant, EffectDefinition
from ._inject import Injected
from ._wrappers import FeatureEffect


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class ViscousDamping(FeatureEffect):
    """A force law with a force opposing the rate of contraction: F_base − g·v
    (:func:`viscous_damping`)."""

    constants: ClassVar[tuple[Constant, ...]] = (Constant("g", "N·s/{x}", lower=0.0),)

    @staticmethod
    def features(muscle, col, grid_value, effect=None):
        return [-col(muscle.speed)]


def viscous_damping() -> EffectDefinition:
    """A force opposing the rate of contraction: −g·v (Cullinan's −G·ẏ, eq. 3).

    Physical reason: viscous losses in the bladder and the air flow resist motion in
    proportion to speed; dissipation requires g ≥ 0. Injector:
    :class:`pamid._effects._viscous_damping.InjectedViscousDamping`.
    """
    return EffectDefinition(
        name="viscous_damping", covariates=("speed_mm_s", "speed_pct_s"),
        constants=ViscousDamping.constants,
        injector="pamid._effects._viscous_damping.InjectedViscousDamping",
        model=ViscousDamping,
        applies=lambda f: len(f.spec.columns) < 3,  # Cullinan with G has it already
    )


@dataclasses.dataclass(frozen=True)
class InjectedViscousDamping(Injected):
    """A force opposing the rate of contraction: F − g·v (Cullinan's −G·ẏ term, eq. 3).

    Needs sweeps run at different speeds to be told apart from hysteresis; give the
    protocol ``sweep_seconds_per_point``.
    """

    N_s_per_mm: float = 2.0

    def force_N(self, ctx):
        return -self.N_s_per_mm * ctx["velocity_mm_s"]
