"""What the fitting code needs to know about a model: its constants and its prediction.

A model is fitted as ``y ≈ predict(theta, x)`` with ``theta`` a flat vector of constants
and ``x`` a tuple of per-sample arrays. The batched solvers, the intervals and the
bootstrap only see this interface, so a new force law is fitted by writing one spec.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax.numpy as jnp

from .._models._sarosi import PARAM_NAMES, PARAM_UNITS, Sarosi, sarosi_force


@dataclasses.dataclass(frozen=True, eq=False)
class ModelSpec:
    """A model as the fitting code sees it.

    Attributes:
        name: the model's name in outputs ("sarosi").
        param_names: names of the constants, in the order of ``theta``.
        param_units: unit of each constant.
        predict: ``predict(theta, x) -> y`` for one muscle; pure JAX, so it can be
            differentiated and vmapped.
        start: ``start(x, y, w) -> theta0`` for a batch: arrays with a leading muscle axis;
            ``w`` is the weight of each sample (0 marks padding).
        x_names: names of the arrays in ``x``, with units.
    """

    name: str
    param_names: tuple[str, ...]
    param_units: dict[str, str]
    predict: Callable
    start: Callable
    x_names: tuple[str, ...]

    @property
    def n_params(self) -> int:
        return len(self.param_names)


def _sarosi_predict(theta, x):
    pressure_bar, contraction_pct = x
    return sarosi_force(Sarosi.from_vector(theta), pressure_bar, contraction_pct)


def _sarosi_start(x, y, w):
    from ._variable_projection import sarosi_variable_projection_start

    return sarosi_variable_projection_start(x, y, w)


SAROSI = ModelSpec(
    name="sarosi",
    param_names=PARAM_NAMES,
    param_units=PARAM_UNITS,
    predict=_sarosi_predict,
    start=_sarosi_start,
    x_names=("pressure_bar", "contraction_pct"),
)

MODELS = {"sarosi": SAROSI}


def get_model(name: str) -> ModelSpec:
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown model {name!r}; choose one of {sorted(MODELS)}") from None


def as_jnp(*arrays):
    return tuple(jnp.asarray(a) for a in arrays)
