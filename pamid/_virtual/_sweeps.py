"""The virtual bench: synthetic quasi-static bench data from known constants.

It reproduces Sárosi's protocol (section 2.1 of the summary): the muscle lies horizontally,
one end on a load cell, the other moved step by step by a threaded rod whose position an
incremental encoder reads to 0.01 mm; the force–contraction curve is sampled in 30 points
at each constant pressure, contracting and extending, and each measurement is repeated five
times and averaged. Every bench file that pamid ships (the `make demo` data set among them)
comes from here, from pamid's own code, with its constants and noise recorded.

Effects the static model lacks can be switched on; the default protocol has none but
sensor noise and resolution. ``hysteresis_N_per_bar`` makes the force direction dependent:
the extending branch lies above the contracting one by 2·h·p (Sárosi's upper curve F_f and
lower curve F_a, eq. 2.3–2.4). ``effects`` takes any of the effects of
:mod:`pamid._effects._inject` (hysteresis of several forms, temperature, load-cell
drift, rig compliance, viscous damping, any logged covariate), alone or together; the file
then carries what a real logger would (a temperature column, say) but never says which
effect is in the force.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._effects._compliance import InjectedCompliance
from .._effects._inject import apply_effects
from .._models._sarosi import Sarosi, contraction_at_force_pct, sarosi_force
from .._units import KPA_PER_BAR


@dataclasses.dataclass(frozen=True)
class SarosiProtocol:
    """Sárosi's quasi-static protocol, with the sensors' noise and resolution.

    Attributes:
        pressures_kPa: constant gauge pressures, one pair of sweeps each.
        points_per_curve: samples per sweep (Sárosi: 30).
        kappa_max_pct: largest contraction the rig reaches (DMSP muscles: 25 %).
        min_force_N: a sweep stops where the true force falls to this value (the muscle
            cannot hold a length at which it would push); Sárosi's curves end there too.
        directions: +1 contracting sweep (κ rising), −1 extending sweep (κ falling).
        repeats: measurements at every point (Sárosi: 5).
        average_repeats: write the mean of the repeats (Sárosi's "taken the average")
            instead of every repeat as its own cycle.
        l0_mm: nominal length of the muscle.
        noise_sd_N: load-cell noise of one reading, standard deviation.
        force_resolution_N: the load cell's reading step (0 for none).
        length_resolution_mm: the encoder's step (Sárosi's LINIMIK MSA 320: 0.01 mm).
        hysteresis_N_per_bar: half height of the hysteresis loop per bar of pressure.
        seconds_per_point: time between samples, for the `time_s` column.
        sweep_seconds_per_point: if given, the time between samples of each sweep in turn
            (cycled over the sweeps), so that sweeps run at different speeds.
        effects: effects hidden in the force (:mod:`pamid._effects._inject`).
        pressure_noise_kPa: noise of the logged pressure (pressure sensor), standard
            deviation of one reading; the true pressure stays at the set point.
        pressure_resolution_kPa: the pressure sensor's reading step (0 for none).
        contraction_noise_pct: noise of the logged contraction (length sensor), standard
            deviation of one reading in % of l0; the muscle stays where the rod holds it.
        trials: write every cycle as its own trial (a ``trial`` column "T1", "T2", …) whose
            ``time_s`` restarts at 0, as a logger that writes one record per run does.
        transient_N_per_pct, transient_tau_s: the force's relaxation after every step of
            the rod: g·Σ_k Δκ_k·exp(−(t − t_k)/τ) over the cycle's earlier steps Δκ_k (in %
            of l0), the rod moving halfway between two samples (a standard linear solid's
            response to a step of strain; Zener 1948). g < 0 is an overshoot of the force's
            own change (the force falls as the muscle contracts).
        softening, softening_repeats: the Mullins effect: every reading of cycle r (0, 1,
            …; the r-th of the repeats at a point when they are averaged) is multiplied by
            1 − s·(1 − exp(−r/r0)), with s = ``softening`` and r0 = ``softening_repeats``.
        pressure_offset_kPa: what the pressure logger adds to the gauge pressure (a zero
            offset of the transducer); the file's pressure column carries it.
    """

    pressures_kPa: tuple[float, ...] = (100.0, 200.0, 300.0, 400.0, 500.0)
    points_per_curve: int = 30
    kappa_max_pct: float = 25.0
    min_force_N: float = 0.0
    directions: tuple[int, ...] = (1, -1)
    repeats: int = 5
    average_repeats: bool = True
    l0_mm: float = 400.0
    noise_sd_N: float = 2.0
    force_resolution_N: float = 0.1
    length_resolution_mm: float = 0.01
    hysteresis_N_per_bar: float = 0.0
    seconds_per_point: float = 2.0
    sweep_seconds_per_point: tuple[float, ...] | None = None
    effects: tuple = ()
    pressure_noise_kPa: float = 0.0
    pressure_resolution_kPa: float = 0.0
    contraction_noise_pct: float = 0.0
    trials: bool = False
    transient_N_per_pct: float = 0.0
    transient_tau_s: float = 1.0
    softening: float = 0.0
    softening_repeats: float = 1.0
    pressure_offset_kPa: float = 0.0

    def __post_init__(self):
        if self.points_per_curve < 2:
            raise ValueError("points_per_curve must be at least 2")
        if self.repeats < 1:
            raise ValueError("repeats must be at least 1")
        if any(d not in (1, -1) for d in self.directions):
            raise ValueError("directions must be +1 (contracting) or -1 (extending)")
        if self.l0_mm <= 0:
            raise ValueError("l0_mm must be positive")
        if self.sweep_seconds_per_point is not None and (
            not self.sweep_seconds_per_point or min(self.sweep_seconds_per_point) <= 0
        ):
            raise ValueError("sweep_seconds_per_point must hold positive durations")
        for name in ("pressure_noise_kPa", "pressure_resolution_kPa", "contraction_noise_pct"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be zero or positive, got {getattr(self, name)}")
        for name in ("transient_tau_s", "softening_repeats"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("transient_N_per_pct", "pressure_offset_kPa"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")
        if not 0 <= self.softening < 1:
            raise ValueError(f"softening must lie in 0 … 1 (a fraction), got {self.softening}")


def _quantize(x, step):
    return x if step <= 0 else np.round(x / step) * step


def _read_sensor(key, value, noise_sd, step):
    """What a sensor logs: ``value`` plus Gaussian noise of ``noise_sd`` (broadcast to it;
    drawn from ``key`` only where some ``noise_sd`` > 0), rounded to the reading step
    ``step`` (0: none)."""
    value = np.asarray(value, float)
    if np.any(np.asarray(noise_sd) > 0):
        value = value + noise_sd * np.asarray(
            jax.random.normal(key, value.shape, dtype=jnp.float64)
        )
    return _quantize(value, step)


def simulate_sarosi_bench(
    key: jax.Array,
    params: Sarosi,
    protocol: SarosiProtocol = SarosiProtocol(),
    muscle_ids: list[str] | None = None,
) -> pd.DataFrame:
    """Simulate bench data for one muscle, or many when ``params`` carries a leading axis.

    Args:
        key: a JAX PRNG key; the only source of randomness.
        params: Sárosi constants; fields of shape () for one muscle or (M,) for M muscles.
        protocol: the measurement protocol and sensor model.
        muscle_ids: names of the muscles (default "M0001", …).

    Returns:
        A table in pamid's bench format: muscle, trial when ``protocol.trials``,
        pressure_kPa, length_mm, l0_mm, contraction_pct, force_N, direction, time_s, and
        cycle when repeats are kept. Contraction is what the encoder reads (quantized),
        pressure what the pressure sensor reads (the set point unless it is noisy or
        quantized); force is the load-cell reading.
    """
    theta = np.atleast_2d(np.asarray(params.to_vector(), dtype=float))
    n_muscles = theta.shape[0]
    if muscle_ids is None:
        muscle_ids = [f"M{i + 1:04d}" for i in range(n_muscles)]
    if len(muscle_ids) != n_muscles:
        raise ValueError(f"{len(muscle_ids)} muscle ids for {n_muscles} parameter sets")
    batched = Sarosi.from_vector(jnp.asarray(theta))

    p_bar = np.asarray(protocol.pressures_kPa, float) / KPA_PER_BAR
    ends = np.asarray(
        jax.vmap(
            lambda prm: contraction_at_force_pct(
                prm, jnp.asarray(p_bar), protocol.kappa_max_pct, protocol.min_force_N
            )
        )(batched)
    )  # (M, P)

    # Set points: 30 evenly spaced positions per sweep; the extending sweep retraces them.
    u = np.linspace(0.0, 1.0, protocol.points_per_curve)
    kappa_set = ends[:, :, None] * u  # (M, P, K)
    n_rep = protocol.repeats
    kappa_sweeps = np.stack(
        [kappa_set if d == 1 else kappa_set[..., ::-1] for d in protocol.directions], axis=2
    )  # (M, P, D, K)
    length_set = protocol.l0_mm * (1.0 - kappa_sweeps / 100.0)
    length_read = _quantize(length_set, protocol.length_resolution_mm)
    kappa_true = 100.0 * (protocol.l0_mm - length_read) / protocol.l0_mm
    kappa_true_read = kappa_true  # what the file says; compliance moves the muscle's own

    direction = np.asarray(protocol.directions, float)[None, None, :, None]
    p_grid = p_bar[None, :, None, None]
    compliance = [e for e in protocol.effects if isinstance(e, InjectedCompliance)]
    if compliance:
        kappa_true = _compliant_contraction(
            batched, p_grid, kappa_true, sum(e.mm_per_N for e in compliance), protocol.l0_mm
        )
    f_true = np.asarray(
        jax.vmap(lambda prm, k: sarosi_force(prm, jnp.asarray(p_grid[0]), k))(
            batched, jnp.asarray(kappa_true)
        )
    )
    f_true = f_true - direction * protocol.hysteresis_N_per_bar * p_grid

    n_rep = protocol.repeats
    cycles = [None] if protocol.average_repeats else list(range(1, n_rep + 1))
    n_points = protocol.points_per_curve
    n_sweeps = len(cycles) * len(p_bar) * len(protocol.directions)
    spp = _sweep_seconds(protocol, n_sweeps).reshape(len(cycles), 1, len(p_bar), -1, 1)
    starts = np.concatenate([[0.0], np.cumsum(spp.ravel() * n_points)[:-1]])
    time = starts.reshape(spp.shape) + spp * np.arange(n_points)  # (C, 1, P, D, K)
    time = np.broadcast_to(time, (len(cycles), n_muscles, *time.shape[2:]))

    f_true = f_true[None]  # (1, M, P, D, K); a cycle axis where the cycles differ
    if protocol.transient_N_per_pct:
        f_true = f_true + protocol.transient_N_per_pct * _rod_relaxation(
            kappa_true_read, time, protocol.transient_tau_s)
    if protocol.softening:  # per reading r: the r-th cycle, or the r-th of averaged repeats
        r = np.arange(protocol.repeats, dtype=float).reshape(-1, 1, 1, 1, 1)
        f_true = f_true * (1.0 - protocol.softening * (
            1.0 - np.exp(-r / protocol.softening_repeats)))

    extra_columns: dict[str, np.ndarray] = {}
    force_effects = [e for e in protocol.effects if not isinstance(e, InjectedCompliance)]
    if force_effects:
        key, effect_key = jax.random.split(key)
        seed = int(jax.random.randint(effect_key, (), 0, 2**31 - 1))
        ctx = _effect_context(protocol, p_grid, kappa_true, ends, spp, time, direction, seed)
        ctx["force_N"] = np.broadcast_to(f_true, time.shape)  # what a scaling effect scales
        added, extra_columns = apply_effects(force_effects, ctx, time.shape)
        f_true = f_true + added  # (C, M, P, D, K)

    noise = protocol.noise_sd_N * np.asarray(
        jax.random.normal(key, (n_rep, *kappa_true.shape), dtype=jnp.float64)
    )
    readings = _quantize(f_true + noise, protocol.force_resolution_N)  # (R, M, P, D, K)
    if protocol.average_repeats:
        readings = readings.mean(axis=0, keepdims=True)

    # The other logged channels: pressure and length sensors (the truth stays at the set
    # points); each reading is noisy and quantized, averaged like the force.
    reading_shape = (n_rep, *kappa_true.shape)
    pressure_log = None  # None: the file gives the set points
    if (protocol.pressure_noise_kPa > 0 or protocol.pressure_resolution_kPa > 0
            or protocol.pressure_offset_kPa != 0):
        pressure_log = _read_sensor(
            jax.random.fold_in(key, 1),
            np.broadcast_to(
                np.asarray(protocol.pressures_kPa, float)[None, None, :, None, None]
                + protocol.pressure_offset_kPa,
                reading_shape,
            ),
            protocol.pressure_noise_kPa,
            protocol.pressure_resolution_kPa,
        )
        if protocol.average_repeats:
            pressure_log = pressure_log.mean(axis=0, keepdims=True)
    length_log = np.broadcast_to(length_read[None], reading_shape)
    kappa_log = np.broadcast_to(kappa_true_read[None], reading_shape)
    if protocol.contraction_noise_pct > 0:
        length_log = _read_sensor(
            jax.random.fold_in(key, 2), length_log,
            protocol.contraction_noise_pct * protocol.l0_mm / 100.0,
            protocol.length_resolution_mm,
        )
        if protocol.average_repeats:
            length_log = length_log.mean(axis=0, keepdims=True)
        kappa_log = 100.0 * (protocol.l0_mm - length_log) / protocol.l0_mm
    if protocol.trials:  # each cycle its own trial, its clock restarting at 0
        time = time - time[:, :, :1, :1, :1]

    frames = []
    for m, muscle in enumerate(muscle_ids):
        for c_index, cycle in enumerate(cycles):
            for pi, p_kpa in enumerate(protocol.pressures_kPa):
                for di, d in enumerate(protocol.directions):
                    c_log = min(c_index, len(length_log) - 1)
                    block = {"muscle": muscle}
                    if protocol.trials:
                        block["trial"] = f"T{cycle or 1}"
                    block |= {
                        "pressure_kPa": (
                            float(p_kpa) if pressure_log is None
                            else np.round(pressure_log[c_log, m, pi, di], 6)
                        ),
                        "length_mm": np.round(length_log[c_log, m, pi, di], 6),
                        "l0_mm": protocol.l0_mm,
                        "contraction_pct": np.round(kappa_log[c_log, m, pi, di], 9),
                        "force_N": np.round(readings[c_index, m, pi, di], 6),
                        "direction": d,
                        "time_s": np.round(time[c_index, m, pi, di], 9),
                    }
                    if cycle is not None:
                        block["cycle"] = cycle
                    for name, values in extra_columns.items():
                        block[name] = np.round(values[c_index, m, pi, di], 9)
                    frames.append(pd.DataFrame(block))
    return pd.DataFrame(pd.concat(frames, ignore_index=True))


def _sweep_seconds(protocol: SarosiProtocol, n_sweeps: int) -> np.ndarray:
    if protocol.sweep_seconds_per_point is None:
        return np.full(n_sweeps, protocol.seconds_per_point)
    durations = np.asarray(protocol.sweep_seconds_per_point, float)
    return durations[np.arange(n_sweeps) % len(durations)]


def _rod_relaxation(kappa_pct, time, tau_s):
    """Σ_k Δκ_k·exp(−(t − t_k)/τ) at every sample: the first-order relaxation of every
    earlier step Δκ_k of the rod within the sample's cycle, the rod moving halfway between
    two samples (t_k). ``kappa_pct`` (M, P, D, K) is the contraction the rod holds,
    ``time`` (C, M, P, D, K) the samples' times; returns (C, M, P, D, K)."""
    c_n, m_n = time.shape[:2]
    t = time.reshape(c_n, m_n, -1)  # the cycle's samples in time order
    k = np.broadcast_to(kappa_pct[None], time.shape).reshape(c_n, m_n, -1)
    dk = np.diff(k, axis=-1, prepend=k[..., :1])
    dt = np.diff(t, axis=-1, prepend=t[..., :1])
    # Between samples n − 1 and n the earlier relaxations decay by exp(−Δt/τ), and the
    # step Δκ_n, made Δt/2 before sample n, has decayed by exp(−Δt/(2τ)).
    out = np.zeros_like(t)
    y = np.zeros(t.shape[:2])
    for n in range(t.shape[-1]):
        y = np.exp(-dt[..., n] / tau_s) * y + dk[..., n] * np.exp(-0.5 * dt[..., n] / tau_s)
        out[..., n] = y
    return out.reshape(time.shape)


