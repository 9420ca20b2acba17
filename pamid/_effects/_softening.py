"""The ``softening`` effect: the Mullins effect, force lost from repeat to repeat; its
definition (its injectors are fields of the virtual protocols)."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._base import Constant, EffectDefinition
from ._wrappers import FeatureEffect

#: Scales r (in repeats) of the ``softening`` grid.
SOFTENING_GRID = (0.3, 1.0, 3.0, 10.0)


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Softening(FeatureEffect):
    """A force law that loses force from repeat to repeat: F_base − s·(1 − e^(−repeat/r))·
    F_model, F_model the baseline fit and r chosen over a grid (:func:`softening`)."""

    constants: ClassVar[tuple[Constant, ...]] = (
        Constant("s", "1", lower=0.0, upper=1.0, meaning="share of force lost"),)

    @staticmethod
    def features(muscle, col, grid_value, effect=None):
        repeat = muscle.frame["repeat"].to_numpy(float)
        return [-(1.0 - np.exp(-repeat / grid_value)) * muscle.baseline_N]


def softening() -> EffectDefinition:
    """Loss of force from repeat to repeat, saturating: −s·(1 − e^(−repeat/r))·F_model.

    Physical reason: the Mullins effect — a filled rubber loaded again to a strain it has
    seen needs less stress than on its first loading, and the loss saturates over the
    first few cycles (Mullins, Rubber Chem. Technol. 42:339–362, 1969; Diani, Fayolle and
    Gilormini, "A review on the Mullins effect", Eur. Polym. J. 45:601–612, 2009). A loss
    of force: 0 ≤ s < 1; r > 0 (in repeats) is chosen over a grid. F_model is the baseline
    fit. The covariate is the repeat index (:attr:`pamid._data._curves.Curves.repeat`: a
    trial's order among the muscle's trials of the same setting, or the cycle). Injectors:
    ``IsometricProtocol.softening`` / ``softening_repeats`` (:mod:`pamid._virtual._isometric`),
    ``SarosiProtocol.softening`` / ``softening_repeats`` (:mod:`pamid._virtual._sweeps`).
    """
    return EffectDefinition(
        name="softening", covariates=("repeat",),
        constants=Softening.constants, model=Softening,
        injector=("pamid._virtual._isometric.IsometricProtocol.softening",
                  "pamid._virtual._sweeps.SarosiProtocol.softening"),
        grid=Constant("r", "repeats", lower=0.0),
        grid_values=lambda f, m: np.asarray(SOFTENING_GRID),
        applies=lambda f: f.max_repeat >= 1,
    )
