"""Friction with memory: the Maxwell-slip element, the one definition that the
``hysteresis`` effect's features (:mod:`pamid._effects._definitions`) and the virtual
bench's :class:`~pamid._effects._hysteresis.InjectedMaxwellSlip` both use.

A Maxwell-slip element is a spring in series with a block under dry friction (Lampaert,
Al-Bender and Swevers, "A generalized Maxwell-slip friction model appropriate for control
purposes", IEEE PhyCon 2003; Al-Bender, Lampaert and Swevers, IEEE Trans. Autom. Control
50(11):1883–1887, 2005). As the input u moves, the spring deflects with it until its force
reaches the block's slip force; then the block slides and the deflection stays at the
threshold r. The deflection is the stop operator of u (Visintin, Differential Models of
Hysteresis, 1994, ch. III; Krasnosel'skii and Pokrovskii, Systems with Hysteresis, 1989):

    s_n = clip(s_(n−1) + (u_n − u_(n−1)), −r, r),

and its force k·s. Elements of several thresholds side by side (non-negative weights) give
the generalized Prandtl–Ishlinskii operator: a rate-independent loop that curves at every
reversal and closes minor loops (the "memory" that a direction-dependent offset lacks). In a
pneumatic muscle the elements are the braid's fibres sliding on each other and on the
bladder (Chou and Hannaford 1996; Tondu and Lopez, IEEE Control Syst. Mag. 20(2):15–38,
2000, model this friction as proportional to the pressure); they do not relax at a held
input, which is what tells them from a viscoelastic transient.

Here ŝ = s/r ∈ [−1, 1] is returned: +1 once u has risen by 2r since its last fall.

A logged input jitters by its sensor's noise where the real one holds, and the force does
not follow the jitter; an element in its elastic range would (by u's noise over r), and
could then cancel the pressure noise that the force law carries into the residual rather
than describe friction. :func:`play_operator` with a half width of a few noise standard
deviations takes the jitter out first (its output moves only where the input moves beyond
it: the backlash, or play, operator of the same references).
"""

from __future__ import annotations

import numpy as np

__all__ = ["initial_state", "play_operator", "stop_operator"]


def play_operator(u: np.ndarray, b: np.ndarray | float, start: np.ndarray | None = None
                  ) -> np.ndarray:
    """The play (backlash) operator of half width ``b`` ≥ 0 (one for all samples or one per
    sample): y_n = clip(y_(n−1), u_n − b_n, u_n + b_n), starting again at y = u where
    ``start`` is True (and at the first sample)."""
    u = np.asarray(u, float)
    b = np.broadcast_to(np.asarray(b, float), u.shape).tolist()
    first = np.zeros(len(u), bool) if start is None else np.asarray(start, bool)
    out = np.empty(len(u))
    y = 0.0
    for n, (v, bn, new) in enumerate(zip(u.tolist(), b, first.tolist(), strict=True)):
        y = v if new or n == 0 else min(v + bn, max(v - bn, y))
        out[n] = y
    return out


def initial_state(u: np.ndarray, r: float) -> float:
    """ŝ before the first sample: the input is taken to have arrived at its first value
    from the side opposite to its first move of more than ``r`` (a trial that inflates
    from rest was deflated before it; a sweep that contracts was extended): −1 if u first
    rises, +1 if it first falls, 0 if it never moves that far."""
    if len(u) == 0:
        return 0.0
    moved = np.flatnonzero(np.abs(u - u[0]) > r)
    if len(moved) == 0:
        return 0.0
    return -float(np.sign(u[moved[0]] - u[0]))


def stop_operator(u: np.ndarray, r: np.ndarray | float, start: np.ndarray | None = None,
                  initial: np.ndarray | float | None = None) -> np.ndarray:
    """The normalized deflection ŝ = s/r of Maxwell-slip elements of thresholds ``r``
    (the input's unit, > 0; a scalar or one per element) driven by ``u`` (1-D, in time
    order). ``start`` marks the samples where a new sequence begins (a new trial: its
    state starts again, at :func:`initial_state` unless ``initial`` gives it, one value per
    element or one for all). Returns (len(u),) for a scalar ``r``, else (len(u), len(r))."""
    u = np.asarray(u, float)
    scalar = np.ndim(r) == 0
    r = np.atleast_1d(np.asarray(r, float))
    if np.any(~(r > 0)):
        raise ValueError("the slip thresholds must be positive")
    n = len(u)
    start = np.zeros(n, bool) if start is None else np.asarray(start, bool).copy()
    if n:
        start[0] = True
    bounds = np.r_[np.flatnonzero(start), n]
    out = np.empty((n, len(r)))
    for j, rj in enumerate(r.tolist()):
        col = out[:, j]
        for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
            seg = u[a:b].tolist()
            if initial is None:
                s = initial_state(u[a:b], rj) * rj
            else:
                s = float(np.broadcast_to(initial, r.shape)[j]) * rj
            prev = seg[0]
            for k, v in enumerate(seg):
                s = min(rj, max(-rj, s + (v - prev)))
                prev = v
                col[a + k] = s / rj
    return out[:, 0] if scalar else out
