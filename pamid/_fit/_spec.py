"""What the fitting code needs to know about a model: its constants and its prediction.

A model is fitted as ``y ≈ predict(theta, x)`` with ``theta`` a flat vector of constants
and ``x`` a tuple of per-sample arrays. The batched solvers, the intervals, the bootstrap,
the plots and the CLI only see this interface, so a new force law is fitted by writing one
spec.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from .._errors import BenchDataError
from .._models._cullinan import CULLINAN_NAMES, CULLINAN_UNITS, Cullinan, cullinan_force
from .._models._sarosi import PARAM_NAMES, PARAM_UNITS, Sarosi, sarosi_force
from .._units import KPA_PER_BAR


@dataclasses.dataclass(frozen=True, eq=False)
class ModelSpec:
    """A model as the fitting code sees it.

    Attributes:
        name: the model's name in outputs ("sarosi", "cullinan").
        param_names: names of the constants, in the order of ``theta``.
        param_units: unit of each constant.
        units: the units the constants are stated in (the JSON ``"units"`` field).
        predict: ``predict(theta, x) -> y`` for one muscle; pure JAX.
        start: ``start(x, y, w) -> theta0`` for a batch (leading muscle axis; ``w`` = 0 on
            padding).
        columns: bench-frame columns that make ``x``, in order.
        to_x: maps those columns (NumPy arrays) to the model's ``x``.
        make: builds the model's parameter object (Sarosi, Cullinan) from ``theta``.
        source: the equation fitted, for outputs.
        output: the fitted quantity and its unit (force in N for the static models).
    """

    name: str
    param_names: tuple[str, ...]
    param_units: dict[str, str]
    units: dict[str, str]
    predict: Callable
    start: Callable
    columns: tuple[str, ...]
    to_x: Callable
    make: Callable
    source: str
    output: tuple[str, str] = ("force", "N")

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    @property
    def contraction_column(self) -> str:
        return self.columns[1]

    def x_from_frame(self, frame, path: str | None = None) -> tuple[np.ndarray, ...]:
        """The model inputs from a bench frame; a clear error if a column is missing."""
        for col in self.columns:
            if col not in frame:
                hint = {
                    "contraction_pct": "give contraction_pct, or length_mm with l0_mm",
                    "contraction_mm": "give contraction_mm, or length_mm or contraction_pct "
                    "together with l0_mm",
                }.get(col, f"add a {col} column")
                raise BenchDataError(
                    path, f"the {self.name} model needs {col}: {hint}", column=col
                )
        return self.to_x(*(frame[c].to_numpy(dtype=float) for c in self.columns))


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
    units={"force": "N", "pressure": "bar", "contraction": "%"},
    predict=_sarosi_predict,
    start=_sarosi_start,
    columns=("pressure_kPa", "contraction_pct"),
    to_x=lambda p_kpa, kappa: (p_kpa / KPA_PER_BAR, kappa),
    make=Sarosi.from_vector,
    source="Sárosi eq. 2.1",
)


def _cullinan_predict(theta, x):
    return cullinan_force(Cullinan.from_vector(theta), *x)


def _zeros_start(n_params):
    # Eq. 3 is linear in its constants, so Gauss–Newton lands on the exact least-squares
    # solution in one step from any start; the tests compare it with a direct linear solve.
    return lambda x, y, w: jnp.zeros((y.shape[0], n_params))


CULLINAN = ModelSpec(
    name="cullinan",
    param_names=CULLINAN_NAMES[:5],
    param_units={k: CULLINAN_UNITS[k] for k in CULLINAN_NAMES[:5]},
    units={"force": "N", "pressure": "kPa", "contraction": "mm", "time": "s"},
    predict=_cullinan_predict,
    start=_zeros_start(5),
    columns=("pressure_kPa", "contraction_mm"),
    to_x=lambda p_kpa, y_mm: (p_kpa, y_mm),
    make=Cullinan.from_vector,
    source="Cullinan eq. 3 (static: A–E)",
)

CULLINAN_DYNAMIC = dataclasses.replace(
    CULLINAN,
    param_names=CULLINAN_NAMES,
    param_units=dict(CULLINAN_UNITS),
    start=_zeros_start(6),
    columns=("pressure_kPa", "contraction_mm", "velocity_mm_s"),
    to_x=lambda p_kpa, y_mm, v: (p_kpa, y_mm, v),
    source="Cullinan eq. 3 (with velocity: A–E and G)",
)

MODELS = {"sarosi": SAROSI, "cullinan": CULLINAN}


def builtin_key(spec: ModelSpec) -> tuple | None:
    """A name for one of pamid's own specs that is the same in every process (the key of
    its exported programs, ``_export_cache``); None for any other spec."""
    for known in (SAROSI, CULLINAN, CULLINAN_DYNAMIC):
        if spec is known:
            return (known.name, known.source)
    return None


def get_model(name: str, frame=None) -> ModelSpec:
    """The spec for a model name; for "cullinan", with G when the data carry a velocity."""
    try:
        spec = MODELS[name]
    except KeyError:
        raise ValueError(f"unknown model {name!r}; choose one of {sorted(MODELS)}") from None
    if spec is CULLINAN and frame is not None and "velocity_mm_s" in frame:
        return CULLINAN_DYNAMIC
    return spec
