"""Sárosi eq. 2.1 and its analytic Jacobian in plain NumPy: the reference the tests compare
pamid's JAX model and fits against (p in bar, κ in %)."""

import numpy as np


def force_np(theta, p, k):
    """Sárosi eq. 2.1: F = (a1·p + a2)·e^(a3·κ) + a4·κ·p + a5·p + a6."""
    a1, a2, a3, a4, a5, a6 = theta
    return (a1 * p + a2) * np.exp(a3 * k) + a4 * k * p + a5 * p + a6


def jacobian_np(theta, p, k):
    """∂F/∂(a1…a6), analytic."""
    a1, a2, a3 = theta[:3]
    e = np.exp(a3 * k)
    return np.stack([p * e, e, (a1 * p + a2) * k * e, k * p, p, np.ones_like(p)], axis=-1)
