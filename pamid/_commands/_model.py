"""The ``--model`` option, shared by ``pamid fit``, ``pamid diagnose`` and ``pamid compare``.

A model is named as one of pamid's own (``sarosi``, ``cullinan``, the published static
laws) or given as ``path/to/file.py:ClassName``, a :class:`pamid.ForceModel` subclass in a
file of the user's. :func:`check_model` resolves it before any data are read, so that a
typo or a broken model file ends in one line (exit 2), not after the data are loaded.
"""

from __future__ import annotations

import argparse

__all__ = ["add_bounds_argument", "add_model_argument", "check_model", "parse_bounds"]

MODEL_HELP = ("force model: the name of one of pamid's own (sarosi: Sárosi eq. 2.1, p in bar, "
              "κ in %%; cullinan: Cullinan eq. 3, N, kPa, mm, s, with G when velocity_mm_s "
              "is given; `pamid compare --help` lists all), or path/to/file.py:ClassName for "
              "your own pamid.ForceModel")


def add_model_argument(parser: argparse.ArgumentParser, default: str = "sarosi") -> None:
    """Add ``--model NAME|FILE.py:CLASS``."""
    parser.add_argument("--model", default=default, metavar="NAME|FILE.py:CLASS",
                        help=f"{MODEL_HELP} (default {default})")


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


def parse_bounds(text: str | None, spec):
    """``--bounds`` text as ``(lower, upper)`` tuples over the spec's constants: the model's
    own bounds (``spec.bounds``, ±inf where none) with the named constants' replaced; None
    for no text. A ValueError naming the constant for text that is not ``NAME=LOW:HIGH``
    with a known constant, numbers, and LOW < HIGH."""
    import math

    if text is None or not text.strip():
        return None
    names = spec.param_names
    if spec.bounds is not None:
        lower, upper = list(spec.bounds[0]), list(spec.bounds[1])
    else:
        lower, upper = [-math.inf] * len(names), [math.inf] * len(names)
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        name, eq, rest = item.partition("=")
        name = name.strip()
        if not eq or ":" not in rest:
            raise ValueError(f"--bounds: {item!r} is not NAME=LOW:HIGH (e.g. a3=-3:0, or "
                             "a1=:0 for an upper bound only)")
        if name not in names:
            raise ValueError(f"--bounds: {spec.name} has no constant {name!r}; its constants: "
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
        j = names.index(name)
        lower[j], upper[j] = low, high
    return tuple(lower), tuple(upper)
