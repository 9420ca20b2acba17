"""The ``drift`` effect: the load cell's zero moving with time; its definition and injector."""

from __future__ import annotations

import dataclasses

import numpy as np

from ._base import Constant, EffectDefinition
from ._inject import Injected, _check_form


def drift() -> EffectDefinition:
    """Load-cell zero drift: δ1·t + δ2·t², t in hours from the start of the muscle's test.

    Physical reason: a strain-gauge bridge's zero moves as it warms and creeps (any load
    cell's datasheet states a zero drift per hour and per kelvin); it is additive and does
    not depend on the load. Injector: :class:`pamid._effects._drift.InjectedDrift`.
    """
    def features(m, col, g):
        h = col("elapsed_s") / 3600.0
        return [h, h**2]

    return EffectDefinition(
        name="drift", covariates=("elapsed_s",),
        constants=(Constant("delta1", "N/h"), Constant("delta2", "N/h²")),
        injector="pamid._effects._drift.InjectedDrift", features=features)


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
