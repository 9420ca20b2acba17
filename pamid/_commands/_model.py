"""The ``--model`` option, shared by ``pamid fit``, ``pamid diagnose`` and ``pamid compare``.

A model is named as one of pamid's own (``sarosi``, ``cullinan``, the published static
laws) or given as ``path/to/file.py:ClassName``, a :class:`pamid.ForceModel` subclass in a
file of the user's. :func:`check_model` resolves it before any data are read, so that a
typo or a broken model file ends in one line (exit 2), not after the data are loaded.
"""

from __future__ import annotations

import argparse

__all__ = ["add_model_argument", "check_model"]

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
