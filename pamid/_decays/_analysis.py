"""Damping of a PAM-driven joint from free decays: logarithmic decrement and trajectory fits.

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints", section VI (after [20], Sekine et al.). The two muscles
act as a rotational spring and viscous damper on the arm (Fig. 7(a)):
J0·β̈ + c·β̇ + k·(β − β_eq) = 0.

    δ = ln(x1/xn)                  per cycle, x the amplitude about the equilibrium  (eq. 8)
    δ = 2/(n − 1)·ln(a1/an)        a the peak-to-trough travel                        (eq. 9)
    ζ = δ / √(4π² + δ²)                                                                (eq. 10)
    c = 2·ζ·√(k·J0)                                                                    (eq. 11)
    J0 = m1·l1²/3 + m2·(d²/16 + t²/12) + m2·l2²   (eq. 12, corrected; see below)

and k = J0·ω_n², ω_n = ω_d/√(1 − ζ²), ω_d = 2π/T_d from the times of the extrema.

Eq. 8 as printed divides the first amplitude by the n-th (over n − 1 cycles); pamid reports
it per cycle, ln(x1/xn)/(n − 1), the usual definition that eq. 10 needs. It needs the
equilibrium, which pamid estimates from the extrema themselves: for a viscous decay the
signed extrema obey e_{j+1} − β_eq = −r·(e_j − β_eq), a straight line through the points
(e_j, e_{j+1}) whose fixed point is β_eq. Eq. 9 needs no equilibrium (why Cullinan used it).

Estimates (every one with a 95 % interval)
-----------------------------------------
* ``log_decrement`` (the headline): eq. 9 as a regression, ln a_j on the half-cycle index j
  (slope −δ/2), which uses every travel instead of the first and last only. Neighbouring
  travels share an extremum, so their errors are correlated (+½); the regression is
  generalised least squares with that covariance (each extremum's error independent, of
  unknown variance), and the interval is Student-t on its slope (n − 2 dof). Ordinary
  least squares, which takes the travels as independent, gave intervals half as wide as
  the scatter of the estimates over repeated virtual decays; with GLS the scatter and the
  intervals agree (coverage 88–95 % over 60 virtual decays at each of 0.5, 1 and 2 encoder
  steps of noise; ``tests/test_decay.py`` checks it on 40).
  The printed two-point forms of eq. 8 and eq. 9 are reported beside it (``*_endpoints``),
  and eq. 8 as a regression on |e_j − β_eq| (weights x_j²).
* ζ (eq. 10) maps δ monotonically, so its interval is the image of δ's. The damped frequency
  comes from a regression of the extremum times on j (slope T_d/2). ω_n, k and c (eq. 11)
  combine ζ and ω_d; their intervals are delta-method intervals on the log scale (ζ and
  ω_d treated as independent; J0 taken as exact), with the smaller of the two dof.
* Pooled over trials: the same regressions with one intercept per trial and a common slope.
* Amplitude dependence, the sign of Coulomb (dry) friction that the viscous model lacks:
  with Coulomb friction T_c the amplitude falls by a fixed 2·T_c/k per half cycle on top of
  the viscous factor, so the per-half-cycle decrement δ_j = 2·ln(a_j/a_{j+1}) grows as the
  amplitude shrinks. Reported: the slope of δ_j against the amplitude (t-test), δ of the
  early and of the late half of the travels and the test of their difference, and T_c
  itself from the exact half-cycle map of the viscous + Coulomb model,
  a_{j+1} = r·a_j − 2·(1 + r)·T_c/k (a regression of a_{j+1} on a_j), all by GLS with the
  covariance the shared extrema imply. ``amplitude_dependent`` is the three tests'
  Bonferroni-corrected decision at 1 % (on virtual decays: 1 false alarm in 40 without
  friction; T_c = 0.1 N·m with k = 88 N·m/rad found in 40 of 40), gated by practical
  significance (:data:`RESOLUTION_STEPS`): the amplitude lost per half cycle beyond the
  viscous factor, |b| = 2·(1 + r)·|T_c|/k, must exceed half an encoder step. The tests
  model only random errors of the extrema; the encoder's quantization is a systematic
  error that repeats identically in repeated trials (without noise, three releases from
  the same deflection record the same samples), so pooling them shrinks the p-values
  without limit while the bias stays. A dry-friction loss below half a step per half
  cycle is within what the quantization of the two extrema of a travel can fake, and is
  reported (``coulomb_shift_rad``, ``resolution_floor_rad``) but not called friction.
  Without friction (ζ = 0.05, f_n = 2.2 Hz, 12-bit encoder, three identical trials) the
  pooled map gave T_c = 0.0012 N·m at p = 0.006: |b| = 5·10⁻⁵ rad, 0.04 steps, not
  flagged; the hidden 0.1 N·m gives |b| ≈ 4·10⁻³ rad, 2.7 steps, flagged.

Honest intervals, growing oscillations, numbers of any size
-----------------------------------------------------------
Every interval is checked before it is reported: finite, ordered, and containing its
estimate; one that is not (too few points, a singular regression, a half period whose
interval reaches 0, an overdamped fit that has no logarithmic decrement) is None, and
``interval_notes`` says why. ζ's interval is the image of δ's on both sides, also below 0.
An oscillation whose δ lies below 0 with its whole interval grows (negative damping):
:attr:`DecrementEstimate.grows`, "the oscillation grows: the decay model does not apply";
the commands exit 1. Angles are analysed in a unit that keeps them near 1 rad
(:data:`ANGLE_RANGE_RAD`, a power of two, so the rescaling is exact), and k and c, which
scale with J, are propagated per unit J, so that 1e-300 or 1e300 rad and kg·m² neither
overflow nor underflow.

Peak and trough detection (:func:`find_extrema`), robust to encoder steps and noise: the
period is first estimated from the spectrum; the signal is smoothed over a twentieth of a
period; ``scipy.signal.find_peaks`` finds peaks and troughs with a prominence above the
noise (estimated from second differences) plus one encoder step (estimated from the
smallest nonzero change), and a spacing of most of a period — so a plateau of equal encoder
readings is one extremum, not many; peaks and troughs are forced to alternate; and each
extremum is refined by a least-squares parabola through the raw samples within ±T/8 of it
(twice, re-centred), which averages the noise and the quantization over ~T/4 of samples.
The parabola underestimates each |extremum − centre| by the same small fraction, which
cancels in every ratio. Extrema whose travel falls below a noise floor (see
:data:`MIN_TRAVEL_STEPS`, :data:`MIN_TRAVEL_NOISE`) end the usable part of the decay.

Trajectory fit (:func:`fit_decay_trajectories`): the closed-form linear decay
(:func:`pamid._sim._oscillator.oscillator_response`) is fitted directly to the samples of
each trial, from its first to its last usable extremum, with parameters ζ, ω_n, the angle
and rate at the first extremum, and β_eq; all trials in one vmapped optimistix
Levenberg–Marquardt solve; Wald intervals from the Jacobian at the optimum (s² = SSE/(n−5),
Student-t). Its residuals are not white under quantization, so its intervals may be
narrow; on the virtual decays their coverage was 90–97 %.

Eq. 12. As printed, J0 = m1·l1/3 + (m2·d²/16 + m2·t/12) + m2·l2² adds terms of different
units (kg·m and kg·m²). The parts are a slender rod of mass m1 and length l1 about its end
(m1·l1²/3) and a solid cylinder of mass m2, diameter d and thickness t about a transverse
axis through its centre (m2·(d²/16 + t²/12)), moved to the distance l2 by the parallel-axis
theorem (m2·l2²); :func:`moment_of_inertia_eq12` uses those squares. The paper quotes
J0 = 0.46 kg·m² with two 1.2 kg masses but gives neither l1, m1, d, t nor l2, so the number
cannot be checked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import jax.numpy as jnp
import numpy as np
import scipy.linalg

from .._errors import BenchDataError
from .._fit._least_squares import least_squares
from .._fit._spec import ModelSpec, scaled
from .._inference import covariance, t_critical, unscaled_covariance, wald_interval
from .._io import json_ready as _plain
from .._lanes._batch import FitData
from .._sim._oscillator import DampedOscillator, cos_sinc, oscillator_response
from .._solvers import ProjectedLevenbergMarquardt

__all__ = [
    "MIN_TRAVEL_NOISE",
    "MIN_TRAVEL_STEPS",
    "RESOLUTION_STEPS",
    "DecayReport",
    "DecrementEstimate",
    "Extrema",
    "NoOscillationError",
    "TrajectoryFit",
    "analyze_decays",
    "check_inertia",
    "decrement_estimate",
    "find_extrema",
    "fit_decay_trajectories",
    "log_decrement_to_zeta",
    "moment_of_inertia_eq12",
    "pooled_decrement_estimate",
]

#: A usable travel is at least this many encoder steps …
MIN_TRAVEL_STEPS = 8.0
#: … and at least this many standard deviations of the sample noise.
MIN_TRAVEL_NOISE = 20.0
#: Fewest usable extrema for an estimate (three travels: a slope with one dof to spare).
MIN_EXTREMA = 4
#: Practical significance of amplitude dependence: the extra amplitude lost per half cycle,
#: |b| = 2·(1 + r)·|T_c|/k, must exceed this many encoder steps (module docstring).
RESOLUTION_STEPS = 0.5
LEVEL = 0.95


class NoOscillationError(ValueError):
    """Too few peaks and troughs above the noise to measure a decay."""


# --------------------------------------------------------------------------------------
# Cullinan eq. 10 and eq. 12
# --------------------------------------------------------------------------------------



def _stats():
    """scipy.stats, imported on first use: it and scipy.signal are slow to import
    (benchmarks/README.md, "Figures that used to live in docstrings", (h))."""
    import scipy.stats

    return scipy.stats


def _signal():
    import scipy.signal

    return scipy.signal


def log_decrement_to_zeta(delta):
    """ζ = δ / √(4π² + δ²), Cullinan eq. 10 (works on arrays, NumPy or JAX)."""
    return delta / (4.0 * math.pi**2 + delta**2) ** 0.5


def _zeta_to_log_decrement(zeta):
    return 2.0 * math.pi * zeta / (1.0 - zeta**2) ** 0.5


def moment_of_inertia_eq12(m1_kg, l1_m, m2_kg, d_m, t_m, l2_m):
    """J0 in kg·m² of the arm and its weights, Cullinan eq. 12 with the squares restored.

    J0 = m1·l1²/3 + m2·(d²/16 + t²/12) + m2·l2²: a slender arm of mass ``m1_kg`` and length
    ``l1_m`` about its end, plus weights of total mass ``m2_kg`` (solid cylinders of diameter
    ``d_m`` and thickness ``t_m``) centred at ``l2_m`` from the pivot. The printed eq. 12
    (m1·l1/3 + m2·d²/16 + m2·t/12 + m2·l2²) drops the squares on l1 and t and mixes units;
    see the module docstring.
    """
    return m1_kg * l1_m**2 / 3.0 + m2_kg * (d_m**2 / 16.0 + t_m**2 / 12.0) + m2_kg * l2_m**2


# --------------------------------------------------------------------------------------
# Peaks and troughs
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Extrema:
    """Peaks and troughs of one decay.

    Attributes:
        time_s, angle_rad: refined time and angle of each extremum, in time order.
        kind: +1 for a peak, −1 for a trough (they alternate).
        n_used: the first ``n_used`` extrema are above the noise floor and used.
        period_s: the damped period estimated from the spectrum (a first guess).
        quantum_rad: encoder step found in the data (0 if none).
        noise_rad: sample noise (standard deviation) estimated from second differences.
        min_travel_rad: the noise floor that ended the usable part.
    """

    time_s: np.ndarray
    angle_rad: np.ndarray
    kind: np.ndarray
    n_used: int
    period_s: float
    quantum_rad: float
    noise_rad: float
    min_travel_rad: float

    @property
    def used(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(time_s, angle_rad, kind) of the usable extrema."""
        n = self.n_used
        return self.time_s[:n], self.angle_rad[:n], self.kind[:n]

    @property
    def travels_rad(self) -> np.ndarray:
        """Peak-to-trough travels a_j = |e_{j+1} − e_j| of the usable extrema."""
        return np.abs(np.diff(self.angle_rad[: self.n_used]))

    def _in_unit(self, unit: float, *, back: bool = False) -> Extrema:
        """The extrema with every angle divided by ``unit`` (``back``: multiplied)."""
        if unit == 1.0:
            return self
        f = (lambda x: x * unit) if back else (lambda x: x / unit)
        return replace(self, angle_rad=f(self.angle_rad), quantum_rad=f(self.quantum_rad),
                       noise_rad=f(self.noise_rad), min_travel_rad=f(self.min_travel_rad))


