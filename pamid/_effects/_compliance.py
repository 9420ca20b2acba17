"""The ``compliance`` effect: something in series with the force stretches under load; the
effect as a model (:class:`Compliance`), its definition and its injector."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from ._base import Constant, EffectDefinition
from ._inject import Injected
from ._wrappers import InputTransform


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Compliance(InputTransform):
    """A model with a spring in series: F solves F = F_base(p, x + c·F), ``c`` ≥ 0 in the
    contraction's unit per newton (:func:`compliance`). ``Compliance.wrap(base,
    implicit=True)``."""

    constants: ClassVar[tuple[Constant, ...]] = (Constant("c", "{x}/N", lower=0.0),)
    depends_on_force: ClassVar[bool] = True

    @classmethod
    def transform(cls, x, t, force, io):
        x = list(x)
        x[io["contraction"]] = x[io["contraction"]] + t[..., 0] * force
        return tuple(x)


def compliance() -> EffectDefinition:
    """Something in series with the force stretches under load: F solves
    F = F_model(p, x + c·F).

    Physical reason: the load cell, its mounts and any cable stretch under the force, so the
    muscle is shorter than the encoder says by c·F (a spring in series; Sárosi's rig reads
    the rod, not the muscle); so do the muscle's own end fittings and braid, which a static
    law of p and κ alone does not describe. On the AARL 10 mm muscles the fitted c grew with
    the muscle's length (0.0012, 0.0066 and 0.025 mm/N at 83, 132 and 281 mm;
    experiments/README.md §10): there it is the muscle's stretch, not the rig's. A spring
    has c ≥ 0: a negative c would mean a line that shortens under load. Injector:
    :class:`pamid._effects._compliance.InjectedCompliance`.
    """
    return EffectDefinition(
        name="compliance", covariates=(), constants=Compliance.constants,
        injector="pamid._effects._compliance.InjectedCompliance", model=Compliance,
        applies=lambda f: f.spec.contraction_column in f.spec.columns)


@dataclasses.dataclass(frozen=True)
class InjectedCompliance(Injected):
    """The rig stretches under load: the encoder reads the rod, not the muscle.

    The load cell, its mounts and a cable between them stretch by ``mm_per_N``·F, so the muscle
    is that much shorter than the rod position says: its true contraction is
    κ = κ_read + 100·c·F/l0, and the force solves F = F_model(p, κ_read + 100·c·F/l0).
    """

    mm_per_N: float = 0.01
