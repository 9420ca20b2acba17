"""The ``softening`` effect: the Mullins effect, force lost from repeat to repeat; its
definition (its injectors are fields of the virtual protocols)."""

from __future__ import annotations

import numpy as np

from ._base import Constant, EffectDefinition

#: Scales r (in repeats) of the ``softening`` grid.
SOFTENING_GRID = (0.3, 1.0, 3.0, 10.0)


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
        constants=(Constant("s", "1", lower=0.0, upper=1.0, meaning="share of force lost"),),
        injector=("pamid._virtual._isometric.IsometricProtocol.softening",
                  "pamid._virtual._sweeps.SarosiProtocol.softening"),
        features=lambda m, col, r: [-(1.0 - np.exp(-m.frame["repeat"].to_numpy(float) / r))
                                    * m.baseline_N],
        grid=Constant("r", "repeats", lower=0.0),
        grid_values=lambda f, m: np.asarray(SOFTENING_GRID),
        applies=lambda f: f.max_repeat >= 1,
    )
