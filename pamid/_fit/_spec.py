"""What the fitting code needs to know about a model: its constants and its prediction.

A model is fitted as ``y ≈ predict(theta, x)`` with ``theta`` a flat vector of constants
and ``x`` a tuple of per-sample arrays. The batched solvers, the intervals, the bootstrap,
the plots and the CLI only see this interface, so a new force law is fitted by writing one
spec.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from .._errors import BenchDataError
from .._models._cullinan import CULLINAN_NAMES, Cullinan
from .._models._sarosi import Sarosi


@dataclasses.dataclass(frozen=True)
class FastPath:
    """A model's written-out kernels, registered with its spec and used in place of the
    generic ones (``_least_squares.solve``, ``statistics``, ``_intervals.profile``).

    Attributes:
        gauss_newton: ``(x, y, w, [theta0], *, max_steps, rtol, atol) -> (theta, ok,
            steps)`` for a batch, with its own start when no ``theta0`` is given.
        statistics: ``(theta, x, y, w) -> (sse, (JᵀJ)⁻¹, corr, n, full_rank)`` for a batch.
        statistics_take_curve: ``statistics`` also takes ``curve=`` (the lanes' curve ids)
            and then returns the residual's lag-1 sums after those five
            (:func:`pamid._fit._least_squares.lag1_sums`), from its own pass.
        variable_projection: ``(x, y, w, n_refine) -> (theta, _, bracket_width)`` or None.
        profile_derivatives: ``(x, y, w) -> (derivatives, sse_only)`` for the profile
            intervals' Newton iteration, or None.
    """

    gauss_newton: Callable
    statistics: Callable
    statistics_take_curve: bool = False
    variable_projection: Callable | None = None
    profile_derivatives: Callable | None = None

    @property
    def key(self) -> str:
        """A name for the kernels, the same in every process (the key of their exported
        programs): where the Gauss–Newton kernel is defined."""
        return f"{self.gauss_newton.__module__}.{self.gauss_newton.__qualname__}"


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
        bounds: physical (lower, upper) of each constant (±inf where none), or None.
        fast_path: the model's registered written-out kernels, or None.
        candidates: ``candidates(x, y, w, clip=True) -> (theta (M, K, p), sse (M, K))``,
            start candidates best first (:mod:`._start`; ``clip``: into the bounds), or None
            where the model brings its own start.
        linear: ``linear() -> mask (p,)``, the constants the model is linear in (found on
            first use, :func:`._start.linear_constants`), or None where the model brings
            its own start.
        model_class: the :class:`~pamid.ForceModel` the spec was made from, or None.
        prior: uniform priors ``{name: (low, high)}`` declared by the model, for MCMC.
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
    bounds: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    fast_path: FastPath | None = None
    candidates: Callable | None = None
    linear: Callable | None = None
    model_class: type | None = None
    prior: dict | None = None

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    @property
    def contraction_column(self) -> str:
        """The frame column of the model's contraction input (``contraction_pct`` where it
        takes none)."""
        return next((c for c in self.columns if c.startswith("contraction")),
                    "contraction_pct")

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


class ModelDefinitionError(ValueError):
    """A :class:`~pamid.ForceModel` that cannot be fitted as written; the message says what
    to change."""


def _input_unit(name: str) -> tuple[str, str]:
    """(quantity, unit) of an input name: ``pressure_kPa`` -> ("pressure", "kPa")."""
    quantity, _, unit = name.partition("_")
    unit = {"pct": "%", "ratio": "1", "mm_s": "mm/s", "m_s": "m/s"}.get(unit, unit)
    return quantity, unit or "1"


def _field_defaults(cls) -> dict[str, float]:
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def spec_from_model(model, *, params: tuple[str, ...] | None = None,
                    inputs: tuple[str, ...] | None = None,
                    start: Callable | None = None,
                    fast_path: FastPath | None = None) -> ModelSpec:
    """The fitting code's view of a :class:`~pamid.ForceModel` subclass (or instance).

    Args:
        model: the model class, or an instance whose field values become the start values.
        params: the constants to fit (default: every field not marked
            ``eqx.field(static=True)``); the others keep their defaults.
        inputs: the inputs to give, a prefix of ``model.inputs`` (default: all of them).
        start: a batched ``start(x, y, w) -> theta0`` in place of the model's own
            ``start`` or the generic one.
        fast_path: written-out kernels to use in place of the generic ones.

    The constants' order is the fields' order. Raises :class:`ModelDefinitionError` where
    the class lacks something the fit needs (a unit, an input, a start value).
    """
    from .._models._protocol import INPUT_CONVERSIONS, ForceModel

    cls = model if isinstance(model, type) else type(model)
    if not (isinstance(cls, type) and issubclass(cls, ForceModel)):
        raise ModelDefinitionError(f"{cls!r} is not a pamid.ForceModel subclass")
    label = cls.__name__
    fields = [f for f in dataclasses.fields(cls)]
    fitted = tuple(f.name for f in fields if not f.metadata.get("static", False))
    names = fitted if params is None else tuple(params)
    unknown = [n for n in names if n not in {f.name for f in fields}]
    if unknown:
        raise ModelDefinitionError(f"{label} has no constant(s) {', '.join(unknown)}")
    if not names:
        raise ModelDefinitionError(f"{label} has no constants to fit (no fields)")
    defaults = _field_defaults(cls)
    if not isinstance(model, type):
        defaults.update({f.name: getattr(model, f.name) for f in fields})
    model_inputs = tuple(cls.inputs)
    taken = model_inputs if inputs is None else tuple(inputs)
    if not taken or not all(isinstance(i, str) for i in taken):
        raise ModelDefinitionError(
            f"{label}.inputs must name the bench columns __call__ takes, in call order, "
            "e.g. inputs = ('pressure_kPa', 'contraction_pct')")
    if taken != model_inputs[:len(taken)]:
        raise ModelDefinitionError(f"inputs {taken} are not a prefix of {label}.inputs")
    units = dict(cls.units)
    missing_units = [n for n in names if n not in units]
    if missing_units:
        raise ModelDefinitionError(
            f"{label}.units has no unit for {', '.join(missing_units)}: give every constant "
            "its unit, e.g. units = {'c0': 'N'}")
    fixed = {k: v for k, v in defaults.items() if k not in names}
    lower = np.full(len(names), -np.inf)
    upper = np.full(len(names), np.inf)
    for key, (lo, hi) in dict(cls.bounds).items():
        if key not in names:
            if key in fixed:
                continue
            raise ModelDefinitionError(f"{label}.bounds names {key!r}, which is not a constant")
        if not lo < hi:
            raise ModelDefinitionError(f"{label}.bounds[{key!r}]: lower {lo} must be below "
                                       f"upper {hi}")
        lower[names.index(key)], upper[names.index(key)] = lo, hi
    bounds = None if np.all(np.isinf(lower)) and np.all(np.isinf(upper)) else (
        tuple(lower.tolist()), tuple(upper.tolist()))
    columns, factors = [], []
    for name in taken:
        column, *factor = INPUT_CONVERSIONS.get(name, (name, 1.0, 1.0))
        columns.append(column)
        factors.append(tuple(factor))

    def predict(theta, x):
        kwargs = {n: theta[..., i] for i, n in enumerate(names)}
        return cls(**kwargs, **fixed)(*x)

    def to_x(*cols):
        return tuple(c if m == d == 1.0 else c * m / d for c, (m, d) in zip(cols, factors))

    def make(theta):
        theta = jnp.asarray(theta)
        return cls(**{n: theta[..., i] for i, n in enumerate(names)}, **fixed)

    own_start = getattr(cls, "start", None)
    candidates = linear_mask = None
    if start is None and own_start is not None:
        def start(x, y, w):
            return own_start(x, y, w)
    elif start is None:
        @functools.cache
        def linear_mask():
            # Found on first use (it traces the model), not when the spec is made.
            from ._start import linear_constants

            reference = [float(defaults.get(n, 1.0)) for n in names]
            # pamid's own classes are named alike in every process (and their code is in
            # the hash that keys the programs kept on disk); a user's are not.
            own = cls.__module__.split(".")[0] == "pamid"
            key = (cls.__module__, cls.__qualname__, names, taken, repr(sorted(fixed.items())))
            return linear_constants(predict, len(names), taken, reference,
                                    cache_key=key if own else None)

        @functools.cache
        def design():
            from ._start import projected_candidates, trial_values

            reference = [float(defaults.get(n, 1.0)) for n in names]
            linear = linear_mask()
            lacking = [n for n, lin in zip(names, linear) if not lin and n not in defaults]
            if lacking:
                raise ModelDefinitionError(
                    f"{label}: give {', '.join(lacking)} a default (its start value) or "
                    "define a classmethod start(cls, inputs, force_N, weight)")
            trials = trial_values(reference, lower, upper, ~linear)
            return projected_candidates(predict, linear, trials, lower, upper)

        def candidates(x, y, w, clip=True):
            return design()(x, y, w, clip=clip)

        def start(x, y, w):
            return candidates(x, y, w)[0][:, 0]

    doc = (cls.__doc__ or "").strip().splitlines()
    if doc and doc[0].startswith(f"{label}("):  # written by dataclasses, not by the author
        doc = []
    source = cls.source or (doc[0] if doc else f"{label} (user model)")
    return ModelSpec(
        name=cls.name or label.lower(),
        param_names=names,
        param_units={n: units[n] for n in names},
        units={"force": "N", **dict(_input_unit(i) for i in taken)},
        predict=predict,
        start=start,
        columns=tuple(columns),
        to_x=to_x,
        make=make,
        source=source,
        bounds=bounds,
        fast_path=fast_path,
        candidates=candidates,
        linear=linear_mask,
        model_class=cls,
        prior=dict(cls.prior) or None,
    )


def _sarosi_fast_path() -> FastPath:
    from .._solvers import (
        sarosi_derivatives,
        sarosi_gauss_newton,
        sarosi_statistics,
        sarosi_variable_projection,
    )

    return FastPath(gauss_newton=sarosi_gauss_newton,
                    statistics=sarosi_statistics, statistics_take_curve=True,
                    variable_projection=sarosi_variable_projection,
                    profile_derivatives=sarosi_derivatives)


def _sarosi_start(x, y, w):
    from .._solvers import sarosi_variable_projection_start

    return sarosi_variable_projection_start(x, y, w)


SAROSI = dataclasses.replace(
    spec_from_model(Sarosi, start=_sarosi_start, fast_path=_sarosi_fast_path()),
    make=Sarosi.from_vector,
)
CULLINAN = dataclasses.replace(
    spec_from_model(Cullinan, params=CULLINAN_NAMES[:5], inputs=Cullinan.inputs[:2]),
    units={"force": "N", "pressure": "kPa", "contraction": "mm", "time": "s"},
    make=Cullinan.from_vector, source="Cullinan eq. 3 (static: A–E)",
)
CULLINAN_DYNAMIC = dataclasses.replace(
    spec_from_model(Cullinan),
    units=CULLINAN.units, make=Cullinan.from_vector,
    source="Cullinan eq. 3 (with velocity: A–E and G)",
)

#: pamid's own models by name (``--model NAME``).
MODELS: dict[str, ModelSpec] = {"sarosi": SAROSI, "cullinan": CULLINAN}

#: A model's variants fitted where the data carry a further input: (column, spec) pairs
#: tried in order (Cullinan eq. 3 with its damping constant G where the file has a
#: velocity).
VARIANTS: dict[str, tuple[tuple[str, ModelSpec], ...]] = {
    "cullinan": (("velocity_mm_s", CULLINAN_DYNAMIC),)}


def register_model(model, *, name: str | None = None, **kwargs) -> ModelSpec:
    """Add a :class:`~pamid.ForceModel` to pamid's own models (``--model NAME``)."""
    spec = spec_from_model(model, **kwargs)
    if name is not None:
        spec = dataclasses.replace(spec, name=name)
    MODELS[spec.name] = spec
    return spec