#: Angles (or travels) whose largest magnitude lies in this range, in rad, are analysed as
#: they are; others are first divided by a power of two that brings it to 1 … 2 (exact in
#: floating point), and the results multiplied back. Squares of angles 1e155 rad overflow,
#: those of 1e-160 rad underflow, and the spectrum, the regressions' covariances and the fit
#: would silently go wrong.
ANGLE_RANGE_RAD = (2.0**-20, 2.0**20)


def angle_unit(values) -> float:
    """1.0, or the power of two that :data:`ANGLE_RANGE_RAD` asks ``values`` to be divided by."""
    a = np.abs(np.asarray(values, float))
    a = a[np.isfinite(a)]
    top = float(a.max()) if a.size else 0.0
    if top == 0.0 or ANGLE_RANGE_RAD[0] <= top <= ANGLE_RANGE_RAD[1]:
        return 1.0
    return math.ldexp(1.0, math.frexp(top)[1] - 1)


def _quantum(y: np.ndarray) -> float:
    """The encoder step: the typical smallest nonzero change, if many changes are zero."""
    d = np.abs(np.diff(y))
    span = float(np.ptp(y)) or 1.0
    nonzero = d[d > 1e-12 * span]
    if len(nonzero) == 0 or np.mean(d <= 1e-12 * span) < 0.05:
        return 0.0
    smallest = nonzero.min()
    return float(np.median(nonzero[nonzero < 1.5 * smallest]))


def _noise_sd(y: np.ndarray) -> float:
    """Sample noise from the MAD of second differences (σ·√6 for white noise)."""
    if len(y) < 5:
        return 0.0
    d2 = y[2:] - 2.0 * y[1:-1] + y[:-2]
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))


