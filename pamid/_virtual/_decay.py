"""The virtual decay bench: free decays of a PAM-driven arm, as an encoder records them.

Protocol (Cullinan, section VI): the joint is held at a set point, displaced by hand by a few
degrees (3°, 5°, 8°; Fig. 7 shows a release from 9°), released, and left to oscillate with
the valves shut; an absolute encoder (Cullinan: CUI AMT203, 12 bit, 2π/4096 rad per step)
reads the angle. Here the arm is the linear oscillator J·β̈ + c·β̇ + k·(β − β_eq) = 0 of
:class:`pamid._sim._oscillator.DampedOscillator`, optionally with a Coulomb friction torque
T_c (sliding seals, the cable over the pulley) that the viscous model lacks:

    J·β̈ + c·β̇ + k·(β − β_eq) + T_c·sign(β̇) = 0,

with sticking when the arm comes to rest where the spring torque k·|β − β_eq| ≤ T_c.

The decay is computed exactly, not integrated: between two instants of zero velocity the
friction torque is constant, so the motion is the closed-form linear decay about the
shifted centre β_eq − sign(β̇)·T_c/k; each such half cycle ends at the analytic time of the
next zero velocity. Without friction this is the closed form of
:func:`pamid._sim._oscillator.oscillator_response` over the whole record.

The sensor: Gaussian noise (``noise_sd_rad``) is added to the true angle, and the encoder
quantizes the sum to its step 2π/2^bits (``encoder_bits=None`` for none). Time stamps are
exact multiples of the sample interval. Every random number comes from the ``key`` given.
The output is a table in the decay-file format that :func:`pamid._data._decay_file.load_decay`
reads: ``trial``, ``time_s``, ``angle_rad`` (or ``angle_deg``), and optionally
``pressure1_kPa``, ``pressure2_kPa``, ``temperature_C``.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._sim._oscillator import DampedOscillator

__all__ = ["DecayProtocol", "simulate_decays"]


@dataclasses.dataclass(frozen=True)
class DecayProtocol:
    """The free-decay protocol and the sensor.

    Attributes:
        n_trials: number of decays recorded.
        deflections_deg: release deflection from the equilibrium per trial, in degrees,
            used in turn (Cullinan: 3°, 5°, 8°; Fig. 7: 9°). A negative value releases from
            the other side.
        release_rate_rad_s: angular rate at release (0: released from rest).
        hold_s: time recorded before the release, the arm held still at the deflection.
        duration_s: time recorded after the release.
        sample_rate_Hz: encoder read-out rate.
        encoder_bits: resolution of the absolute encoder, 2π/2^bits rad per step (Cullinan's
            AMT203: 12); None for an unquantized reading.
        noise_sd_rad: standard deviation of the Gaussian noise added before quantization.
        angle_unit: ``"rad"`` (column ``angle_rad``) or ``"deg"`` (column ``angle_deg``).
        pressures_kPa: the two muscle pressures, written as ``pressure1_kPa`` and
            ``pressure2_kPa`` when given (constant: the valves are shut).
        temperature_C: written as ``temperature_C`` when given.
    """

    n_trials: int = 3
    deflections_deg: tuple[float, ...] = (9.0,)
    release_rate_rad_s: float = 0.0
    hold_s: float = 0.0
    duration_s: float = 4.0
    sample_rate_Hz: float = 1000.0
    encoder_bits: int | None = 12
    noise_sd_rad: float = 0.0
    angle_unit: str = "rad"
    pressures_kPa: tuple[float, float] | None = None
    temperature_C: float | None = None

    def __post_init__(self):
        if self.n_trials < 1:
            raise ValueError(f"n_trials must be at least 1, got {self.n_trials}")
        if not self.deflections_deg:
            raise ValueError("deflections_deg must name at least one deflection")
        if self.duration_s <= 0 or self.sample_rate_Hz <= 0 or self.hold_s < 0:
            raise ValueError("duration_s and sample_rate_Hz must be positive, hold_s ≥ 0")
        if self.encoder_bits is not None and not 1 <= self.encoder_bits <= 32:
            raise ValueError(f"encoder_bits must be 1–32 or None, got {self.encoder_bits}")
        if self.noise_sd_rad < 0:
            raise ValueError("noise_sd_rad must be ≥ 0")
        if self.angle_unit not in ("rad", "deg"):
            raise ValueError(f"angle_unit must be 'rad' or 'deg', got {self.angle_unit!r}")

    @property
    def encoder_step_rad(self) -> float:
        """One encoder step in rad (0 when unquantized)."""
        return 0.0 if self.encoder_bits is None else 2.0 * math.pi / 2**self.encoder_bits


def _linear_segment(sigma, wn2, x0, v0, t):
    """Closed-form displacement and velocity of ẍ + 2σẋ + ωn²x = 0 (any damping), NumPy."""
    wd2 = wn2 - sigma**2
    if abs(wd2) * (t.max(initial=0.0) ** 2) < 1e-12:
        c, s = np.ones_like(t), t.copy()
    elif wd2 > 0:
        wd = math.sqrt(wd2)
        c, s = np.cos(wd * t), np.sin(wd * t) / wd
    else:
        wd = math.sqrt(-wd2)
        c, s = np.cosh(wd * t), np.sinh(wd * t) / wd
    e = np.exp(-sigma * t)
    return e * (x0 * c + (v0 + sigma * x0) * s), e * (v0 * c - (sigma * v0 + wn2 * x0) * s)


def _next_rest(sigma, wn2, x0, v0):
    """Time until the velocity of the linear decay from (x0, v0) is next zero (inf if never)."""
    wd2 = wn2 - sigma**2
    if wd2 <= 0:
        return math.inf  # (critically) over-damped: creeps to the centre, never turns back
    wd = math.sqrt(wd2)
    b = (sigma * v0 + wn2 * x0) / wd
    phi = math.atan2(b, v0)
    theta = (math.pi / 2 - phi) % math.pi
    if theta < 1e-12:
        theta += math.pi
    return theta / wd


def coulomb_decay(
    inertia, stiffness, damping, equilibrium, coulomb_Nm, angle0, rate0, t
) -> np.ndarray:
    """Exact angle of J·β̈ + c·β̇ + k·(β − β_eq) + T_c·sign(β̇) = 0 at times ``t`` ≥ 0 (NumPy).

    Half cycle by half cycle (see the module docstring); the arm sticks for good when it
    comes to rest with k·|β − β_eq| ≤ T_c.
    """
    t = np.asarray(t, float)
    sigma, wn2 = damping / (2.0 * inertia), stiffness / inertia
    out = np.empty_like(t)
    u, v, tau, i = angle0 - equilibrium, float(rate0), 0.0, 0
    shift = coulomb_Nm / stiffness
    while i < len(t):
        if coulomb_Nm > 0 and v == 0.0 and abs(u) <= shift:
            out[i:] = u  # stuck: static friction holds the spring torque
            break
        direction = math.copysign(1.0, v) if v != 0.0 else -math.copysign(1.0, u)
        centre = -direction * shift if coulomb_Nm > 0 else 0.0
        x0 = u - centre
        span = _next_rest(sigma, wn2, x0, v) if coulomb_Nm > 0 else math.inf
        j = i + int(np.searchsorted(t[i:], tau + span, side="left"))
        out[i:j] = centre + _linear_segment(sigma, wn2, x0, v, t[i:j] - tau)[0]
        if j >= len(t):
            break
        x_end, _ = _linear_segment(sigma, wn2, x0, v, np.array([span]))
        u, v, tau, i = centre + float(x_end[0]), 0.0, tau + span, j
    return equilibrium + out


def simulate_decays(
    key: jax.Array,
    oscillator: DampedOscillator,
    protocol: DecayProtocol = DecayProtocol(),
    *,
    coulomb_Nm: float = 0.0,
    drift_rad_s: float = 0.0,
) -> pd.DataFrame:
    """Simulate ``protocol.n_trials`` free decays as the encoder records them.

    Args:
        key: a JAX PRNG key, the only source of randomness (the sensor noise).
        oscillator: J, k, c and β_eq; fields of shape () or (n_trials,) (one per trial).
            :meth:`DampedOscillator.from_modal` builds it from ζ and f_n.
        protocol: the release, the sampling and the sensor.
        coulomb_Nm: Coulomb friction torque T_c ≥ 0 (hidden from the viscous model).
        drift_rad_s: an equilibrium that moves after the release, β_eq + r·t (a slow leak,
            a creeping set point; hidden from the model): the arm oscillates about the moving
            line, released at the deflection from it with the release rate relative to it
            (the ``drift`` effect of :data:`pamid._effects._definitions.DECAY_EFFECT_DEFINITIONS`).

    Returns:
        A table in the decay-file format: ``trial`` (1, 2, …), ``time_s``, ``angle_rad`` or
        ``angle_deg``, and the pressures and temperature when the protocol gives them.
    """
    if coulomb_Nm < 0:
        raise ValueError(f"coulomb_Nm must be ≥ 0, got {coulomb_Nm}")
    if not math.isfinite(drift_rad_s):
        raise ValueError(f"drift_rad_s must be finite, got {drift_rad_s}")
    n_trials = protocol.n_trials
    fields = {
        name: np.broadcast_to(np.asarray(getattr(oscillator, name), float), (n_trials,))
        for name in ("inertia_kg_m2", "stiffness_Nm_per_rad", "damping_Nms_per_rad",
                     "equilibrium_rad")
    }
    dt = 1.0 / protocol.sample_rate_Hz
    n_hold = int(round(protocol.hold_s * protocol.sample_rate_Hz))
    n_free = int(round(protocol.duration_s * protocol.sample_rate_Hz)) + 1
    time = dt * np.arange(n_hold + n_free)
    noise = protocol.noise_sd_rad * np.asarray(
        jax.random.normal(key, (n_trials, n_hold + n_free), dtype=jnp.float64)
    )
    q = protocol.encoder_step_rad
    frames = []
    for i in range(n_trials):
        deflection = math.radians(protocol.deflections_deg[i % len(protocol.deflections_deg)])
        eq = fields["equilibrium_rad"][i]
        t_free = dt * np.arange(n_free)
        free = coulomb_decay(
            fields["inertia_kg_m2"][i], fields["stiffness_Nm_per_rad"][i],
            fields["damping_Nms_per_rad"][i], eq, coulomb_Nm, eq + deflection,
            protocol.release_rate_rad_s - drift_rad_s, t_free,
        ) + drift_rad_s * t_free
        angle = np.concatenate([np.full(n_hold, eq + deflection), free]) + noise[i]
        if q > 0:
            angle = np.round(angle / q) * q
        block = {"trial": i + 1, "time_s": time}
        if protocol.angle_unit == "deg":
            block["angle_deg"] = np.degrees(angle)
        else:
            block["angle_rad"] = angle
        if protocol.pressures_kPa is not None:
            block["pressure1_kPa"] = float(protocol.pressures_kPa[0])
            block["pressure2_kPa"] = float(protocol.pressures_kPa[1])
        if protocol.temperature_C is not None:
            block["temperature_C"] = float(protocol.temperature_C)
        frames.append(pd.DataFrame(block))
    return pd.DataFrame(pd.concat(frames, ignore_index=True))