def model_names() -> tuple[str, ...]:
    """The names of pamid's own models, those :func:`register_model` added included (what
    ``--model NAME`` and :func:`get_model` accept), in the order they were registered."""
    return tuple(MODELS)


def builtin_key(spec: ModelSpec) -> tuple | None:
    """A name for one of pamid's own specs that is the same in every process (the key of
    its exported programs, ``_export_cache``); None for any other spec."""
    for known in (*MODELS.values(), *(v for pairs in VARIANTS.values() for _, v in pairs)):
        if spec is known:
            return (known.name, known.source)
    return None


def get_model(name, frame=None) -> ModelSpec:
    """The spec for a model: a name of pamid's own (for "cullinan", with G when the data
    carry a velocity), ``"path/to/file.py:ClassName"`` for a user's, a
    :class:`~pamid.ForceModel` class or instance, or a ModelSpec (returned as it is)."""
    if isinstance(name, ModelSpec):
        return name
    if isinstance(name, type):
        return _class_spec(name)
    if not isinstance(name, str):
        return spec_from_model(name)  # an instance: its values are the start
    if ":" in name and name.split(":", 1)[0].endswith(".py"):
        return _class_spec(load_model_class(name))
    try:
        spec = MODELS[name]
    except KeyError:
        raise ValueError(
            f"unknown model {name!r}; choose one of {sorted(MODELS)}, or give "
            "path/to/file.py:ClassName for your own pamid.ForceModel") from None
    for column, variant in VARIANTS.get(name, ()) if frame is not None else ():
        if column in frame:
            return variant
    return spec