def _period_guess(t: np.ndarray, y: np.ndarray) -> float:
    """Dominant period from the zero-padded periodogram of the (uniformly resampled) signal."""
    n = len(t)
    tu = np.linspace(t[0], t[-1], n)
    yu = np.interp(tu, t, y)
    yu = yu - np.median(yu)
    dt = tu[1] - tu[0]
    nfft = 1 << int(math.ceil(math.log2(8 * n)))
    power = np.abs(np.fft.rfft(yu * np.hanning(n), nfft)) ** 2
    freq = np.fft.rfftfreq(nfft, dt)
    low = 1.5 / (t[-1] - t[0])
    power[freq < low] = 0.0
    f = freq[int(np.argmax(power))]
    return 1.0 / f if f > 0 else math.inf


def _smooth(y: np.ndarray, width: int) -> np.ndarray:
    """Triangular smoothing (a box filter twice), edges padded with the end values."""
    if width <= 1:
        return y
    box = np.ones(width) / width
    pad = width
    z = np.pad(y, pad, mode="edge")
    z = np.convolve(np.convolve(z, box, mode="same"), box, mode="same")
    return z[pad:-pad]


def _refine(t: np.ndarray, y: np.ndarray, t0: float, half: float, kind: int):
    """Vertex of a least-squares parabola through the samples within ±half of t0.

    Fitted twice, the second time centred on the first vertex. Returns (time, angle) or
    None where the window leaves the record or the fit does not curve the right way.
    """
    if t0 - half < t[0] or t0 + half > t[-1]:
        return None
    centre = t0
    for _ in range(2):
        sel = np.abs(t - centre) <= half
        if sel.sum() < 5:
            return None
        tau = (t[sel] - centre) / half
        c2, c1, c0 = np.polyfit(tau, y[sel], 2)
        if kind * c2 >= 0:  # a peak needs a downward parabola
            # Flat top (all samples on one encoder level): the plateau's middle.
            extreme = y[sel].max() if kind > 0 else y[sel].min()
            on = sel & (y == extreme)
            return float(t[on].mean()), float(extreme)
        vertex = -c1 / (2.0 * c2)
        if abs(vertex) > 1.0:
            return None
        new_centre = centre + vertex * half
        value = c0 - c1**2 / (4.0 * c2)
        if new_centre - half < t[0] or new_centre + half > t[-1]:
            return float(new_centre), float(value)
        centre = new_centre
    return float(centre), float(value)


def find_extrema(time_s, angle_rad) -> Extrema:
    """Peaks and troughs of a decay, robust to encoder steps and noise (module docstring).

    Angles of any magnitude are analysed in a unit that keeps them near 1
    (:data:`ANGLE_RANGE_RAD`); the extrema come back in rad.

    Raises:
        NoOscillationError: fewer than :data:`MIN_EXTREMA` usable extrema.
    """
    y = np.asarray(angle_rad, float)
    unit = angle_unit(y)
    return _find_extrema(np.asarray(time_s, float), y / unit, unit)._in_unit(unit, back=True)


def _find_extrema(t: np.ndarray, y: np.ndarray, unit: float) -> Extrema:
    """:func:`find_extrema` on angles ``y`` in ``unit`` rad (``unit`` only for messages)."""
    q = _quantum(y)
    sigma = _noise_sd(y)
    noise = math.hypot(sigma, q / math.sqrt(12.0))
    span = float(np.ptp(y))
    period = _period_guess(t, y)
    if not np.isfinite(period) or span == 0.0:
        raise NoOscillationError("no oscillation found: the angle does not change")
    dt = float(np.median(np.diff(t)))
    samples_per_period = period / dt
    if samples_per_period < 8:
        raise NoOscillationError(
            f"no oscillation found that the sampling resolves: the dominant period "
            f"{period:.3g} s holds only {samples_per_period:.1f} samples (need ≥ 8)"
        )
    ys = _smooth(np.interp(np.linspace(t[0], t[-1], len(t)), t, y),
                 max(1, int(round(samples_per_period / 20))))
    tu = np.linspace(t[0], t[-1], len(t))
    prominence = max(3.0 * noise + q, 1e-9 * span)
    distance = max(1, int(0.7 * samples_per_period))
    peaks, _ = _signal().find_peaks(ys, prominence=prominence, distance=distance)
    troughs, _ = _signal().find_peaks(-ys, prominence=prominence, distance=distance)
    idx = np.concatenate([peaks, troughs])
    kinds = np.concatenate([np.ones(len(peaks), int), -np.ones(len(troughs), int)])
    order = np.argsort(idx)
    idx, kinds = idx[order], kinds[order]

    # Alternate: of two neighbours of one kind keep the more extreme.
    keep_idx: list[int] = []
    keep_kind: list[int] = []
    for i, k in zip(idx, kinds, strict=True):
        if keep_kind and keep_kind[-1] == k:
            if k * ys[i] > k * ys[keep_idx[-1]]:
                keep_idx[-1] = i
            continue
        keep_idx.append(int(i))
        keep_kind.append(int(k))

    half = period / 8.0
    times, values, kinds_out = [], [], []
    for i, k in zip(keep_idx, keep_kind, strict=True):
        refined = _refine(t, y, float(tu[i]), half, k)
        if refined is None:
            if times:  # a gap in the middle would break the alternation: stop here
                break
            continue
        times.append(refined[0])
        values.append(refined[1])
        kinds_out.append(k)
    times_a, values_a = np.asarray(times), np.asarray(values)
    kinds_a = np.asarray(kinds_out, int)

    min_travel = max(MIN_TRAVEL_STEPS * q, MIN_TRAVEL_NOISE * sigma, 1e-9 * span)
    travels = np.abs(np.diff(values_a))
    below = np.nonzero(travels < min_travel)[0]
    n_used = int(below[0]) + 1 if len(below) else len(values_a)
    if n_used < MIN_EXTREMA:
        raise NoOscillationError(
            f"no oscillation found: {n_used} peak(s)/trough(s) with a travel above the noise "
            f"floor {min_travel * unit:.3g} rad (encoder step {q * unit:.3g} rad, noise "
            f"{sigma * unit:.3g} rad); need at least {MIN_EXTREMA}"
        )
    return Extrema(times_a, values_a, kinds_a, n_used, float(period), q, sigma, min_travel)


# --------------------------------------------------------------------------------------
# Regressions
# --------------------------------------------------------------------------------------


def _t(dof: float) -> float:
    return float(t_critical(dof, LEVEL))


def _slope(xs: list[np.ndarray], ys: list[np.ndarray], ws: list[np.ndarray] | None = None):
    """Common slope of y on x with one intercept per group (weighted least squares).

    Returns (slope, standard error, dof, intercepts). With one group this is the ordinary
    straight-line fit.
    """
    if ws is None:
        ws = [np.ones_like(x) for x in xs]
    sxx = sxy = 0.0
    centred = []
    for x, y, w in zip(xs, ys, ws, strict=True):
        xm, ym = np.average(x, weights=w), np.average(y, weights=w)
        centred.append((x - xm, y - ym, w, xm, ym))
        sxx += float(np.sum(w * (x - xm) ** 2))
        sxy += float(np.sum(w * (x - xm) * (y - ym)))
    if sxx <= 0:
        return math.nan, math.nan, 0, [math.nan] * len(xs)
    b = sxy / sxx
    sse = sum(float(np.sum(w * (yc - b * xc) ** 2)) for xc, yc, w, _, _ in centred)
    n = sum(len(x) for x in xs)
    dof = n - len(xs) - 1
    se = math.sqrt(sse / dof / sxx) if dof > 0 else math.nan
    return b, se, dof, [ym - b * xm for _, _, _, xm, ym in centred]


