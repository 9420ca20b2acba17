"""The steps of a bench file's moving input: the valve's pulses of the pressure at a held
length (isometric tests), the rod's steps of the contraction at a held pressure (Sárosi's
sweeps), and the time since the last one. The ``transient`` effect follows them, and the
diagnosis reads them for every muscle (:mod:`pamid._diagnose._static`)."""

from __future__ import annotations

import numpy as np

#: A sample-to-sample change of the moving input larger than this many robust standard
#: deviations of such changes is a step (the valve's pulse), not sensor noise.
STEP_SIGMAS = 5.0


def moving_steps(pressure_kPa: np.ndarray, moving: np.ndarray, trial: np.ndarray
                 ) -> np.ndarray:
    """The steps of the moving pressure (kPa) at each sample of one muscle, 0 elsewhere.

    A step is a change from the previous sample of the same trial, where the pressure moves
    (``moving == 1``, an isometric test), larger than :data:`STEP_SIGMAS` robust standard
    deviations (1.4826·median absolute deviation) of all such changes: a valve's pulse, not
    the sensor's noise. Without noise every change is a step (a ramp is a train of steps).
    """
    dp = np.diff(pressure_kPa, prepend=pressure_kPa[:1])
    same = np.r_[False, trial[1:] == trial[:-1]] & (moving == 1)
    dp = np.where(same, dp, 0.0)
    if not same.any():
        return dp
    inside = dp[same]
    sigma = 1.4826 * np.median(np.abs(inside - np.median(inside)))
    floor = 1e-9 * (np.max(np.abs(pressure_kPa)) + 1.0)
    return np.where(np.abs(dp) > max(STEP_SIGMAS * sigma, floor), dp, 0.0)


def rod_steps(contraction: np.ndarray, moving: np.ndarray, trial: np.ndarray,
              noise: np.ndarray | float) -> np.ndarray:
    """The steps of the moving contraction (in its unit) at each sample of one muscle, 0
    elsewhere: a change from the previous sample of the same trial, where the contraction
    moves (``moving == 0``, Sárosi's sweeps: the rod steps at every point), larger than
    :data:`STEP_SIGMAS` times the contraction's noise (``noise``: the curve finder's
    estimate, :attr:`pamid._data._curves.Curves.noise`). Every point of a sweep is a step,
    so the robust spread of the changes (:func:`moving_steps`) cannot measure the noise
    here."""
    dk = np.diff(contraction, prepend=contraction[:1])
    same = np.r_[False, trial[1:] == trial[:-1]] & (moving == 0)
    floor = 1e-9 * (np.max(np.abs(contraction)) + 1.0) if len(contraction) else 0.0
    return np.where(same & (np.abs(dk) > np.maximum(STEP_SIGMAS * np.asarray(noise), floor)),
                    dk, 0.0)


def time_since_step(steps: np.ndarray, time_s: np.ndarray, trial: np.ndarray) -> np.ndarray:
    """Time since the last step of the moving input in the same trial (since the trial's
    first sample where none came yet), in s."""
    n = len(steps)
    idx = np.arange(n)
    first = np.r_[True, trial[1:] != trial[:-1]]
    marker = np.where((steps != 0) | first, idx, 0)
    last = np.maximum.accumulate(marker)
    return time_s - time_s[last]
