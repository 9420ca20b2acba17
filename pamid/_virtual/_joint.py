"""The virtual joint bench: Cullinan's two joint tests, simulated from known constants.

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints", Sections III–V.

1. The torque sweep of Section IV (:func:`simulate_joint_sweep`). The arm is removed, so
   the joint carries no load and the two PAMs only act against each other. One PAM is held
   at the test pressure while the other's pressure rises slowly and turns the joint; when
   both are at the test pressure (at 0 rad, since nothing loads the joint) the roles swap
   and the PAM that was held is slowly vented to atmospheric pressure; then the sequence runs
   backwards and the joint returns. Four ramps per test pressure:

   ====== =============== =============== ========= ======================
   phase  P1              P2              direction PAM at test pressure
   ====== =============== =============== ========= ======================
   1      test            0 → test        −1        1
   2      test → 0        test            −1        2
   3      0 → test        test            +1        2
   4      test            test → 0        +1        1
   ====== =============== =============== ========= ======================

   The joint is quasi-static: at every sample the angle solves T(β, P1, P2) = 0 (Cullinan
   eq. 3–5 with cable stretch, :func:`~pamid._models._joint.joint_torque_Nm`) by bisection
   on [−β_range/2, β_range/2]. Where the torque does not change sign there, the joint rests
   on a limit (the antagonist fully extended) and the stop carries the torque: ``at_limit``.
   ``test_torque_Nm`` is the torque of the PAM at the test pressure, r·F, which is what
   Cullinan's Fig. 4 plots against the angle.

2. The closed-system deflection test of Section V (:func:`simulate_deflection_test`). The
   valves bring the joint to a set point (β0, P1, P2) and close; the joint is then displaced
   by hand by 3°, 5° or 8° and returned, with the mass of air in each PAM constant. Each
   PAM's pressure follows its volume (:func:`~pamid._models._volume.closed_system_pressure_kPa`)
   and the torque is the difference of the two load cells' torques. The slope of a line fitted
   to torque against angle over the displacement is the closed-system stiffness
   (:func:`deflection_test_stiffness`); without noise or friction it equals
   :func:`~pamid._models._joint.closed_system_stiffness`'s ``regression_Nm_per_rad``.

Sensors (Section III), with ASSUMED resolutions and noise: a CUI AMT203 absolute encoder
(12 bit, 2π/4096 rad per count), Honeywell TruStability HSC pressure sensors (14 bit over
0–150 psi ≈ 1034 kPa, 0.063 kPa per count; 0.5 kPa noise), STA-1 S-type load cells (1 N
noise, 0.1 N per count). Every noise source draws from the one PRNG key passed in.

Effects the static model lacks, off by default so that later tests can hide them:

* ``hysteresis_N`` (+ ``hysteresis_N_per_kPa``·P′): Coulomb friction in each PAM. A PAM that
  shortens pulls this much less, one that lengthens this much more (Cullinan saw
  "significant hysteresis", larger for the sleeve PAM, blamed on the sliding seal). In the
  sweep it shifts the equilibrium by the direction of motion; in the deflection test it
  builds up over ``friction_length_mm`` of travel (0: at once), a Dahl-like first-order lag,
  and so adds an apparent stiffness to small deflections. Friction changes the load-cell
  readings only; the cables' stretch is computed from the friction-free force.
* ``polytropic_n`` of the sealed air in the deflection test (1: isothermal; 1.4: adiabatic,
  a fast displacement).

Units: N, kPa (gauge), mm, rad, s; torque N·m.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._models._cullinan import Cullinan, cullinan_force
from .._models._cullinan_presets import TEST_PRESSURES_KPA
from .._models._joint import JointGeometry, contractions_mm, joint_torque_Nm, muscle_state
from .._models._volume import PamVolume, closed_system_pressure_kPa
from .._units import ATMOSPHERE_KPA

#: AMT203: 12-bit absolute encoder.
ENCODER_RESOLUTION_RAD = 2.0 * math.pi / 4096
#: HSC 150 psi gauge sensor, 14-bit output.
PRESSURE_RESOLUTION_KPA = 150.0 * 6.894757293168361 / 16383

_BISECTION_STEPS = 60
_FIXED_POINT_STEPS = 12  # cable stretch of sealed muscles: c·|dF/dy| < 0.1, so 1e-12


def _quantize(x, step):
    return x if step <= 0 else np.round(np.asarray(x) / step) * step


@dataclasses.dataclass(frozen=True)
class _Sensors:
    angle_resolution_rad: float
    pressure_noise_sd_kPa: float
    pressure_resolution_kPa: float
    force_noise_sd_N: float
    force_resolution_N: float

    def read(self, key, angle, p1, p2, f1, f2):
        k_p, k_f = jax.random.split(key)
        n = np.asarray(angle).shape
        pn = self.pressure_noise_sd_kPa * np.asarray(jax.random.normal(k_p, (2, *n)))
        fn = self.force_noise_sd_N * np.asarray(jax.random.normal(k_f, (2, *n)))
        return (
            _quantize(angle, self.angle_resolution_rad),
            _quantize(p1 + pn[0], self.pressure_resolution_kPa),
            _quantize(p2 + pn[1], self.pressure_resolution_kPa),
            _quantize(f1 + fn[0], self.force_resolution_N),
            _quantize(f2 + fn[1], self.force_resolution_N),
        )


def _sensors_of(protocol) -> _Sensors:
    """The sensor model of a protocol (both protocols carry the same sensor fields)."""
    return _Sensors(
        protocol.angle_resolution_rad,
        protocol.pressure_noise_sd_kPa,
        protocol.pressure_resolution_kPa,
        protocol.force_noise_sd_N,
        protocol.force_resolution_N,
    )


def _check_sensors(protocol) -> None:
    for name in (
        "angle_resolution_rad",
        "pressure_noise_sd_kPa",
        "pressure_resolution_kPa",
        "force_noise_sd_N",
        "force_resolution_N",
        "hysteresis_N",
        "hysteresis_N_per_kPa",
    ):
        if getattr(protocol, name) < 0:
            raise ValueError(f"{name} must be >= 0; got {getattr(protocol, name)}")


@dataclasses.dataclass(frozen=True)
class JointSweepProtocol:
    """Cullinan's joint test (Section IV), with the sensors' noise and resolution.

    Attributes:
        test_pressures_kPa: gauge test pressures (ASSUMED 10–60 psi; the paper shows six).
        points_per_ramp: samples per pressure ramp (four ramps per test pressure).
        ramp_kPa_per_s: rate of each ramp ("slowly"; ASSUMED 5 kPa/s).
        angle_resolution_rad, pressure_noise_sd_kPa, pressure_resolution_kPa,
        force_noise_sd_N, force_resolution_N: the sensors (module docstring).
        hysteresis_N, hysteresis_N_per_kPa: friction in each PAM (module docstring).
    """

    test_pressures_kPa: tuple[float, ...] = TEST_PRESSURES_KPA
    points_per_ramp: int = 41
    ramp_kPa_per_s: float = 5.0
    angle_resolution_rad: float = ENCODER_RESOLUTION_RAD
    pressure_noise_sd_kPa: float = 0.5
    pressure_resolution_kPa: float = PRESSURE_RESOLUTION_KPA
    force_noise_sd_N: float = 1.0
    force_resolution_N: float = 0.1
    hysteresis_N: float = 0.0
    hysteresis_N_per_kPa: float = 0.0

    def __post_init__(self):
        if self.points_per_ramp < 2:
            raise ValueError("points_per_ramp must be at least 2")
        if self.ramp_kPa_per_s <= 0:
            raise ValueError("ramp_kPa_per_s must be positive")
        if not self.test_pressures_kPa or min(self.test_pressures_kPa) <= 0:
            raise ValueError("test_pressures_kPa must be positive gauge pressures")
        _check_sensors(self)

    def sensors(self) -> _Sensors:
        return _sensors_of(self)


@jax.jit
def _equilibrium(params1, params2, geometry, p1, p2, offset_Nm):
    """Angle where T(β) + offset = 0 in [−β_range/2, β_range/2], or the limit it rests on.

    The torque falls as β rises (the joint resists deflection), so bisection finds the
    root; where T + offset keeps one sign over the range the joint rests on that limit.
    Returns (β, net torque at β, at_limit).
    """
    half = geometry.beta_range_rad / 2.0
    shape = jnp.broadcast_shapes(jnp.shape(p1), jnp.shape(p2), jnp.shape(offset_Nm))

    def net(beta):
        return joint_torque_Nm(params1, params2, geometry, beta, p1, p2) + offset_Nm

    lo = jnp.broadcast_to(-half, shape)
    hi = jnp.broadcast_to(half, shape)
    t_lo, t_hi = net(lo), net(hi)

    def step(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        above = net(mid) > 0.0
        return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

    lo_b, hi_b = jax.lax.fori_loop(0, _BISECTION_STEPS, step, (lo, hi))
    beta = jnp.where(t_hi >= 0.0, half, jnp.where(t_lo <= 0.0, -half, 0.5 * (lo_b + hi_b)))
    at_limit = (t_hi >= 0.0) | (t_lo <= 0.0)
    return beta, net(beta), at_limit


def _sweep_schedule(protocol: JointSweepProtocol):
    """Pressures, phase, direction and test muscle of every sample, in time order."""
    u = np.linspace(0.0, 1.0, protocol.points_per_ramp)
    rows = {k: [] for k in ("p_test", "phase", "p1", "p2", "direction", "test_muscle", "dt")}
    for pt in protocol.test_pressures_kPa:
        up, down = pt * u, pt * u[::-1]
        held = np.full_like(u, pt)
        dt = pt / (protocol.points_per_ramp - 1) / protocol.ramp_kPa_per_s
        for phase, p1, p2, direction, test in (
            (1, held, up, -1, 1),
            (2, down, held, -1, 2),
            (3, up, held, 1, 2),
            (4, held, down, 1, 1),
        ):
            rows["p_test"].append(np.full_like(u, pt))
            rows["phase"].append(np.full(u.size, phase))
            rows["p1"].append(p1)
            rows["p2"].append(p2)
            rows["direction"].append(np.full(u.size, direction))
            rows["test_muscle"].append(np.full(u.size, test))
            rows["dt"].append(np.full_like(u, dt))
    return {k: np.concatenate(v) for k, v in rows.items()}


def simulate_joint_sweep(
    key: jax.Array,
    params: Cullinan,
    geometry: JointGeometry,
    protocol: JointSweepProtocol = JointSweepProtocol(),
    params2: Cullinan | None = None,
) -> pd.DataFrame:
    """Simulate Cullinan's joint test (Section IV) for one joint; see the module docstring.

    Args:
        key: a JAX PRNG key; the only source of randomness.
        params: eq. 3 constants of muscle 1 (and of muscle 2 unless ``params2`` is given).
        geometry: pulley, β_range and cable compliance.
        protocol: test pressures, ramps, sensors and the friction hook.

    Returns:
        One row per sample, in time order: time_s, test_pressure_kPa, phase (1–4),
        direction (+1 while β rises), test_muscle (1 or 2), angle_rad, pressure1_kPa,
        pressure2_kPa, force1_N, force2_N (load-cell readings), torque_Nm = r·(F1 − F2)
        from the readings, test_torque_Nm = r·F of the PAM at the test pressure, at_limit.
    """
    params2 = params if params2 is None else params2
    s = _sweep_schedule(protocol)
    p1, p2, direction = s["p1"], s["p2"], s["direction"].astype(float)
    h1 = protocol.hysteresis_N + protocol.hysteresis_N_per_kPa * p1
    h2 = protocol.hysteresis_N + protocol.hysteresis_N_per_kPa * p2
    r_m = float(geometry.pulley_radius_mm) / 1000.0
    # β rising: muscle 1 shortens (pulls h1 less), muscle 2 lengthens (pulls h2 more).
    offset = -direction * r_m * (h1 + h2)
    beta, _, at_limit = _equilibrium(
        params, params2, geometry, jnp.asarray(p1), jnp.asarray(p2), jnp.asarray(offset)
    )
    state = muscle_state(params, params2, geometry, beta, p1, p2)
    f1 = np.asarray(state.f1_N) - direction * h1
    f2 = np.asarray(state.f2_N) + direction * h2
    angle, p1r, p2r, f1r, f2r = protocol.sensors().read(key, np.asarray(beta), p1, p2, f1, f2)
    test_force = np.where(s["test_muscle"] == 1, f1r, f2r)
    time = np.concatenate([[0.0], np.cumsum(s["dt"][1:])])
    return pd.DataFrame(
        {
            "time_s": time,
            "test_pressure_kPa": s["p_test"],
            "phase": s["phase"].astype(int),
            "direction": s["direction"].astype(int),
            "test_muscle": s["test_muscle"].astype(int),
            "angle_rad": angle,
            "pressure1_kPa": p1r,
            "pressure2_kPa": p2r,
            "force1_N": f1r,
            "force2_N": f2r,
            "torque_Nm": r_m * (f1r - f2r),
            "test_torque_Nm": r_m * test_force,
            "at_limit": np.asarray(at_limit),
        }
    )


# --------------------------------------------------------------------------------------
# The closed-system deflection test (Section V).


@dataclasses.dataclass(frozen=True)
class DeflectionProtocol:
    """Cullinan's closed-system stiffness test (Section V), with sensors and friction.

    Attributes:
        set_points: (β0 [rad], P1 [kPa], P2 [kPa]) at which the valves close.
        deflections_deg: displacements by hand (Cullinan: 3°, 5°, 8°), each out and back.
        direction: +1 or −1, the side of the displacement.
        points_per_deflection: samples on the way out (the same on the way back).
        seconds_per_point: time between samples.
        polytropic_n: exponent of the sealed air (1 isothermal, 1.4 adiabatic).
        p_atm_kPa: atmospheric pressure.
        angle_resolution_rad, pressure_noise_sd_kPa, pressure_resolution_kPa,
        force_noise_sd_N, force_resolution_N: the sensors (module docstring).
        hysteresis_N, hysteresis_N_per_kPa: friction in each PAM, and
        friction_length_mm: the travel over which it builds up (0: at once).
    """

    set_points: tuple[tuple[float, float, float], ...] = ((0.0, 300.0, 300.0),)
    deflections_deg: tuple[float, ...] = (3.0, 5.0, 8.0)
    direction: int = 1
    points_per_deflection: int = 21
    seconds_per_point: float = 0.05
    polytropic_n: float = 1.0
    p_atm_kPa: float = ATMOSPHERE_KPA
    angle_resolution_rad: float = ENCODER_RESOLUTION_RAD
    pressure_noise_sd_kPa: float = 0.5
    pressure_resolution_kPa: float = PRESSURE_RESOLUTION_KPA
    force_noise_sd_N: float = 1.0
    force_resolution_N: float = 0.1
    hysteresis_N: float = 0.0
    hysteresis_N_per_kPa: float = 0.0
    friction_length_mm: float = 0.0

    def __post_init__(self):
        if self.direction not in (1, -1):
            raise ValueError(f"direction must be +1 or -1; got {self.direction}")
        if self.points_per_deflection < 2:
            raise ValueError("points_per_deflection must be at least 2")
        if not self.deflections_deg or min(self.deflections_deg) <= 0:
            raise ValueError("deflections_deg must be positive angles in degrees")
        if not self.set_points or any(len(sp) != 3 for sp in self.set_points):
            raise ValueError("set_points must be (beta0_rad, p1_kPa, p2_kPa) triples")
        if self.polytropic_n <= 0 or self.p_atm_kPa <= 0:
            raise ValueError("polytropic_n and p_atm_kPa must be positive")
        if self.friction_length_mm < 0:
            raise ValueError("friction_length_mm must be >= 0")
        _check_sensors(self)

    def sensors(self) -> _Sensors:
        return _sensors_of(self)


@jax.jit
def _sealed_state(params1, params2, geometry, volume1, volume2, y10, y20, p10, p20, beta, n, p_atm):
    """Contractions, pressures and tensions of both sealed muscles at the angles ``beta``.

    y_i = y_geom,i + c·F_i(P_i(y_i), y_i) by fixed-point iteration (c·|dF/dy| < 0.1).
    """
    y1g, y2g = contractions_mm(geometry, beta)
    c = geometry.cable_compliance_mm_per_N

    def solve(params, volume, y0, p0, y_geom):
        def pressure(y):
            return closed_system_pressure_kPa(volume, y0, p0, y, n, p_atm)

        def tension(y):
            return jnp.maximum(cullinan_force(params, pressure(y), y), 0.0)

        y = jax.lax.fori_loop(0, _FIXED_POINT_STEPS, lambda _, y: y_geom + c * tension(y), y_geom)
        y = jnp.maximum(y, y_geom)
        return y, pressure(y), tension(y)

    y1, p1, f1 = solve(params1, volume1, y10, p10, y1g)
    y2, p2, f2 = solve(params2, volume2, y20, p20, y2g)
    return y1, y2, p1, p2, f1, f2


def _friction(y: np.ndarray, y0: float, h: np.ndarray, length_mm: float) -> np.ndarray:
    """Friction force (N, subtracted from the pull) along a path of contractions.

    Starts at 0 at the set point; moves towards h·sign(ẏ) with the travel, at once when
    ``length_mm`` is 0, else as 1 − exp(−travel/length) (a Dahl-like lag).
    """
    out = np.zeros_like(y)
    state, prev = 0.0, y0
    for i, yi in enumerate(y):
        dy = yi - prev
        if dy != 0.0:
            target = h[i] * np.sign(dy)
            keep = 0.0 if length_mm == 0.0 else math.exp(-abs(dy) / length_mm)
            state = target + (state - target) * keep
        out[i] = state
        prev = yi
    return out


def simulate_deflection_test(
    key: jax.Array,
    params: Cullinan,
    geometry: JointGeometry,
    volume: PamVolume,
    protocol: DeflectionProtocol = DeflectionProtocol(),
    params2: Cullinan | None = None,
    volume2: PamVolume | None = None,
) -> pd.DataFrame:
    """Simulate Cullinan's closed-system deflection test (Section V); see the module docstring.

    Args:
        key: a JAX PRNG key; the only source of randomness.
        params, volume: eq. 3 constants and gas volume of muscle 1 (and of muscle 2 unless
            ``params2`` / ``volume2`` are given).
        geometry: pulley, β_range and cable compliance.
        protocol: set points, deflections, gas, sensors and friction.

    Returns:
        One row per sample: set_point (index), beta0_rad, p1_set_kPa, p2_set_kPa,
        deflection_deg, leg ("out" or "back"), time_s, angle_rad, pressure1_kPa,
        pressure2_kPa, force1_N, force2_N, torque_Nm = r·(F1 − F2) from the readings.
    """
    params2 = params if params2 is None else params2
    volume2 = volume if volume2 is None else volume2
    r_m = float(geometry.pulley_radius_mm) / 1000.0
    u = np.linspace(0.0, 1.0, protocol.points_per_deflection)
    frames, t0 = [], 0.0
    keys = jax.random.split(key, len(protocol.set_points) * len(protocol.deflections_deg))
    k_index = 0
    for sp_index, (beta0, p10, p20) in enumerate(protocol.set_points):
        set_state = muscle_state(params, params2, geometry, beta0, p10, p20)
        for delta in protocol.deflections_deg:
            out = beta0 + protocol.direction * math.radians(delta) * u
            path = np.concatenate([out, out[-2::-1]])
            leg = np.array(["out"] * u.size + ["back"] * (u.size - 1))
            y1, y2, p1, p2, f1, f2 = (
                np.asarray(a)
                for a in _sealed_state(
                    params,
                    params2,
                    geometry,
                    volume,
                    volume2,
                    set_state.y1_mm,
                    set_state.y2_mm,
                    p10,
                    p20,
                    jnp.asarray(path),
                    protocol.polytropic_n,
                    protocol.p_atm_kPa,
                )
            )
            h1 = protocol.hysteresis_N + protocol.hysteresis_N_per_kPa * p1
            h2 = protocol.hysteresis_N + protocol.hysteresis_N_per_kPa * p2
            f1 = f1 - _friction(y1, float(set_state.y1_mm), h1, protocol.friction_length_mm)
            f2 = f2 - _friction(y2, float(set_state.y2_mm), h2, protocol.friction_length_mm)
            angle, p1r, p2r, f1r, f2r = protocol.sensors().read(keys[k_index], path, p1, p2, f1, f2)
            k_index += 1
            time = t0 + protocol.seconds_per_point * np.arange(path.size)
            t0 = time[-1] + protocol.seconds_per_point
            frames.append(
                pd.DataFrame(
                    {
                        "set_point": sp_index,
                        "beta0_rad": float(beta0),
                        "p1_set_kPa": float(p10),
                        "p2_set_kPa": float(p20),
                        "deflection_deg": float(delta),
                        "leg": leg,
                        "time_s": time,
                        "angle_rad": angle,
                        "pressure1_kPa": p1r,
                        "pressure2_kPa": p2r,
                        "force1_N": f1r,
                        "force2_N": f2r,
                        "torque_Nm": r_m * (f1r - f2r),
                    }
                )
            )
    return pd.DataFrame(pd.concat(frames, ignore_index=True))


def deflection_test_stiffness(frame: pd.DataFrame) -> pd.DataFrame:
    """Closed-system stiffness −dT/dβ (N·m/rad) per set point and deflection, as Cullinan.

    The slope of a least-squares line (with intercept) through torque against angle on the
    way out of each displacement (``leg == "out"``), negated. Returns set_point,
    deflection_deg, stiffness_Nm_per_rad, and the set point's beta0_rad, p1_set_kPa,
    p2_set_kPa.
    """
    rows = []
    out = frame[frame["leg"] == "out"]
    for (sp, delta), g in out.groupby(["set_point", "deflection_deg"], sort=True):
        x = g["angle_rad"].to_numpy()
        t = g["torque_Nm"].to_numpy()
        xc = x - x.mean()
        slope = float((xc * (t - t.mean())).sum() / (xc * xc).sum())
        first = g.iloc[0]
        rows.append(
            {
                "set_point": int(sp),
                "deflection_deg": float(delta),
                "stiffness_Nm_per_rad": -slope,
                "beta0_rad": float(first["beta0_rad"]),
                "p1_set_kPa": float(first["p1_set_kPa"]),
                "p2_set_kPa": float(first["p2_set_kPa"]),
            }
        )
    return pd.DataFrame(rows)
