"""The ``sensor_offset`` effect: an offset of the logged pressure; the effect as a model
(:class:`SensorOffset`) and its definition (its injectors are fields of the virtual
protocols)."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from ._base import Constant, EffectDefinition, FileContext
from ._wrappers import InputTransform

#: Largest pressure-sensor offset that is still an offset, as a share of the largest
#: logged pressure; beyond it the logged pressure is not the muscle's pressure at all.
MAX_OFFSET_SHARE = 0.1


def _offset_bounds(file: FileContext) -> tuple[float, float]:
    b = MAX_OFFSET_SHARE * file.pressure_max_kPa
    return -b, b


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class SensorOffset(InputTransform):
    """A model whose logged pressure is off by δ: F = F_base(p_logged + δ, x), δ in kPa
    (:func:`sensor_offset`; its bound, a share of the file's largest pressure, is the
    file's). ``SensorOffset.wrap(base)``."""

    constants: ClassVar[tuple[Constant, ...]] = (
        Constant("delta_kPa", "kPa", bounds=_offset_bounds),)

    @classmethod
    def transform(cls, x, t, force, io):
        x = list(x)
        i, per_kpa = io["pressure"]
        x[i] = x[i] + t[..., 0] * per_kpa
        return tuple(x)


def sensor_offset() -> EffectDefinition:
    """An offset of the logged pressure: F = F_model(p_logged + δ, x).

    Physical reason: a pressure transducer's zero is off by manufacturing tolerance,
    mounting stress and temperature (zero-offset error; e.g. Ashcroft, "What causes offset
    in the output of a transducer at zero and span?", blog.ashcroft.com, and any sensor's
    datasheet, which states it in % of full scale); AARL's logger reads 7–9 kPa at ambient
    (``../shared/data/README.md``), i.e. δ ≈ −8 kPa. |δ| must stay below
    :data:`MAX_OFFSET_SHARE` of the largest logged pressure. Identifiable only where the
    force law is not affine in p at every length (Sárosi eq. 2.1: through the a4·κ·p term).
    Injectors: ``IsometricProtocol.pressure_offset_kPa`` (:mod:`pamid._virtual._isometric`),
    ``SarosiProtocol.pressure_offset_kPa`` (:mod:`pamid._virtual._sweeps`).
    """
    return EffectDefinition(
        name="sensor_offset", covariates=(),
        constants=SensorOffset.constants,
        injector=("pamid._virtual._isometric.IsometricProtocol.pressure_offset_kPa",
                  "pamid._virtual._sweeps.SarosiProtocol.pressure_offset_kPa"),
        model=SensorOffset,
        applies=lambda f: "pressure_kPa" in f.spec.columns)
