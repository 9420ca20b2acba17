"""The ``covariate`` family: any smooth function of a logged covariate, which names what the
library cannot model by what it depends on; its definition and injector."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._base import Constant, EffectDefinition, FileContext
from ._basis import legendre_basis, scaled
from ._inject import Injected, _check_form
from ._wrappers import FeatureEffect

#: Largest Legendre degree of the ``covariate`` family.
COVARIATE_DEGREE = 3


def _covariate_family(file: FileContext):
    out = []
    for c in file.covariates:
        if c == "direction":
            continue
        lo, hi = file.ranges[c]
        top = min(COVARIATE_DEGREE, file.distinct[c] - 1)
        degrees = [k for k in range(1, top + 1)
                   if k not in file.in_model.get(c, ())]
        if degrees:
            out.append((f"covariate:{c}", c, tuple(Constant(f"b{k}", "N") for k in degrees)))
    return out


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Covariate(FeatureEffect):
    """A force law plus a smooth function of one covariate z: F_base + Σ_k b_k·P_k(z), z
    scaled to [−1, 1] over the file (:func:`covariate`); its constants are a file's (the
    degrees its covariate allows: ``Covariate.wrap(base, constants)``), and its columns
    those of one member of the family (``effect``)."""

    constants: ClassVar[tuple[Constant, ...]] = ()

    @staticmethod
    def features(muscle, col, grid_value, effect=None):
        lo, hi = muscle.file.ranges[effect.covariate]
        basis = legendre_basis(scaled(col(effect.covariate), lo, hi), COVARIATE_DEGREE)
        return [basis[int(name[1:]) - 1] for name in effect.param_names]


def covariate() -> EffectDefinition:
    """Any smooth function of a covariate z: b1·P1(z) + b2·P2(z) + b3·P3(z), z scaled to
    [−1, 1] over the file, P_k Legendre polynomials (Abramowitz and Stegun, 22.2.10).

    Not a physical effect: it traces what the library cannot model to its covariate, so
    that an effect outside the library is still named by what it depends on. No bounds.
    Injector: :class:`pamid._effects._covariate.InjectedCovariate`.
    """
    return EffectDefinition(
        name="covariate", covariates=(), constants=(),
        injector="pamid._effects._covariate.InjectedCovariate",
        model=Covariate, family=_covariate_family)


@dataclasses.dataclass(frozen=True)
class InjectedCovariate(Injected):
    """Any other influence: a logged quantity (``column``) that the force depends on.

    Each sweep gets its own value drawn uniformly in ``range``, rounded to ``resolution``,
    written to the column; the force changes by ``N_per_unit·(v − mid)`` (``linear``),
    ``N_per_unit·(v − mid)²/half_range`` (``quadratic``) or
    ``N_per_unit·half_range·sin(π·(v − mid)/half_range)`` (``sine``), with ``mid`` and
    ``half_range`` the centre and half width of ``range``.
    """

    column: str = "humidity_pct"
    range: tuple[float, float] = (30.0, 70.0)
    N_per_unit: float = 0.3
    form: str = "linear"
    resolution: float = 0.1

    def __post_init__(self):
        _check_form(self.form, ("linear", "quadratic", "sine"), "covariate")

    def columns(self, ctx):
        lo, hi = self.range
        v = ctx["rng"].uniform(lo, hi, size=ctx["sweep"].shape[:-1] + (1,))
        v = np.broadcast_to(v, ctx["sweep"].shape[:-1] + (ctx["point_fraction"].shape[-1],))
        if self.resolution > 0:
            v = np.round(v / self.resolution) * self.resolution
        return {self.column: v}

    def force_N(self, ctx):
        lo, hi = self.range
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        u = ctx[self.column] - mid
        if self.form == "linear":
            return self.N_per_unit * u
        if self.form == "quadratic":
            return self.N_per_unit * u**2 / half
        return self.N_per_unit * half * np.sin(np.pi * u / half)