@functools.cache
def _class_spec(cls: type) -> ModelSpec:
    """One spec per model class, so that its compiled programs are reused across fits."""
    for spec in MODELS.values():
        if spec.model_class is cls:
            return spec
    return spec_from_model(cls)


_LOADED: dict[tuple[str, str, float], type] = {}


def load_model_class(reference: str) -> type:
    """The class named by ``"path/to/file.py:ClassName"``, imported from that file.

    Raises :class:`ModelDefinitionError` with one line naming the file (and the line, for
    an error in it) when the file cannot be read or run, or holds no such ForceModel."""
    import importlib.util
    import os
    import sys
    import traceback

    from .._models._protocol import ForceModel

    path, _, class_name = reference.rpartition(":")
    if not class_name:
        raise ModelDefinitionError(f"{reference}: name the class after a colon, "
                                   "e.g. models.py:Quadratic")
    try:
        mtime = os.stat(path).st_mtime
    except OSError as exc:
        raise ModelDefinitionError(f"{path}: cannot read the model file "
                                   f"({exc.strerror or exc})") from None
    key = (os.path.abspath(path), class_name, mtime)
    if key in _LOADED:
        return _LOADED[key]
    module_name = f"pamid_user_model_{abs(hash(key))}"
    try:
        module_spec = importlib.util.spec_from_file_location(module_name, path)
        if module_spec is None or module_spec.loader is None:
            raise ModelDefinitionError(f"{path}: not a Python file")
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[module_name] = module
        module_spec.loader.exec_module(module)
    except ModelDefinitionError:
        raise
    except SyntaxError as exc:
        raise ModelDefinitionError(
            f"{path}, line {exc.lineno}: syntax error in the model file: {exc.msg}") from None
    except (Exception, SystemExit) as exc:  # the user's code: where it failed, in one line
        frames = [f for f in traceback.extract_tb(exc.__traceback__)
                  if os.path.abspath(f.filename) == key[0]]
        where = f", line {frames[-1].lineno}" if frames else ""
        what = (f"it ended the program (SystemExit: {exc.code!r}); a model file defines "
                "classes" if isinstance(exc, SystemExit) else f"{type(exc).__name__}: {exc}")
        raise ModelDefinitionError(
            f"{path}{where}: the model file failed to run: {what}") from None
    cls = getattr(module, class_name, None)
    if cls is None:
        found = sorted(k for k, v in vars(module).items()
                       if isinstance(v, type) and issubclass(v, ForceModel) and v is not ForceModel)
        raise ModelDefinitionError(
            f"{path}: no class {class_name!r}; pamid.ForceModel classes in it: "
            f"{', '.join(found) or 'none'}")
    if not (isinstance(cls, type) and issubclass(cls, ForceModel)):
        raise ModelDefinitionError(f"{path}: {class_name} is not a pamid.ForceModel subclass")
    _LOADED[key] = cls
    return cls


