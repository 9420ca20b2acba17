"""Argument checks shared by the model functions: specific, early ValueErrors.

A check runs only on concrete values; under an outer ``jit``/``vmap`` the arguments are
tracers and the check is skipped (the functions stay traceable).
"""

from __future__ import annotations

import jax
import numpy as np


def concrete_or_none(value) -> np.ndarray | None:
    """``value`` as a NumPy array, or None where it is traced (no checks under jit)."""
    if isinstance(value, jax.core.Tracer):  # the value is not known until run time
        return None
    return np.asarray(value, dtype=np.float64)


def require(name: str, value, ok, condition: str) -> None:
    """Raise ValueError naming ``name`` unless ``ok`` holds for its concrete value."""
    arr = concrete_or_none(value)
    if arr is not None and not np.all(ok(arr)):
        raise ValueError(f"{name} must be {condition}; got {arr.tolist()}")