def _gls(x: np.ndarray, y: np.ndarray, v: np.ndarray):
    """Generalised least squares y = x·β + e, Cov(e) = σ²·V with V known and σ² estimated.

    Returns (β, Cov(β̂), dof) with Cov(β̂) = s²·(XᵀV⁻¹X)⁻¹, s² = rᵀV⁻¹r/(n − p).
    """
    n, p = x.shape
    dof = n - p
    nothing = np.full(p, math.nan), np.full((p, p), math.nan), dof
    if dof < 1:
        return nothing
    try:
        chol = np.linalg.cholesky(v)
        xw = scipy.linalg.solve_triangular(chol, x, lower=True)
        yw = scipy.linalg.solve_triangular(chol, y, lower=True)
    except np.linalg.LinAlgError:  # V not positive definite
        return nothing
    inv, _, full_rank = unscaled_covariance(xw)
    if not full_rank:  # a design the rank criterion cannot resolve
        return nothing
    coef, *_ = np.linalg.lstsq(xw, yw, rcond=None)
    r = yw - xw @ coef
    return coef, float(r @ r) / dof * inv, dof


def _travel_cov(a: np.ndarray) -> np.ndarray:
    """Covariance (up to σ²) of the travels a_j = |e_{j+1} − e_j| when every extremum e_j
    carries an independent error of variance σ²: 2 on the diagonal and +1 beside it, since
    two neighbouring travels share an extremum and both grow when it moves outwards."""
    n = len(a)
    return 2.0 * np.eye(n) + np.eye(n, k=1) + np.eye(n, k=-1)


def _log_travel_cov(a: np.ndarray) -> np.ndarray:
    """Covariance (up to σ²) of ln a_j: the travel covariance divided by a_j·a_k."""
    return _travel_cov(a) / np.outer(a, a)


def _block(mats: list[np.ndarray]) -> np.ndarray:
    return scipy.linalg.block_diag(*mats) if len(mats) > 1 else mats[0]


def _trial_design(columns: list[np.ndarray]) -> np.ndarray:
    """Design with one intercept per trial and a common slope on ``columns[i]``."""
    n = sum(len(c) for c in columns)
    x = np.zeros((n, len(columns) + 1))
    start = 0
    for i, c in enumerate(columns):
        x[start:start + len(c), i] = 1.0
        x[start:start + len(c), -1] = c
        start += len(c)
    return x


def _common_slope_gls(columns, ys, covs):
    """Common slope (per-trial intercepts) by GLS: (slope, se, dof)."""
    coef, cov, dof = _gls(_trial_design(columns), np.concatenate(ys), _block(covs))
    return float(coef[-1]), math.sqrt(max(float(cov[-1, -1]), 0.0)), dof


def _interval(value, se, dof):
    return [float(b) for b in wald_interval(value, se, dof, LEVEL)]


def _log_interval(value, rel_se, dof):
    """Interval exp(ln v ± t·se(ln v)) for a positive quantity."""
    t = _t(dof)
    if not (value > 0) or not np.isfinite(rel_se):
        return [math.nan, math.nan]
    return [value * math.exp(-t * rel_se), value * math.exp(t * rel_se)]


def _settle_intervals(out: dict, reasons: dict | None = None) -> dict:
    """Make every ``<name>_ci95`` of ``out`` honest, in place; returns the notes.

    An interval is kept when it is finite, ordered and contains its estimate ``out[name]``;
    otherwise it becomes None and the note (``reasons[key]``, or what is wrong with it)
    says why, keyed by the interval's name.
    """
    notes = {}
    for key in [k for k in out if k.endswith("_ci95") and k[:-5] in out]:
        value, ci = out[key[:-5]], out[key]
        if ci is None:
            why = "no interval"
        elif value is None or not np.isfinite(value):
            why = "no estimate"
        elif not all(x is not None and np.isfinite(x) for x in ci):
            why = "no finite standard error (too few points, or a singular regression)"
        elif not ci[0] <= value <= ci[1]:
            why = f"[{ci[0]:.6g}, {ci[1]:.6g}] is not ordered around the estimate {value:.6g}"
        else:
            out[key] = [float(ci[0]), float(ci[1])]
            continue
        out[key] = None
        notes[key] = (reasons or {}).get(key, why)
    return notes


def _equilibrium(values: np.ndarray) -> float:
    """β_eq from e_{j+1} = α + β·e_j: the fixed point α/(1 − β) (β ≈ −r)."""
    if len(values) < 3:
        return float(np.mean(values))
    beta, alpha = np.polyfit(values[:-1], values[1:], 1)
    return float(alpha / (1.0 - beta))


# --------------------------------------------------------------------------------------
# Logarithmic decrement
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DecrementEstimate:
    """Logarithmic-decrement estimates of one trial (or pooled over trials).

    Every ``*_ci95`` is a 95 % interval [low, high]; see the module docstring for how each is
    made. Frequencies in Hz, stiffness in N·m/rad, damping in N·m·s/rad.
    """

    n_extrema: int
    n_travels: int
    log_decrement: float  # eq. 9, regression over every travel (per cycle)
    log_decrement_ci95: list
    log_decrement_eq9_endpoints: float  # eq. 9 as printed: 2/(n−1)·ln(a1/an)
    log_decrement_eq8: float  # eq. 8, regression of ln|e − β_eq| (per cycle)
    log_decrement_eq8_ci95: list
    log_decrement_eq8_endpoints: float  # eq. 8 on the peaks: ln(x1/xn)/(n−1)
    equilibrium_rad: float
    zeta: float
    zeta_ci95: list
    frequency_Hz: float  # damped, from the extremum times
    frequency_Hz_ci95: list
    natural_frequency_Hz: float
    natural_frequency_Hz_ci95: list
    stiffness_Nm_per_rad: float
    stiffness_Nm_per_rad_ci95: list
    damping_Nms_per_rad: float
    damping_Nms_per_rad_ci95: list
    amplitude_dependence: dict = field(default_factory=dict)
    #: Why an interval is None (the interval's name → the reason).
    interval_notes: dict = field(default_factory=dict)

    @property
    def grows(self) -> bool:
        """The oscillation grows: δ and its whole 95 % interval lie below 0 (negative
        damping), and the decay model does not apply."""
        ci = self.log_decrement_ci95
        return bool(self.log_decrement < 0 and (ci is None or ci[1] < 0))

    @property
    def stability(self) -> str:
        """One line on whether the oscillation decays (what the decay model needs)."""
        delta = self.log_decrement
        if self.grows:
            return (f"the oscillation grows: the decay model does not apply (negative "
                    f"damping, δ = {delta:.4g}, ζ = {self.zeta:.4g} < 0)")
        if delta < 0:
            lo, hi = self.log_decrement_ci95
            return (f"no damping resolved: δ = {delta:.4g}, its 95 % interval "
                    f"[{lo:.4g}, {hi:.4g}] contains 0")
        return "decays"

    def _times_unit(self, unit: float) -> DecrementEstimate:
        """The estimate of travels measured in ``unit`` rad, in rad."""
        if unit == 1.0:
            return self
        amp = dict(self.amplitude_dependence)
        for key, power in _AMPLITUDE_ANGLE_POWER.items():
            if amp.get(key) is not None:
                value = amp[key]
                f = unit if power > 0 else 1.0 / unit
                amp[key] = [v * f for v in value] if isinstance(value, list) else value * f
        return replace(self, equilibrium_rad=self.equilibrium_rad * unit,
                       amplitude_dependence=amp)

    def to_dict(self) -> dict:
        out = {k: _plain(v) for k, v in self.__dict__.items()}
        out["stable"] = not self.grows
        out["stability"] = self.stability
        return out