def check_callable(spec: ModelSpec, where: str) -> None:
    """Call the model once at its start values on a few probe inputs: a
    :class:`ModelDefinitionError` naming the file and line of a model that fails there or
    returns no force of the inputs' shape."""
    import os
    import traceback

    from ._start import probe_inputs

    cls = spec.model_class
    path = os.path.abspath(where.rpartition(":")[0]) if ":" in where else None
    probe = probe_inputs(tuple(cls.inputs[: len(spec.columns)]))
    defaults = _field_defaults(cls)
    theta = jnp.asarray([float(defaults.get(n, 1.0)) for n in spec.param_names])
    try:
        out = spec.predict(theta, probe)
        shape = np.shape(out)
    except (Exception, SystemExit) as exc:  # the user's code: one line, the place it failed
        frames = [f for f in traceback.extract_tb(exc.__traceback__)
                  if path is not None and os.path.abspath(f.filename) == path]
        at = f"{where.rpartition(':')[0]}, line {frames[-1].lineno}" if frames else where
        raise ModelDefinitionError(
            f"{at}: {cls.__name__}.__call__ failed on test inputs "
            f"({type(exc).__name__}: {exc})") from None
    if shape != np.shape(probe[0]):
        raise ModelDefinitionError(
            f"{where}: {cls.__name__}.__call__ returned shape {shape} for inputs of shape "
            f"{np.shape(probe[0])}: it must return one force per sample")


def _register_published() -> None:
    """The published static force laws (:mod:`pamid._models._published`), by their names."""
    from .._models._published import published_models

    for model, options in published_models():
        register_model(model, **options)


_register_published()
