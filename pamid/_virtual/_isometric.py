"""The virtual bench for isometric tests, and files shaped as other labs deliver them.

Sárosi moves the muscle's end at constant pressure (:mod:`pamid._virtual._sweeps`);
many labs do the opposite. The Agile & Adaptive Robotics Lab's isometric protocol (Portland
State University, as documented with its published data set) clamps each muscle at a few fixed
lengths — 0 % and 25/50/75 % of the way to its length at the largest pressure — while a
pulsed valve steps the pressure up to about 620 kPa, holds it, and steps it back down,
three trials per length, about 28 s each, the logger's clock restarting at 0 in every
trial. Such a file is not quasi-static: every valve pulse puts a force transient into it;
the pressure sensor reads an offset at ambient; inflating and deflating branches differ a
little. :class:`IsometricProtocol` describes such a test, :func:`simulate_isometric_bench`
runs it for many muscles at once, from the "true" static model (Sárosi eq. 2.1) plus what
the protocol switches on.

:func:`virtual_lab_file` makes whole files of given kinds and sizes (isometric stairs or
ramps, noisy sweeps with trials, a mix) for tests and benchmarks, optionally with blank
direction cells or columns left out; :func:`write_bench_csv` writes one with any separator
and decimal mark (semicolons and decimal commas, as European spreadsheets write them).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._effects._compliance import InjectedCompliance
from .._effects._hysteresis import InjectedHysteresis
from .._effects._inject import apply_effects
from .._io import PARQUET_SUFFIXES, write_frame_atomic
from .._models._sarosi import Sarosi, contraction_at_force_pct, sarosi_force, table_3_1
from .._units import KPA_PER_BAR
from ._sweeps import (
    SarosiProtocol,
    _compliant_contraction,
    _read_sensor,
    simulate_sarosi_bench,
)

__all__ = [
    "LAB_FILE_KINDS",
    "IsometricProtocol",
    "simulate_isometric_bench",
    "virtual_lab_file",
    "write_bench_csv",
]

LEVEL_UNITS = ("fraction", "pct")
PROGRAMS = ("stairs", "ramp")
LAB_FILE_KINDS = ("isometric_stairs", "isometric_ramp", "sweeps_noisy", "mixed")
_KAPPA_SEARCH_PCT = 50.0  # free contraction at p_max is searched in 0 … 50 % (load_bench's range)


@dataclasses.dataclass(frozen=True)
class IsometricProtocol:
    """An isometric test: the muscle clamped at fixed lengths while the pressure moves.

    The defaults follow the AARL protocol (four lengths, 0 % and 25/50/75 % of the way to
    the free contraction at 620 kPa, three trials each, a pulsed valve). Every effect is
    off by default except the sensors' noise and resolution.

    Attributes:
        levels: the clamped contractions, one set of trials each; fractions of the way to
            the muscle's free contraction at ``p_max_kPa`` (``level_unit="fraction"``, where
            eq. 2.1 gives zero force) or contractions in % of l0 (``level_unit="pct"``).
        level_unit: "fraction" or "pct".
        program: the pressure program of a trial. "stairs": the valve pulses, each pulse
            steps the pressure up by ``step_kPa`` and holds it ``dwell_s``, up to
            ``p_max_kPa``; it stays there ``hold_s`` longer and steps back down to 0 the same
            way. "ramp": a continuous ramp at ``ramp_kPa_per_s`` up to ``p_max_kPa``, a hold
            of ``hold_s``, a ramp down at the same rate.
        p_max_kPa: largest gauge pressure of a trial.
        step_kPa: pressure step of one valve pulse (the last one up may be smaller).
        dwell_s: time between valve pulses.
        ramp_kPa_per_s: rate of a ramp.
        hold_s: time at ``p_max_kPa`` (for stairs: beyond the top step's own dwell).
        rest_s: time at ambient pressure before the first pulse and after the last.
        sample_s: time between samples.
        repeats: trials at every level.
        transient_N_per_kPa, transient_tau_s: the force transient of the valve: a
            first-order relaxation g·Δp·exp(−(t − t_step)/τ) after every pressure step Δp
            (the same first-order system's response to a ramp, g·r·τ·(1 − exp(−t/τ)) at rate
            r, where the program ramps).
        pressure_noise_kPa, force_noise_N, contraction_noise_pct: standard deviation of
            every logged reading of the pressure, force and length sensors (the length's in %
            of l0); the muscle's true state is not noisy.
        time_jitter_s: the logged time of a sample is off by a uniform error in
            ±``time_jitter_s`` (less than half a sample; the first sample of a trial stays
            at 0).
        pressure_resolution_kPa, force_resolution_N, length_resolution_mm: reading steps of
            the logged channels (0: none).
        pressure_offset_kPa: what the pressure logger adds to the gauge pressure (AARL's
            sensor reads 7–9 kPa at ambient).
        hysteresis_N_at_3_bar, hysteresis_form: inflate/deflate hysteresis, half height at
            3 bar: the force lies ``h(p)`` below the static curve while the pressure rises
            (and holds after rising), ``h(p)`` above it while it falls — the form of
            :class:`~pamid._effects._hysteresis.InjectedHysteresis` with the pressure's
            direction as the direction.
        softening, softening_repeats: the muscle softens from trial to trial at a level: its
            force is multiplied by 1 − s·(1 − exp(−repeat/r)), repeat = 0, 1, 2, ….
        min_force_N: if given, samples whose true force falls below it are not written (a
            slack muscle: AARL's file lacks its rows of force ≤ 0); None writes every sample.
        effects: further hidden effects (:mod:`pamid._effects._inject`): drift,
            temperature, covariates, hysteresis of other forms, rig compliance (the muscle is
            shorter than the clamp says by c·F); viscous damping adds nothing at a held length.
    """

    levels: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75)
    level_unit: str = "fraction"
    program: str = "stairs"
    p_max_kPa: float = 620.0
    step_kPa: float = 62.0
    dwell_s: float = 0.5
    ramp_kPa_per_s: float = 125.0
    hold_s: float = 10.0
    rest_s: float = 2.0
    sample_s: float = 0.02
    repeats: int = 3
    transient_N_per_kPa: float = 0.0
    transient_tau_s: float = 0.05
    pressure_noise_kPa: float = 1.0
    force_noise_N: float = 1.0
    contraction_noise_pct: float = 0.01
    time_jitter_s: float = 0.0
    pressure_resolution_kPa: float = 0.1
    force_resolution_N: float = 0.1
    length_resolution_mm: float = 0.01
    pressure_offset_kPa: float = 0.0
    hysteresis_N_at_3_bar: float = 0.0
    hysteresis_form: str = "linear"
    softening: float = 0.0
    softening_repeats: float = 1.0
    min_force_N: float | None = None
    effects: tuple = ()

    def __post_init__(self):
        if self.level_unit not in LEVEL_UNITS:
            raise ValueError(f"level_unit must be one of {LEVEL_UNITS}, got {self.level_unit!r}")
        if self.program not in PROGRAMS:
            raise ValueError(f"program must be one of {PROGRAMS}, got {self.program!r}")
        levels = np.asarray(self.levels, float)
        if levels.ndim != 1 or levels.size == 0 or not np.all(np.isfinite(levels)):
            raise ValueError("levels must hold at least one finite contraction level")
        if len(set(self.levels)) != len(self.levels):
            raise ValueError(f"levels must differ from each other, got {self.levels}")
        if self.level_unit == "fraction" and not np.all((levels >= 0) & (levels <= 1)):
            raise ValueError(
                "levels with level_unit='fraction' are fractions of the way to the free "
                f"contraction at p_max_kPa and must lie in 0 … 1, got {self.levels}"
            )
        if self.level_unit == "pct" and not np.all((levels >= -10) & (levels < 50)):
            raise ValueError(f"levels in % of l0 must lie in −10 … 50, got {self.levels}")
        positive = ["p_max_kPa", "sample_s", "transient_tau_s", "softening_repeats"]
        positive += ["step_kPa", "dwell_s"] if self.program == "stairs" else ["ramp_kPa_per_s"]
        for name in positive:
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be positive, got {value}")
        for name in (
            "hold_s", "rest_s", "pressure_noise_kPa", "force_noise_N", "contraction_noise_pct",
            "time_jitter_s", "pressure_resolution_kPa", "force_resolution_N",
            "length_resolution_mm",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be zero or positive, got {value}")
        for name in ("transient_N_per_kPa", "pressure_offset_kPa", "hysteresis_N_at_3_bar"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")
        if not 0 <= self.softening < 1:
            raise ValueError(f"softening must lie in 0 … 1 (a fraction), got {self.softening}")
        if not (isinstance(self.repeats, int | np.integer) and self.repeats >= 1):
            raise ValueError(f"repeats must be a whole number ≥ 1, got {self.repeats}")
        if self.time_jitter_s >= 0.5 * self.sample_s:
            raise ValueError(
                f"time_jitter_s ({self.time_jitter_s}) must be less than half of sample_s "
                f"({self.sample_s}), or the logged time could run backwards"
            )
        if self.trial_duration_s / self.sample_s > 1e7:
            raise ValueError("sample_s is too small for the trial: more than 10⁷ samples")
        InjectedHysteresis(self.hysteresis_N_at_3_bar, self.hysteresis_form)  # checks the form

    @property
    def trial_duration_s(self) -> float:
        """Length of one trial in s (its last sample is at or just before this time)."""
        t0, t1, _ = self.segments()
        return float(t1[-1]) + self.rest_s

    @property
    def samples_per_trial(self) -> int:
        return int(math.floor(self.trial_duration_s / self.sample_s + 1e-6)) + 1

    def segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pressure program of a trial as segments: start time, end time (equal to the
        start for a valve step) and pressure change in kPa, in order of time."""
        if self.program == "stairs":
            n_steps = max(1, math.ceil(self.p_max_kPa / self.step_kPa - 1e-9))
            plateau = np.minimum(np.arange(1, n_steps + 1) * self.step_kPa, self.p_max_kPa)
            up_dp = np.diff(plateau, prepend=0.0)
            up_t = self.rest_s + self.dwell_s * np.arange(n_steps)
            down_t = up_t[-1] + self.dwell_s + self.hold_s + self.dwell_s * np.arange(n_steps)
            down_dp = -up_dp[::-1]
            t0 = np.concatenate([up_t, down_t])
            return t0, t0.copy(), np.concatenate([up_dp, down_dp])
        ramp_s = self.p_max_kPa / self.ramp_kPa_per_s
        t0 = np.array([self.rest_s, self.rest_s + ramp_s + self.hold_s])
        return t0, t0 + ramp_s, np.array([self.p_max_kPa, -self.p_max_kPa])

    def level_labels(self) -> list[str]:
        """The trial label's level part: "k25" for 25 % of the way (or 25 % of l0)."""
        scale = 100.0 if self.level_unit == "fraction" else 1.0
        return [f"k{scale * level:g}" for level in self.levels]


def _program(protocol: IsometricProtocol, t: np.ndarray):
    """Set pressure (kPa), valve transient per N/kPa of gain (kPa) and direction (+1 while
    the pressure rises or holds after rising, −1 while it falls) at the times ``t``."""
    t0, t1, dp = protocol.segments()
    eps = 1e-9 * protocol.sample_s  # a sample at a step's time reads the new pressure
    tt = t[:, None]
    started = tt >= t0 - eps
    span = t1 - t0
    ramp = span > 0
    frac = np.where(ramp, np.clip((tt - t0) / np.where(ramp, span, 1.0), 0.0, 1.0), started)
    pressure = frac @ dp
    # First-order relaxation (time constant τ) of every step; the same system's response
    # to a ramp of rate r from t0 to t1 is r·τ·(exp(−max(t − t1, 0)/τ) − exp(−max(t − t0, 0)/τ)).
    tau = protocol.transient_tau_s
    since0 = np.maximum(tt - t0, 0.0)
    step = np.where(started, np.exp(-since0 / tau), 0.0) * dp
    rate = dp / np.where(ramp, span, 1.0)
    ramp_resp = rate * tau * (np.exp(-np.maximum(tt - t1, 0.0) / tau) - np.exp(-since0 / tau))
    transient = np.where(ramp, ramp_resp, step).sum(axis=1)
    # A ramp's first sample still belongs to what came before it (its pressure has not moved).
    moving = np.where(ramp, tt > t0 + eps, started)
    last = moving.sum(axis=1) - 1
    direction = np.where(last < 0, 1.0, np.sign(dp)[np.maximum(last, 0)])
    return pressure, transient, direction


def _muscle_params(params: Sarosi, muscle_ids, l0_mm):
    theta = np.atleast_2d(np.asarray(params.to_vector(), dtype=float))
    n_muscles = theta.shape[0]
    if muscle_ids is None:
        muscle_ids = [f"M{i + 1:04d}" for i in range(n_muscles)]
    muscle_ids = [str(m) for m in muscle_ids]
    if len(muscle_ids) != n_muscles:
        raise ValueError(f"{len(muscle_ids)} muscle ids for {n_muscles} parameter sets")
    if len(set(muscle_ids)) != n_muscles:
        raise ValueError("muscle_ids must differ from each other")
    l0 = np.broadcast_to(np.asarray(l0_mm, float), (n_muscles,)) if np.ndim(l0_mm) <= 1 else None
    if l0 is None or not np.all(np.isfinite(l0) & (l0 > 0)):
        raise ValueError("l0_mm must be one positive length or one per muscle")
    return Sarosi.from_vector(jnp.asarray(theta)), muscle_ids, np.array(l0)


def simulate_isometric_bench(
    key: jax.Array,
    params: Sarosi,
    protocol: IsometricProtocol = IsometricProtocol(),
    muscle_ids: Sequence[str] | None = None,
    l0_mm: float | Sequence[float] = 400.0,
    *,
    blank_direction_for: Sequence[str] = (),
    drop_columns: Sequence[str] = (),
) -> pd.DataFrame:
    """Simulate isometric tests of one muscle, or of many when ``params`` has a leading axis.

    The true force is Sárosi's static model (eq. 2.1) at the true pressure and the clamped
    contraction, plus the protocol's effects; the file holds what the sensors log. All
    muscles, trials and samples are computed as arrays at once.

    Args:
        key: a JAX PRNG key; the only source of randomness.
        params: Sárosi constants; fields of shape () for one muscle or (M,) for M muscles.
        protocol: the test and its sensors.
        muscle_ids: names of the muscles (default "M0001", …).
        l0_mm: nominal length, one for all muscles or one per muscle.
        blank_direction_for: muscles whose ``direction`` cells are left empty (NaN), as from
            a logger that does not record the valve's state.
        drop_columns: columns left out of the file.

    Returns:
        One row per sample, in order of muscle, trial and time: muscle, trial ("k25_T1": the
        level's label and the trial's number at that level), time_s (restarting at 0 in every
        trial), pressure_kPa (as logged: noise, offset and resolution), force_N, length_mm,
        l0_mm, contraction_pct = 100·(l0 − length)/l0 (both as logged), direction (+1 while
        the pressure rises or holds after rising, −1 while it falls), and the columns the
        effects log (temperature_C, …).
    """
    batched, muscle_ids, l0 = _muscle_params(params, muscle_ids, l0_mm)
    n_muscles, n_levels, n_rep = len(muscle_ids), len(protocol.levels), protocol.repeats
    n_trials, n_samples = n_levels * n_rep, protocol.samples_per_trial

    # Clamped contraction of every trial, (M, T, 1).
    levels = np.asarray(protocol.levels, float)
    if protocol.level_unit == "fraction":
        p_max_bar = jnp.asarray(protocol.p_max_kPa / KPA_PER_BAR)
        free = np.asarray(
            jax.vmap(lambda prm: contraction_at_force_pct(
                prm, p_max_bar, _KAPPA_SEARCH_PCT, 0.0))(batched)
        )
        kappa_level = free[:, None] * levels[None, :]
    else:
        kappa_level = np.broadcast_to(levels, (n_muscles, n_levels))
    shape = (n_muscles, n_trials, n_samples)
    kappa_set = np.repeat(kappa_level, n_rep, axis=1)[:, :, None]
    repeat = np.tile(np.arange(n_rep), n_levels)[None, :, None]

    t = np.arange(n_samples) * protocol.sample_s
    p_kpa, transient, direction = _program(protocol, t)
    p_bar = np.broadcast_to(p_kpa / KPA_PER_BAR, shape)
    direction_all = np.broadcast_to(direction, shape)

    kappa_true = np.broadcast_to(kappa_set, shape)
    compliance = [e for e in protocol.effects if isinstance(e, InjectedCompliance)]
    if compliance:
        kappa_true = _compliant_contraction(
            batched, p_bar, kappa_true, sum(e.mm_per_N for e in compliance), l0
        )
    force = np.asarray(
        jax.vmap(sarosi_force)(batched, jnp.asarray(p_bar), jnp.asarray(kappa_true))
    )  # Sárosi eq. 2.1
    ctx = {"p_bar": p_bar, "direction": direction_all}
    force = force + InjectedHysteresis(
        protocol.hysteresis_N_at_3_bar, protocol.hysteresis_form
    ).force_N(ctx)
    force = force + protocol.transient_N_per_kPa * transient
    force = force * (
        1.0 - protocol.softening * (1.0 - np.exp(-repeat / protocol.softening_repeats))
    )

    trial_start = np.arange(n_trials) * protocol.trial_duration_s
    extra_columns: dict[str, np.ndarray] = {}
    other = [e for e in protocol.effects if not isinstance(e, InjectedCompliance)]
    if other:
        seed = int(jax.random.randint(jax.random.fold_in(key, 0), (), 0, 2**31 - 1))
        ctx |= {
            "kappa_pct": kappa_true,
            "time_s": np.broadcast_to(trial_start[:, None] + t, shape),
            "velocity_mm_s": np.zeros(shape),  # the clamp holds the length
            "moving_input": np.broadcast_to(p_kpa, shape),
            "sequence_axes": 1,
            "sweep": np.broadcast_to(np.arange(n_trials)[:, None], shape),
            "point_fraction": t / protocol.trial_duration_s,
            "rng": np.random.default_rng(seed),
        }
        ctx["force_N"] = force  # what a scaling effect scales
        added, extra_columns = apply_effects(other, ctx, shape)
        force = force + added

    # What the sensors log. Every channel has its own stream of the key.
    pressure_log = _read_sensor(
        jax.random.fold_in(key, 1), np.broadcast_to(p_kpa + protocol.pressure_offset_kPa, shape),
        protocol.pressure_noise_kPa, protocol.pressure_resolution_kPa,
    )
    force_log = _read_sensor(
        jax.random.fold_in(key, 2), force, protocol.force_noise_N, protocol.force_resolution_N
    )
    l0_col = l0[:, None, None]
    length_log = _read_sensor(
        jax.random.fold_in(key, 3),
        np.broadcast_to(l0_col * (1.0 - kappa_set / 100.0), shape),
        protocol.contraction_noise_pct * l0_col / 100.0,
        protocol.length_resolution_mm,
    )
    length_log = np.round(length_log, 6)  # the contraction column is computed from this
    time_log = np.broadcast_to(t, shape)
    if protocol.time_jitter_s > 0:
        jitter = np.array(
            jax.random.uniform(
                jax.random.fold_in(key, 4), shape, jnp.float64,
                -protocol.time_jitter_s, protocol.time_jitter_s,
            )
        )
        jitter[:, :, 0] = 0.0
        time_log = time_log + jitter

    labels = [
        f"{level}_T{r + 1}" for level in protocol.level_labels() for r in range(n_rep)
    ]
    columns = {
        "muscle": np.repeat(np.asarray(muscle_ids, dtype=object), n_trials * n_samples),
        "trial": np.tile(np.repeat(np.asarray(labels, dtype=object), n_samples), n_muscles),
        "time_s": np.round(time_log, 9).ravel(),
        "pressure_kPa": np.round(pressure_log, 6).ravel(),
        "force_N": np.round(force_log, 6).ravel(),
        "length_mm": length_log.ravel(),
        "l0_mm": np.repeat(l0, n_trials * n_samples),
        "contraction_pct": np.round(100.0 * (l0_col - length_log) / l0_col, 9).ravel(),
        "direction": direction_all.astype(np.int64).ravel(),
    }
    for name, values in extra_columns.items():
        columns[name] = np.round(values, 9).ravel()
    frame = pd.DataFrame(columns)
    if protocol.min_force_N is not None:
        frame = frame[force.ravel() >= protocol.min_force_N].reset_index(drop=True)
    return _as_delivered(frame, blank_direction_for, drop_columns)


def _as_delivered(frame: pd.DataFrame, blank_direction_for, drop_columns) -> pd.DataFrame:
    """The frame as another lab's file: blank direction cells for some muscles, and
    columns left out."""
    blank = [str(m) for m in blank_direction_for]
    if blank:
        if "muscle" not in frame or "direction" not in frame:
            raise ValueError("blank_direction_for needs the muscle and direction columns")
        unknown = sorted(set(blank) - set(frame["muscle"]))
        if unknown:
            raise ValueError(f"blank_direction_for names muscles not in the file: {unknown}")
        direction = frame["direction"].to_numpy(float).copy()
        direction[frame["muscle"].isin(blank).to_numpy()] = np.nan
        frame = frame.assign(direction=direction)
    missing = sorted(set(drop_columns) - set(frame.columns))
    if missing:
        raise ValueError(f"drop_columns names columns not in the file: {missing}")
    return frame.drop(columns=list(drop_columns))


def write_bench_csv(
    frame: pd.DataFrame, path: str | os.PathLike, *, sep: str = ",", decimal: str = "."
) -> Path:
    """Write a bench table as CSV, atomically, with the given separator and decimal mark.

    ``sep=";", decimal=","`` writes what European spreadsheets do. NaN cells (blank
    directions) are written empty. Returns the path.
    """
    if Path(path).suffix.lower() in PARQUET_SUFFIXES:
        raise ValueError(f"{path}: write_bench_csv writes CSV; give a path that is not .parquet")
    if decimal not in (".", ","):
        raise ValueError(f"decimal must be '.' or ',', got {decimal!r}")
    if len(sep) != 1 or sep == decimal or sep in "\"\n\r" or sep.isalnum():
        raise ValueError(f"sep must be one character other than the decimal mark, got {sep!r}")
    return write_frame_atomic(path, frame, sep=sep, decimal=decimal)


def virtual_lab_file(
    key: jax.Array,
    kind: str,
    n_rows: int,
    *,
    n_muscles: int = 1,
    params: Sarosi | None = None,
    l0_mm: float = 400.0,
    muscle_ids: Sequence[str] | None = None,
    blank_direction_for: Sequence[str] = (),
    drop_columns: Sequence[str] = (),
    **protocol_options,
) -> pd.DataFrame:
    """A bench file of one of the kinds real labs deliver, of about ``n_rows`` rows.

    Kinds (:data:`LAB_FILE_KINDS`):

    * ``isometric_stairs``: AARL's test (:class:`IsometricProtocol` defaults) with what its
      file shows: a valve transient (0.05 N/kPa, τ = 50 ms), a pressure offset of 8 kPa, an
      inflate/deflate hysteresis of ±2 N at 3 bar, no rows where the muscle is slack
      (true force < 0);
    * ``isometric_ramp``: the same with the pressure ramped at 125 kPa/s;
    * ``sweeps_noisy``: Sárosi's sweeps (:class:`SarosiProtocol`, repeats kept, min_force_N
      10 N, ±3 N/bar hysteresis), each cycle its own trial, with noise on the logged
      pressure (1 kPa) and contraction (0.01 %) besides the force (2 N);
    * ``mixed``: the first half of the muscles isometric stairs, the rest noisy sweeps
      (needs ``n_muscles`` ≥ 2); the columns both have.

    The sample interval (isometric) or the points per sweep (sweeps) is chosen so that the
    file has about ``n_rows`` rows: sweeps and isometric files without slack rows
    (``min_force_N=None``) have at most ``n_rows``, fewer by less than one sample per sweep or
    trial; isometric files whose slack rows are left out are within about 1 % of it.
    ``protocol_options`` replace fields of the kind's protocol (``pressure_offset_kPa=0.0``,
    ``repeats=2``, ``min_force_N=None``, …). ``params`` defaults to Table 3-1 for every
    muscle; ``l0_mm`` is the muscles' nominal length.
    """
    if kind not in LAB_FILE_KINDS:
        raise ValueError(f"unknown kind {kind!r}; choose one of {LAB_FILE_KINDS}")
    if not (isinstance(n_muscles, int | np.integer) and n_muscles >= 1):
        raise ValueError(f"n_muscles must be a whole number ≥ 1, got {n_muscles}")
    if kind == "mixed" and n_muscles < 2:
        raise ValueError("kind 'mixed' needs n_muscles ≥ 2 (some isometric, some sweeps)")
    if params is None:
        params = Sarosi.from_vector(jnp.tile(table_3_1().to_vector(), (n_muscles, 1)))
    batched, muscle_ids, _ = _muscle_params(params, muscle_ids, l0_mm)
    theta = np.asarray(batched.to_vector())
    if theta.shape[0] != n_muscles:
        raise ValueError(f"params hold {theta.shape[0]} muscles, n_muscles is {n_muscles}")

    n_iso = {"isometric_stairs": n_muscles, "isometric_ramp": n_muscles, "sweeps_noisy": 0,
             "mixed": n_muscles // 2}[kind]
    iso_fields = {f.name for f in dataclasses.fields(IsometricProtocol)}
    sweep_fields = {f.name for f in dataclasses.fields(SarosiProtocol)}
    known = (iso_fields if n_iso else set()) | (sweep_fields if n_iso < n_muscles else set())
    unknown = sorted(set(protocol_options) - known)
    if unknown:
        raise ValueError(f"protocol options {unknown} do not apply to kind {kind!r}")
    iso_options = {k: v for k, v in protocol_options.items() if k in iso_fields}
    sweep_options = {k: v for k, v in protocol_options.items() if k in sweep_fields}
    frames = []
    if n_iso:
        iso_rows = n_rows if n_iso == n_muscles else round(n_rows * n_iso / n_muscles)
        frames.append(_isometric_file(
            jax.random.fold_in(key, 0), "ramp" if kind == "isometric_ramp" else "stairs",
            iso_rows // n_iso, Sarosi.from_vector(jnp.asarray(theta[:n_iso])),
            muscle_ids[:n_iso], l0_mm, iso_options,
        ))
    if n_iso < n_muscles:
        n_sweep = n_muscles - n_iso
        sweep_rows = n_rows - (sum(len(f) for f in frames) if frames else 0)
        frames.append(_sweeps_file(
            jax.random.fold_in(key, 1), sweep_rows // n_sweep,
            Sarosi.from_vector(jnp.asarray(theta[n_iso:])), muscle_ids[n_iso:], l0_mm,
            sweep_options,
        ))
    if len(frames) > 1:
        shared = [c for c in frames[0].columns if c in frames[1].columns]
        frames = [f[shared] for f in frames]
    frame = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
    return _as_delivered(frame, blank_direction_for, drop_columns)


def _isometric_file(key, program, rows_per_muscle, params, muscle_ids, l0_mm, options):
    base = {"program": program, "transient_N_per_kPa": 0.05, "transient_tau_s": 0.05,
            "pressure_offset_kPa": 8.0, "hysteresis_N_at_3_bar": 2.0, "min_force_N": 0.0}
    protocol = IsometricProtocol(**(base | options))
    n_trials = len(protocol.levels) * protocol.repeats
    n_samples = rows_per_muscle // n_trials
    if protocol.min_force_N is not None and n_samples >= 2:
        # Slack samples are not written: a coarse run says which share of a trial is kept.
        pilot = _with_samples(protocol, min(n_samples, 400))
        kept = len(simulate_isometric_bench(key, params, pilot, muscle_ids, l0_mm)) / (
            len(muscle_ids) * n_trials * pilot.samples_per_trial
        )
        n_samples = int(rows_per_muscle / n_trials / max(kept, 1e-3))
    if n_samples < 2:
        raise ValueError(
            f"{rows_per_muscle} rows per muscle are too few for {n_trials} isometric trials "
            "of at least 2 samples"
        )
    return simulate_isometric_bench(
        key, params, _with_samples(protocol, n_samples), muscle_ids, l0_mm
    )


def _with_samples(protocol: IsometricProtocol, n_samples: int) -> IsometricProtocol:
    """``protocol`` with the sample interval that puts ``n_samples`` samples in a trial,
    the last at its end (and the time jitter kept below half a sample)."""
    sample_s = protocol.trial_duration_s / (n_samples - 1)
    return dataclasses.replace(
        protocol, sample_s=sample_s, time_jitter_s=min(protocol.time_jitter_s, 0.4 * sample_s)
    )


def _sweeps_file(key, rows_per_muscle, params, muscle_ids, l0_mm, options):
    base = {"average_repeats": False, "trials": True, "min_force_N": 10.0,
            "hysteresis_N_per_bar": 3.0, "pressure_noise_kPa": 1.0,
            "pressure_resolution_kPa": 0.1, "contraction_noise_pct": 0.01, "l0_mm": l0_mm}
    protocol = SarosiProtocol(**(base | options))
    n_sweeps = protocol.repeats * len(protocol.pressures_kPa) * len(protocol.directions)
    points = rows_per_muscle // n_sweeps
    if points < 2:
        raise ValueError(
            f"{rows_per_muscle} rows per muscle are too few for {n_sweeps} sweeps of at "
            "least 2 points"
        )
    protocol = dataclasses.replace(protocol, points_per_curve=points)
    return simulate_sarosi_bench(key, params, protocol, list(muscle_ids))