#: The angle dimension of the amplitude-dependence results (+1: rad, −1: per rad).
_AMPLITUDE_ANGLE_POWER = {"slope_per_rad": -1, "slope_per_rad_ci95": -1, "coulomb_Nm": 1,
                          "coulomb_Nm_ci95": 1, "coulomb_shift_rad": 1,
                          "resolution_floor_rad": 1}


def _derived(delta, delta_se, delta_dof, half_period, half_period_se, time_dof, inertia):
    """ζ, f_d, f_n, k, c with intervals from δ and the half period (module docstring).

    Returns the values, their intervals and ``interval_notes`` (why an interval is None).
    """
    zeta = log_decrement_to_zeta(delta)
    lo, hi = _interval(delta, delta_se, delta_dof)
    zeta_ci = [log_decrement_to_zeta(lo), log_decrement_to_zeta(hi)]  # eq. 10 is monotone
    zeta_se = 4.0 * math.pi**2 / (4.0 * math.pi**2 + delta**2) ** 1.5 * delta_se
    f_d = 1.0 / (2.0 * half_period)
    rel_f = half_period_se / half_period  # se of ln f_d
    t_lo, t_hi = _interval(half_period, half_period_se, time_dof)
    reasons = {}
    if t_lo > 0:
        f_ci = [1.0 / (2.0 * t_hi), 1.0 / (2.0 * t_lo)]
    else:
        f_ci = None
        reasons["frequency_Hz_ci95"] = ("the half period's interval reaches 0 s, so the "
                                        "frequency's has no upper end")
    f_n = f_d / math.sqrt(1.0 - zeta**2)
    rel_fn = math.hypot(rel_f, zeta / (1.0 - zeta**2) * zeta_se)
    dof = min(delta_dof, time_dof)
    omega_n = 2.0 * math.pi * f_n
    k = inertia * omega_n**2
    c = 2.0 * zeta * inertia * omega_n  # Cullinan eq. 11, c = 2·ζ·√(k·J) with k = J·ω_n²
    if c > 0:
        rel_c = math.hypot((1.0 / zeta + zeta / (1.0 - zeta**2)) * zeta_se, rel_f)
        c_ci = _log_interval(c, rel_c, dof)
    else:  # no positive damping: on the linear scale, d c = 2·J·(ω_n·dζ + ζ·dω_n)
        c_se = 2.0 * inertia * omega_n * math.hypot(zeta_se, zeta * rel_fn)
        c_ci = _interval(c, c_se, dof)
    out = {
        "zeta": zeta,
        "zeta_ci95": zeta_ci,
        "frequency_Hz": f_d,
        "frequency_Hz_ci95": f_ci,
        "natural_frequency_Hz": f_n,
        "natural_frequency_Hz_ci95": _log_interval(f_n, rel_fn, dof),
        "stiffness_Nm_per_rad": k,
        "stiffness_Nm_per_rad_ci95": _log_interval(k, 2.0 * rel_fn, dof),
        "damping_Nms_per_rad": c,
        "damping_Nms_per_rad_ci95": c_ci,
    }
    out["interval_notes"] = _settle_intervals(out, reasons)
    return out


