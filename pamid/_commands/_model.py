"""The ``--model`` option, shared by ``pamid fit``, ``pamid diagnose`` and ``pamid compare``.

A model is named as one of pamid's own (``sarosi``, ``cullinan``, the published static
laws) or given as ``path/to/file.py:ClassName``, a :class:`pamid.ForceModel` subclass in a
file of the user's. :func:`check_model` resolves it before any data are read, so that a
typo or a broken model file ends in one line (exit 2), not after the data are loaded.
"""

from __future__ import annotations

import argparse

__all__ = [
    "CODE_WARNING",
    "add_bounds_argument",
    "add_model_argument",
    "bound_items",
    "bounds_with",
    "check_model",
    "parse_bounds",
    "parse_bounds_per_model",
]

#: What every option that takes a model file says: pamid imports the file, which runs it.
CODE_WARNING = ("A model file is Python code: pamid imports it, which runs whatever it does, "
                "with your permissions; give only files you trust")

MODEL_HELP = ("force model: the name of one of pamid's own (sarosi: Sárosi eq. 2.1, p in bar, "
              "κ in %%; cullinan: Cullinan eq. 3, N, kPa, mm, s, with G when velocity_mm_s "
              "is given; `pamid compare --help` lists all), or path/to/file.py:ClassName for "
              "your own pamid.ForceModel")


def add_model_argument(parser: argparse.ArgumentParser, default: str = "sarosi") -> None:
    """Add ``--model NAME|FILE.py:CLASS``."""
    parser.add_argument("--model", default=default, metavar="NAME|FILE.py:CLASS",
                        help=f"{MODEL_HELP} (default {default}). {CODE_WARNING}")


def check_model(reference: str):
    """The model's spec, or a ValueError naming what is wrong (an unknown name, a model file
    that does not run, a class that is no ForceModel, a call that fails on test inputs)."""
    from .._fit._spec import check_callable, get_model

    spec = get_model(reference)
    if spec.model_class is not None and ":" in reference:
        check_callable(spec, reference)
    return spec


BOUNDS_HELP = ("physical bounds of constants, e.g. 'a3=-3:0,a1=:0' (an empty side: no bound "
               "there); in place of the model's own bounds for the constants named. A fit "
               "never reports a constant outside them; one on a bound is marked")


def add_bounds_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--bounds NAME=LOW:HIGH,…``."""
    parser.add_argument("--bounds", default=None, metavar="NAME=LOW:HIGH,...",
                        help=BOUNDS_HELP)


def bound_items(text: str | None, names, model: str = "the model") -> dict[str, tuple]:
    """``--bounds`` text as {constant: (low, high)} for the constants it names (±inf for an
    empty side); {} for no text. A ValueError naming the item for text that is not
    ``NAME=LOW:HIGH`` with a constant of ``names``, numbers, and LOW < HIGH."""
    import math

    items: dict[str, tuple] = {}
    for item in (part.strip() for part in (text or "").split(",")):
        if not item:
            continue
        name, eq, rest = item.partition("=")
        name = name.strip()
        if not eq or ":" not in rest:
            raise ValueError(f"--bounds: {item!r} is not NAME=LOW:HIGH (e.g. a3=-3:0, or "
                             "a1=:0 for an upper bound only)")
        if name not in names:
            raise ValueError(f"--bounds: {model} has no constant {name!r}; its constants: "
                             f"{', '.join(names)}")
        low_text, high_text = (t.strip() for t in rest.split(":", 1))
        try:
            low = float(low_text) if low_text else -math.inf
            high = float(high_text) if high_text else math.inf
        except ValueError:
            raise ValueError(f"--bounds: {name}: {rest!r} is not LOW:HIGH with numbers "
                             "(e.g. -3:0)") from None
        if math.isnan(low) or math.isnan(high) or not low < high:
            raise ValueError(f"--bounds: {name}: the lower bound {low_text or '-inf'} must be "
                             f"below the upper bound {high_text or 'inf'}")
        items[name] = (low, high)
    return items


def bounds_with(spec, items: dict[str, tuple]):
    """``(lower, upper)`` tuples over the spec's constants: the model's own bounds
    (``spec.bounds``, ±inf where none) with those of ``items`` in place; None for none."""
    import math

    if not items:
        return None
    names = spec.param_names
    if spec.bounds is not None:
        lower, upper = list(spec.bounds[0]), list(spec.bounds[1])
    else:
        lower, upper = [-math.inf] * len(names), [math.inf] * len(names)
    for name, (low, high) in items.items():
        j = names.index(name)
        lower[j], upper[j] = low, high
    return tuple(lower), tuple(upper)


def parse_bounds(text: str | None, spec):
    """``--bounds`` text as ``(lower, upper)`` tuples over the spec's constants
    (:func:`bounds_with` of :func:`bound_items`); None for no text."""
    return bounds_with(spec, bound_items(text, spec.param_names, spec.name))


def parse_bounds_per_model(text: str | None, specs) -> dict[str, tuple]:
    """``--bounds`` of ``pamid compare``: items ``MODEL.NAME=LOW:HIGH`` for one model, or
    ``NAME=LOW:HIGH`` for every compared model with a constant of that name. Returns
    {model name: (lower, upper)} for the models given a bound."""
    by_name = {spec.name: spec for spec in specs}
    per_model: dict[str, list[str]] = {}
    for item in (part.strip() for part in (text or "").split(",")):
        if not item:
            continue
        left, eq, right = item.partition("=")
        head = left.strip()
        model, dot, const = head.rpartition(".")
        if dot and model in by_name:
            per_model.setdefault(model, []).append(const + eq + right)
            continue
        if dot:
            raise ValueError(f"--bounds: {item!r} names a model not compared ({model!r}); "
                             f"compared: {', '.join(by_name)}")
        having = [s.name for s in specs if head in s.param_names]
        if not having:
            raise ValueError(f"--bounds: no compared model has a constant {head!r} "
                             f"(write MODEL.NAME=LOW:HIGH for one model)")
        for name in having:
            per_model.setdefault(name, []).append(item)
    return {name: parse_bounds(",".join(items), by_name[name])
            for name, items in per_model.items()}