def _compliant_contraction(batched, p_bar, kappa_read, mm_per_N, l0_mm):
    """Solve F = F_model(p, κ_read + 100·c·F/l0) for the muscle's true contraction (Newton).

    The rig's stretch c·F shortens the muscle below what the rod position says
    (:class:`~pamid._effects._compliance.InjectedCompliance`). ``kappa_read`` has a
    leading muscle axis (M, …); ``p_bar`` (bar) broadcasts to it, ``l0_mm`` is one length
    or one per muscle.
    """
    kappa_read = jnp.asarray(kappa_read)
    p_all = jnp.broadcast_to(jnp.asarray(p_bar), kappa_read.shape)
    gains = jnp.broadcast_to(100.0 * mm_per_N / jnp.asarray(l0_mm, float), kappa_read.shape[:1])

    def one(prm, p, k_read, gain):
        def residual(f):
            return f - sarosi_force(prm, p, k_read + gain * f)

        f = sarosi_force(prm, p, k_read)
        for _ in range(30):
            r, dr = jax.jvp(residual, (f,), (jnp.ones_like(f),))
            f = f - r / dr
        return k_read + gain * f

    return np.asarray(jax.vmap(one)(batched, p_all, kappa_read, gains))


def _effect_context(protocol, p_grid, kappa, ends, spp, time, direction, seed):
    """The arrays an injected effect sees (:mod:`pamid._effects._inject`)."""
    n_points = protocol.points_per_curve
    step_mm = ends[None, :, :, None, None] / max(n_points - 1, 1) * protocol.l0_mm / 100.0
    shape = time.shape
    sweep = np.broadcast_to(
        np.arange(shape[0] * shape[2] * shape[3]).reshape(shape[0], 1, shape[2], shape[3], 1),
        shape,
    )
    return {
        "p_bar": np.broadcast_to(p_grid[None], shape),
        "kappa_pct": np.broadcast_to(kappa[None], shape),
        "direction": np.broadcast_to(direction[None], shape),
        "time_s": time,
        "velocity_mm_s": np.broadcast_to(direction[None] * step_mm / spp, shape),
        "moving_input": np.broadcast_to(kappa[None], shape),
        "sequence_axes": 3,  # a cycle's sweeps, pressure by pressure, in time order
        "sweep": sweep,
        "point_fraction": np.broadcast_to(np.linspace(0.0, 1.0, n_points), shape),
        "rng": np.random.default_rng(seed),
    }