def _amplitude_dependence(travel_lists, stiffness, quantum_rad=0.0):
    """Tests for a decrement that changes with amplitude, and the Coulomb torque (docstring).

    ``quantum_rad`` is the encoder step: an effect smaller than :data:`RESOLUTION_STEPS`
    of it per half cycle is not significant in practice, whatever its p-value.

    Every regression is generalised least squares with the error covariance that follows
    from independent errors of the extrema (:func:`_travel_cov`), so that neighbouring
    travels, which share an extremum, are not counted as independent.
    """
    usable = [a for a in travel_lists if len(a) >= 3]
    if not usable or sum(len(a) - 1 for a in usable) - len(usable) - 1 < 1:
        return {"amplitude_dependent": None, "note": "too few travels to test"}
    out: dict = {}
    # (1) δ_j = 2·ln(a_j/a_{j+1}) against the amplitude (a_j + a_{j+1})/4.
    amps, deltas, covs = [], [], []
    for a in usable:
        diff = np.eye(len(a) - 1, len(a)) - np.eye(len(a) - 1, len(a), k=1)
        deltas.append(2.0 * diff @ np.log(a))
        amps.append((a[:-1] + a[1:]) / 4.0)
        covs.append(4.0 * diff @ _log_travel_cov(a) @ diff.T)
    slope, se, dof = _common_slope_gls(amps, deltas, covs)
    tval = slope / se if se > 0 else math.nan
    p = float(2.0 * _stats().t.sf(abs(tval), dof)) if np.isfinite(tval) else math.nan
    out.update(slope_per_rad=slope, slope_per_rad_ci95=_interval(slope, se, dof),
               slope_p_value=p)
    # (2) δ of the early and of the late half of the travels.
    halves = [(a[: len(a) // 2], a[len(a) // 2:]) for a in usable
              if len(a) // 2 >= 3 and len(a) - len(a) // 2 >= 3]
    if halves:
        fits = []
        for part in zip(*halves, strict=True):
            b, sb, db = _common_slope_gls([np.arange(len(a), dtype=float) for a in part],
                                          [np.log(a) for a in part],
                                          [_log_travel_cov(a) for a in part])
            fits.append((-2.0 * b, 2.0 * sb, db))
        (d1, s1, n1), (d2, s2, n2) = fits
        z = (d2 - d1) / math.hypot(s1, s2)
        p_el = float(2.0 * _stats().t.sf(abs(z), min(n1, n2))) if np.isfinite(z) else math.nan
        out.update(log_decrement_early=d1, log_decrement_early_ci95=_interval(d1, s1, n1),
                   log_decrement_late=d2, log_decrement_late_ci95=_interval(d2, s2, n2),
                   early_late_p_value=p_el)
    else:
        out.update(log_decrement_early=None, log_decrement_late=None, early_late_p_value=None)
    # (3) Viscous + Coulomb half-cycle map a_{j+1} = r·a_j + b with b = −2·(1 + r)·T_c/k.
    x = np.concatenate([a[:-1] for a in usable])
    y = np.concatenate([a[1:] for a in usable])
    design = np.column_stack([x, np.ones_like(x)])
    r0 = float(np.linalg.lstsq(design, y, rcond=None)[0][0])
    covs = []
    for a in usable:
        lag = -r0 * np.eye(len(a) - 1, len(a)) + np.eye(len(a) - 1, len(a), k=1)
        covs.append(lag @ _travel_cov(a) @ lag.T)
    coef, cov, dof_m = _gls(design, y, _block(covs))
    r, b = float(coef[0]), float(coef[1])
    tc = -b * stiffness / (2.0 * (1.0 + r))
    grad = np.array([b / (2.0 * (1.0 + r) ** 2), -1.0 / (2.0 * (1.0 + r))])  # of T_c / k
    tc_se = abs(stiffness) * math.sqrt(max(float(grad @ cov @ grad), 0.0))
    delta_v = -2.0 * math.log(r) if r > 0 else math.nan
    t_b = b / math.sqrt(cov[1, 1]) if cov[1, 1] > 0 else math.nan
    p_tc = float(2.0 * _stats().t.sf(abs(t_b), dof_m)) if np.isfinite(t_b) else math.nan
    out.update(coulomb_Nm=tc, coulomb_Nm_ci95=_interval(tc, tc_se, dof_m),
               coulomb_p_value=p_tc, log_decrement_viscous=delta_v,
               zeta_viscous=log_decrement_to_zeta(delta_v) if np.isfinite(delta_v)
               else math.nan)
    # One decision from the three tests, Bonferroni-corrected to a 1 % family-wise level.
    ps = [v for v in (p, out.get("early_late_p_value"), p_tc)
          if v is not None and np.isfinite(v)]
    p_min = min(ps) * len(ps) if ps else math.nan
    out["p_value_bonferroni"] = min(p_min, 1.0) if ps else math.nan
    statistically = bool(ps and p_min < 0.01)
    floor = RESOLUTION_STEPS * float(quantum_rad)
    shift = abs(b)
    practically = bool(np.isfinite(shift) and shift > floor)
    out.update(coulomb_shift_rad=shift, resolution_floor_rad=floor,
               statistically_significant=statistically, practically_significant=practically)
    out["amplitude_dependent"] = statistically and practically
    notes = _settle_intervals(out)
    if notes:
        out["interval_notes"] = notes
    if not statistically:
        out["note"] = "no significant change of the decrement with amplitude (p ≥ 0.01)"
    elif not practically:
        out["note"] = (f"a change of the decrement with amplitude is statistically significant "
                       f"(p = {out['p_value_bonferroni']:.2g}) but its amplitude loss per half "
                       f"cycle, {shift:.2g} rad, is below half an encoder step ({floor:.2g} "
                       "rad), within what quantization can produce: not called friction")
    elif tc > 0 or slope < 0:
        out["note"] = ("the decrement grows as the amplitude falls: Coulomb (dry) friction, "
                       "which the viscous model lacks")
    else:
        out["note"] = "the decrement changes with the amplitude"
    return out


def pooled_decrement_estimate(extrema: list[Extrema], inertia_kg_m2: float) -> DecrementEstimate:
    """Decrement estimates from one or more trials (common slopes, per-trial intercepts).

    Travels of any magnitude are regressed in a unit that keeps them near 1
    (:data:`ANGLE_RANGE_RAD`); the estimates come back in rad. An oscillation that grows
    (:attr:`DecrementEstimate.grows`) is not tested for amplitude dependence.
    """
    unit = angle_unit(np.concatenate([e.travels_rad for e in extrema]))
    estimate = _pooled_decrement_estimate([e._in_unit(unit) for e in extrema], inertia_kg_m2)
    return estimate._times_unit(unit)


def _pooled_decrement_estimate(extrema: list[Extrema], inertia_kg_m2: float):
    travels = [e.travels_rad for e in extrema]
    idx = [np.arange(len(a), dtype=float) for a in travels]
    slope, se, dof = _common_slope_gls(idx, [np.log(a) for a in travels],
                                       [_log_travel_cov(a) for a in travels])
    delta, delta_se = -2.0 * slope, 2.0 * se
    ci = [-2.0 * v for v in _interval(slope, se, dof)[::-1]]

    eq8, eq8_ends, eqs = [], [], []
    amp_idx, amp_log = [], []
    for e in extrema:
        _, values, kinds = e.used
        beq = _equilibrium(values)
        eqs.append(beq)
        x = np.abs(values - beq)
        amp_idx.append(np.arange(len(x), dtype=float))
        amp_log.append(np.log(np.maximum(x, 1e-300)))
        peaks = x[kinds == kinds[0]]
        if len(peaks) >= 2:
            eq8_ends.append(math.log(peaks[0] / peaks[-1]) / (len(peaks) - 1))
    # ln|e_j − β_eq| has error ε_j/x_j: weights x_j² (β_eq's own error is not propagated).
    s8, se8, dof8, _ = _slope(amp_idx, amp_log, [np.exp(2.0 * y) for y in amp_log])
    eq8 = -2.0 * s8
    ci8 = [-2.0 * v for v in _interval(s8, se8, dof8)[::-1]]
    ends9 = [2.0 / (len(a) - 1) * math.log(a[0] / a[-1]) for a in travels if len(a) >= 2]

    times = [e.used[0] for e in extrema]
    hslope, hse, hdof, _ = _slope([np.arange(len(t), dtype=float) for t in times], times)
    derived = _derived(delta, delta_se, dof, hslope, hse, hdof, inertia_kg_m2)
    notes = derived.pop("interval_notes")
    decrement = {"log_decrement": delta, "log_decrement_ci95": ci,
                 "log_decrement_eq8": eq8, "log_decrement_eq8_ci95": ci8}
    notes.update(_settle_intervals(decrement))
    estimate = DecrementEstimate(
        n_extrema=int(sum(e.n_used for e in extrema)),
        n_travels=int(sum(len(a) for a in travels)),
        log_decrement_eq9_endpoints=float(np.mean(ends9)) if ends9 else math.nan,
        log_decrement_eq8_endpoints=float(np.mean(eq8_ends)) if eq8_ends else math.nan,
        equilibrium_rad=float(np.mean(eqs)),
        interval_notes=notes,
        **decrement,
        **derived,
    )
    if estimate.grows:
        amp = {"amplitude_dependent": None, "note": "not tested: the oscillation grows"}
    else:
        quantum = max((e.quantum_rad for e in extrema), default=0.0)
        amp = _amplitude_dependence(travels, derived["stiffness_Nm_per_rad"], quantum)
    return replace(estimate, amplitude_dependence=amp)


def decrement_estimate(time_s, angle_rad, inertia_kg_m2: float) -> DecrementEstimate:
    """Logarithmic-decrement estimates of one decay (Cullinan eq. 8–11)."""
    return pooled_decrement_estimate([find_extrema(time_s, angle_rad)], inertia_kg_m2)


# --------------------------------------------------------------------------------------
# Trajectory fit
# --------------------------------------------------------------------------------------

FIT_NAMES = ("zeta", "omega_n_rad_s", "angle0_rad", "rate0_rad_s", "equilibrium_rad")


def _model_angle(theta, t):
    zeta, omega, angle0, rate0, eq = theta
    osc = DampedOscillator(1.0, omega**2, 2.0 * zeta * omega, eq)  # J cancels out
    return oscillator_response(osc, angle0, rate0, t)[0]


@dataclass(frozen=True, eq=False, kw_only=True)
class Trajectory(ModelSpec):
    """The linear damped oscillator's free response as a model: ``theta`` = :data:`FIT_NAMES`,
    ``x`` = (time since the window's start, s,). What a free decay's effects wrap
    (:class:`pamid._effects._coulomb_friction.CoulombFriction`,
    :class:`pamid._effects._drift.DecayDrift`): they read its modal constants, its state at
    t = 0 and its closed form about the centre."""

    def predict(self, theta, x):
        return _model_angle(theta, x[0])

    @staticmethod
    def modal(theta):
        """(σ, ω_n²) = (ζ·ω_n, ω_n²) (Cullinan eq. 11)."""
        return theta[0] * theta[1], theta[1] ** 2

    @staticmethod
    def state0(theta):
        """(β_eq, the displacement β(0) − β_eq, the rate β̇(0))."""
        return theta[4], theta[2] - theta[4], theta[3]

    @staticmethod
    def segment(sigma, wn2, x0, v0, s):
        """The displacement s after a start (x0, v0) about the centre: the closed form of
        :func:`pamid._sim._oscillator.oscillator_response`, any damping."""
        c, sn = cos_sinc(wn2 - sigma**2, s)
        return jnp.exp(-sigma * s) * (x0 * c + (v0 + sigma * x0) * sn)


#: The trajectory fit's model, in constants divided by each lane's scale.
TRAJECTORY = scaled(Trajectory(
    name="trajectory", param_names=FIT_NAMES,
    param_units={"zeta": "1", "omega_n_rad_s": "rad/s", "angle0_rad": "rad",
                 "rate0_rad_s": "rad/s", "equilibrium_rad": "rad"},
    units={"angle": "rad", "time": "s"}, columns=("time_s",),
    source="J·β̈ + c·β̇ + k·(β − β_eq) = 0, free response (Cullinan section VI)",
    output=("angle", "rad")))


def _fit_batch(p0, scale, t, y, w, max_steps):
    """Every window's trajectory fit (one lane each) through pamid's one least-squares
    entry, by its own Levenberg–Marquardt: stops where a step would lower the SSE by at most
    1e-12 of itself plus (1e-12 rad)² per sample. Returns the constants (unscaled), the
    weighted residual, its Jacobian (in the scaled constants), convergence and steps."""
    data = FitData(x=(t, scale), y=y, w=w, curve=np.zeros(np.shape(t), np.int32))
    sol = least_squares(TRAJECTORY, data, solver=ProjectedLevenbergMarquardt(
        rtol=1e-12, floor_per_sample=1e-24), theta0=p0, max_steps=max_steps,
        outputs=("jacobian",))
    return sol.params * scale, sol.residual, sol.jac, sol.converged, sol.steps


@dataclass(frozen=True)
class TrajectoryFit:
    """Linear damped oscillator fitted to the samples of one trial (or pooled).

    ``params`` holds ζ, ω_n (rad/s), the angle and rate at ``t0_s`` (the first usable
    extremum) and β_eq; ``derived`` the quantities of the decrement report with Wald
    intervals (delta method).
    """

    params: dict
    params_ci95: dict
    derived: dict
    converged: bool
    n_steps: int
    n_samples: int
    rmse_rad: float
    t0_s: float
    t1_s: float

    def to_dict(self) -> dict:
        return _plain({**self.derived, "params": self.params, "params_ci95": self.params_ci95,
                       "converged": self.converged, "n_steps": self.n_steps,
                       "n_samples": self.n_samples, "rmse_rad": self.rmse_rad,
                       "window_s": [self.t0_s, self.t1_s]})


def _fit_derived(theta, cov, dof, inertia):
    """The decrement report's quantities from the fitted ζ and ω_n, with Wald intervals
    (delta method) and ``interval_notes``. k and c scale with J: their standard errors are
    taken per unit J and multiplied back, so that no J overflows a square."""
    zeta, omega = float(theta[0]), float(theta[1])
    t = _t(dof)
    two_pi = 2.0 * math.pi
    under = abs(zeta) < 1.0  # a damped oscillation; none when overdamped
    sq = math.sqrt(1.0 - zeta**2) if under else math.nan
    grads = {
        "log_decrement": (two_pi / sq**3, 0.0),
        "zeta": (1.0, 0.0),
        "frequency_Hz": (-omega * zeta / (two_pi * sq), sq / two_pi),
        "natural_frequency_Hz": (0.0, 1.0 / two_pi),
        "stiffness_Nm_per_rad": (0.0, 2.0 * omega),  # per unit J
        "damping_Nms_per_rad": (2.0 * omega, 2.0 * zeta),  # per unit J
    }
    values = {
        "log_decrement": two_pi * zeta / sq,
        "zeta": zeta,
        "frequency_Hz": omega * sq / two_pi,
        "natural_frequency_Hz": omega / two_pi,
        "stiffness_Nm_per_rad": inertia * omega**2,
        "damping_Nms_per_rad": 2.0 * zeta * inertia * omega,  # Cullinan eq. 11
    }
    c2 = np.asarray(cov)[:2, :2]
    out = {}
    for name, g in grads.items():
        g = np.asarray(g)
        se = math.sqrt(max(float(g @ c2 @ g), 0.0)) if np.all(np.isfinite(g)) else math.nan
        if name in ("stiffness_Nm_per_rad", "damping_Nms_per_rad"):
            se *= inertia
        out[name] = values[name]
        out[name + "_se"] = se
        out[name + "_ci95"] = [values[name] - t * se, values[name] + t * se]
    reasons = {} if under else {
        key: f"|ζ| = {abs(zeta):.4g} ≥ 1: overdamped, no damped oscillation"
        for key in ("log_decrement_ci95", "frequency_Hz_ci95")}
    out["interval_notes"] = _settle_intervals(out, reasons)
    return out


def fit_decay_trajectories(
    times: list[np.ndarray],
    angles: list[np.ndarray],
    extrema: list[Extrema],
    starts: list[DecrementEstimate],
    inertia_kg_m2: float,
    *,
    max_steps: int = 200,
) -> list[TrajectoryFit]:
    """Fit J·β̈ + c·β̇ + k·(β − β_eq) = 0 to every trial at once (module docstring).

    Each trial is fitted from its first to its last usable extremum, started from its
    decrement estimates; trials are padded to one length (zero weight) and solved in one
    vmapped Levenberg–Marquardt call.
    """
    windows, p0s, scales, units, centres = [], [], [], [], []
    for t, y, e, s in zip(times, angles, extrema, starts, strict=True):
        te, ve, _ = e.used
        sel = (t >= te[0]) & (t <= te[-1])
        # Fitted about the decrement's equilibrium, in a unit that keeps the deviations near
        # 1: a decay of 1e-12 rad about 1 rad, or of 1e155 rad, is fitted as one of 0.1 rad.
        centre = s.equilibrium_rad if np.isfinite(s.equilibrium_rad) else 0.0
        unit = angle_unit(y[sel] - centre)
        units.append(unit)
        centres.append(centre)
        windows.append((t[sel] - te[0], (y[sel] - centre) / unit))
        omega = 2.0 * math.pi * s.natural_frequency_Hz
        angle0 = (ve[0] - centre) / unit
        amp = abs(angle0) or 1.0
        p0s.append([s.zeta, omega, angle0, 0.0, 0.0])
        scales.append([max(abs(s.zeta), 1e-3), omega, amp, amp * omega, amp])
    # Padded to a multiple of 512 samples, so that records of similar length share one
    # compiled solve (in a session and in the persistent compilation cache).
    n_max = 512 * -(-max(len(w[0]) for w in windows) // 512)
    tt = np.zeros((len(windows), n_max))
    yy = np.zeros_like(tt)
    ww = np.zeros_like(tt)
    for i, (t, y) in enumerate(windows):
        tt[i, : len(t)], yy[i, : len(y)], ww[i, : len(t)] = t, y, 1.0
        tt[i, len(t):] = t[-1]
    scale = np.asarray(scales, float)
    p0 = np.asarray(p0s, float) / scale
    theta, res, jac, ok, steps = _fit_batch(p0, scale, tt, yy, ww, max_steps)
    theta, res, jac = np.asarray(theta), np.asarray(res), np.asarray(jac)
    fits = []
    n_par = len(FIT_NAMES)
    for i, (t, _) in enumerate(windows):
        n = len(t)
        dof = n - n_par
        sse = float(np.sum(res[i] ** 2))
        cov_scaled, _ = covariance(jac[i], sse, dof)  # NaN where J is rank-deficient
        cov = cov_scaled * np.outer(scale[i], scale[i])
        in_rad = units[i] ** _FIT_ANGLE_POWER  # back from the fit's unit (exact: 2^k)
        se = np.sqrt(np.maximum(np.diag(cov), 0.0)) * in_rad
        tq = _t(dof)
        params = dict(zip(FIT_NAMES, (theta[i] * in_rad + centres[i] * _FIT_ANGLE_OFFSET)
                          .tolist(), strict=True))
        cis = {k: [v - tq * s, v + tq * s] for (k, v), s in zip(params.items(), se, strict=True)}
        notes = _settle_intervals({**params, **{k + "_ci95": v for k, v in cis.items()}})
        cis = {k: None if k + "_ci95" in notes else v for k, v in cis.items()}
        derived = _fit_derived(theta[i], cov, dof, inertia_kg_m2)
        derived["interval_notes"].update(
            {f"params_ci95.{k[:-5]}": why for k, why in notes.items()})
        te = extrema[i].used[0]
        fits.append(TrajectoryFit(
            params=params, params_ci95=cis, derived=derived,
            converged=bool(ok[i]), n_steps=int(steps[i]), n_samples=n,
            rmse_rad=math.sqrt(sse / n) * units[i], t0_s=float(te[0]), t1_s=float(te[-1]),
        ))
    return fits


#: The angle dimension of each of :data:`FIT_NAMES` (ζ and ω_n have none) …
_FIT_ANGLE_POWER = np.array([0.0, 0.0, 1.0, 1.0, 1.0])
#: … and which of them are angles measured from the centre of the fit (β(t0) and β_eq).
_FIT_ANGLE_OFFSET = np.array([0.0, 0.0, 1.0, 0.0, 1.0])


def pooled_fit(fits: list[TrajectoryFit]) -> dict:
    """Inverse-variance weighted means of the fitted quantities over trials (fixed effect)."""
    out = {}
    for name in ("log_decrement", "zeta", "frequency_Hz", "natural_frequency_Hz",
                 "stiffness_Nm_per_rad", "damping_Nms_per_rad"):
        v = np.array([f.derived[name] for f in fits])
        se = np.array([f.derived[name + "_se"] for f in fits])
        ok = np.isfinite(v) & np.isfinite(se) & (se > 0)
        if not ok.any():
            out[name], out[name + "_ci95"] = math.nan, None
            continue
        smallest = float(se[ok].min())
        w = (smallest / se[ok]) ** 2  # 1/se², relative to the smallest: no se² overflows
        mean = float(np.sum(w * v[ok]) / np.sum(w))
        s = smallest / math.sqrt(float(np.sum(w)))
        z = float(_stats().norm.ppf(0.5 + LEVEL / 2))
        out[name], out[name + "_ci95"] = mean, [mean - z * s, mean + z * s]
    out["interval_notes"] = _settle_intervals(out)
    out["converged"] = all(f.converged for f in fits)
    return out


# --------------------------------------------------------------------------------------
# A whole decay file
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DecayReport:
    """Everything :func:`analyze_decays` finds; :meth:`to_dict` is the CLI's JSON."""

    source: str
    inertia_kg_m2: float
    trials: tuple[str, ...]
    extrema: list[Extrema]
    decrement: list[DecrementEstimate]
    pooled: DecrementEstimate
    fits: list[TrajectoryFit] | None
    pooled_fit: dict | None
    n_samples: list[int]

    @property
    def growing_trials(self) -> list[str]:
        """Trials whose oscillation grows (:attr:`DecrementEstimate.grows`)."""
        return [t for t, d in zip(self.trials, self.decrement, strict=True) if d.grows]

    @property
    def stable(self) -> bool:
        """No trial, and not the pooled estimate, grows: the decay model applies."""
        return not self.growing_trials and not self.pooled.grows

    def to_dict(self) -> dict:
        trials = []
        for i, trial in enumerate(self.trials):
            e = self.extrema[i]
            row = {"trial": trial, "n_samples": self.n_samples[i],
                   "n_extrema_detected": len(e.angle_rad),
                   "encoder_step_rad": e.quantum_rad, "noise_rad": e.noise_rad,
                   "min_travel_rad": e.min_travel_rad, **self.decrement[i].to_dict()}
            if self.fits is not None:
                row["trajectory_fit"] = self.fits[i].to_dict()
            trials.append(_plain(row))
        out = {"source": self.source, "inertia_kg_m2": self.inertia_kg_m2,
               "n_trials": len(self.trials), "stable": self.stable,
               "growing_trials": self.growing_trials, "trials": trials,
               "pooled": self.pooled.to_dict()}
        if self.pooled_fit is not None:
            out["pooled"]["trajectory_fit"] = _plain(self.pooled_fit)
        return out


def check_inertia(inertia_kg_m2, name: str = "the moment of inertia J") -> float:
    """``inertia_kg_m2`` if it is a positive finite number, else ValueError naming ``name``
    and the value (an option name such as ``--inertia`` in the commands)."""
    value = inertia_kg_m2
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not (
            math.isfinite(value) and value > 0):
        shown = "nan (not a number)" if isinstance(value, float) and math.isnan(value) else (
            f"{value:g}" if isinstance(value, (int, float)) else repr(value))
        raise ValueError(f"{name} must be positive (> 0 kg·m²), got {shown}")
    return float(value)


def analyze_decays(data, inertia_kg_m2: float, *, fit: bool = True) -> DecayReport:
    """Decrement estimates per trial and pooled, and (``fit=True``) the trajectory fits.

    ``data`` is a :class:`pamid._data._decay_file.DecayData`. A trial without a usable
    oscillation raises :class:`~pamid.BenchDataError` naming the file, the angle column and
    the trial's first row.
    """
    check_inertia(inertia_kg_m2)
    times, angles, extrema, estimates, counts = [], [], [], [], []
    for trial in data.trials:
        t, y = data.arrays(trial)
        try:
            e = find_extrema(t, y)
        except NoOscillationError as exc:
            first_row = int(data.for_trial(trial)["source_row"].iloc[0])
            whose = f"trial '{trial}': " if data.has_trial_column else ""
            raise BenchDataError(data.path, f"{whose}{exc}", column=data.angle_column,
                                 row=first_row) from None
        times.append(t)
        angles.append(y)
        extrema.append(e)
        counts.append(len(t))
        estimates.append(pooled_decrement_estimate([e], inertia_kg_m2))
    pooled = pooled_decrement_estimate(extrema, inertia_kg_m2)
    for trial, est in zip(data.trials, estimates, strict=True):
        if not (math.isfinite(est.stiffness_Nm_per_rad) and math.isfinite(est.frequency_Hz)):
            raise ValueError(
                f"{data.path}: trial '{trial}': the stiffness k = J·ω_n² is "
                f"{est.stiffness_Nm_per_rad:g} N·m/rad with J = {inertia_kg_m2:g} kg·m² and "
                f"f_n = {est.natural_frequency_Hz:g} Hz, beyond what a float holds; give J in "
                "kg·m² and the time in s")
    fits = pooled_f = None
    if fit:
        fits = fit_decay_trajectories(times, angles, extrema, estimates, inertia_kg_m2)
        pooled_f = pooled_fit(fits)
    return DecayReport(data.path, float(inertia_kg_m2), data.trials, extrema, estimates, pooled,
                       fits, pooled_f, counts)
