"""Energy an ideal isothermal compressor spends to drive a PAM joint along a trajectory.

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints", Section VII, eq. 13–14, after
Chou & Hannaford (1996). Air is an ideal gas, every change is isothermal at T = 293.15 K,
and the dynamics of joint and muscles (G in eq. 3) are ignored.

The joint moves in discrete steps. In each step each muscle goes from (P_m1, V_m1) to
(P_m2, V_m2), absolute pressures, which takes the mass Δm = (P_m2·V_m2 − P_m1·V_m1)/(R·T). If
Δm > 0 an ideal compressor draws Δm at ambient pressure, V_c1 = Δm·R·T/P_atm, compresses
it to the muscle's pressure, V_c2 = Δm·R·T/P_m1, then opens the valve and completes its
stroke while the muscle's volume goes to V_m2:

    W = −∫_{V_c1}^{V_c2} (P − P_atm) dV − ∫_{V_c2+V_m1}^{V_m2} (P − P_atm) dV          (eq. 13)
      = −Δm·R·T·ln(V_c2/V_c1) − P_atm·(V_c1 − V_c2)
        − (Δm + m1)·R·T·ln(V_m2/(V_c2 + V_m1)) − P_atm·((V_c2 + V_m1) − V_m2)          (eq. 14)

with m1 = P_m1·V_m1/(R·T). Air exhausted from a muscle is lost to the atmosphere: a step
with Δm ≤ 0 costs nothing (Cullinan: "only energy input to the PAM is considered").

Every step of eq. 13 is reversible and isothermal, so eq. 14 is the isothermal minimum: it
equals the change of the air's exergy, X2 − X1 with X = P·V·ln(P/P_atm) − (P − P_atm)·V
(the air drawn from the atmosphere has none). The tests use this.

Units: the public arguments are in kPa (gauge), mm³ and K; inside, SI (Pa absolute, m³, kg,
J). The work is in J.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._checks import require
from .._units import ATMOSPHERE_KPA, PA_PER_KPA
from ._cullinan import Cullinan
from ._joint import (
    CULLINAN_P_MAX_KPA,
    JointGeometry,
    contractions_mm,
    pressures_for_torque_stiffness_kPa,
)
from ._volume import PamVolume, volume_mm3

#: Specific gas constant of dry air, J/(kg·K).
R_AIR_J_PER_KG_K = 287.05
#: Temperature of the isothermal analysis, K (20 °C).
ROOM_TEMPERATURE_K = 293.15

_M3_PER_MM3 = 1e-9


class TrajectoryEnergy(NamedTuple):
    """Result of :func:`trajectory_energy_J`, for a trajectory of N angles.

    * ``total_J``: the energy of the whole trajectory, J.
    * ``step_work_J``: shape (N, 2), eq. 14 per step and muscle; step 0 fills both muscles
      from atmospheric pressure at the first angle.
    * ``p1_kPa``, ``p2_kPa``: shape (N,), the gauge pressures from eq. 6 and eq. 7.
    * ``feasible``: shape (N,), False where a pressure lies outside [0, P_max]; the energy
      is still computed there, with the pressures as solved (check this flag).
    """

    total_J: Float[Array, ""]
    step_work_J: Float[Array, "n 2"]
    p1_kPa: Float[Array, " n"]
    p2_kPa: Float[Array, " n"]
    feasible: Bool[Array, " n"]


def air_mass_kg(
    p_kPa: ArrayLike,
    v_mm3: ArrayLike,
    p_atm_kPa: ArrayLike = ATMOSPHERE_KPA,
    temperature_K: ArrayLike = ROOM_TEMPERATURE_K,
) -> Float[Array, "..."]:
    """Mass of air in kg at the gauge pressure ``p_kPa`` in ``v_mm3``: m = P·V/(R·T)."""
    p_abs_Pa = (jnp.asarray(p_kPa, float) + jnp.asarray(p_atm_kPa, float)) * PA_PER_KPA
    return (
        p_abs_Pa
        * jnp.asarray(v_mm3, float)
        * _M3_PER_MM3
        / (R_AIR_J_PER_KG_K * jnp.asarray(temperature_K, float))
    )


def compressor_work_J(
    p1_kPa: ArrayLike,
    v1_mm3: ArrayLike,
    p2_kPa: ArrayLike,
    v2_mm3: ArrayLike,
    p_atm_kPa: ArrayLike = ATMOSPHERE_KPA,
    temperature_K: ArrayLike = ROOM_TEMPERATURE_K,
) -> Float[Array, "..."]:
    """Work in J of the ideal isothermal compressor for one step of one muscle, Cullinan eq. 14.

    The muscle goes from the gauge pressure ``p1_kPa`` and volume ``v1_mm3`` to ``p2_kPa``
    and ``v2_mm3``. W = 0 where the step needs no air (Δm ≤ 0, to a relative 1e-12: exhausted
    air is lost).
    Broadcasts; differentiable (the Δm ≤ 0 branch is masked safely).
    """
    require("p_atm_kPa", p_atm_kPa, lambda a: a > 0, "> 0 (an absolute pressure)")
    require("temperature_K", temperature_K, lambda a: a > 0, "> 0 (an absolute temperature)")
    rt = R_AIR_J_PER_KG_K * jnp.asarray(temperature_K, float)  # J/kg
    p_atm = jnp.asarray(p_atm_kPa, float) * PA_PER_KPA  # Pa
    p_m1 = jnp.asarray(p1_kPa, float) * PA_PER_KPA + p_atm  # Pa, absolute
    p_m2 = jnp.asarray(p2_kPa, float) * PA_PER_KPA + p_atm
    v_m1 = jnp.asarray(v1_mm3, float) * _M3_PER_MM3  # m³
    v_m2 = jnp.asarray(v2_mm3, float) * _M3_PER_MM3
    m1 = p_m1 * v_m1 / rt  # kg
    m2 = p_m2 * v_m2 / rt
    dm = m2 - m1
    # A Δm below 1e-12 of the mass is rounding (the same state computed twice), not air.
    needs_air = dm > 1e-12 * (m1 + m2)
    dm_safe = jnp.where(needs_air, dm, 1.0)  # keeps the logs finite where masked
    v_c1 = dm_safe * rt / p_atm  # drawn at ambient pressure
    v_c2 = dm_safe * rt / p_m1  # compressed to the muscle's pressure
    work = (
        -dm_safe * rt * jnp.log(v_c2 / v_c1)
        - p_atm * (v_c1 - v_c2)
        - (dm_safe + m1) * rt * jnp.log(v_m2 / (v_c2 + v_m1))
        - p_atm * ((v_c2 + v_m1) - v_m2)
    )
    return jnp.where(needs_air, work, 0.0)


def trajectory_energy_J(
    params: Cullinan,
    geometry: JointGeometry,
    volume: PamVolume,
    beta_traj_rad: ArrayLike,
    torque_Nm: ArrayLike,
    stiffness_Nm_per_rad: ArrayLike,
    p_max_kPa: ArrayLike = CULLINAN_P_MAX_KPA,
    p_atm_kPa: ArrayLike = ATMOSPHERE_KPA,
    temperature_K: ArrayLike = ROOM_TEMPERATURE_K,
) -> TrajectoryEnergy:
    """Compressor energy in J to follow a joint trajectory (Cullinan Section VII, Fig. 8).

    ``beta_traj_rad`` has shape (N,); ``torque_Nm`` (static output torque) and
    ``stiffness_Nm_per_rad`` (isobaric stiffness magnitude −dT/dβ) broadcast to it. At each
    angle the pressures solve eq. 6 and eq. 7 (two linear equations in P1, P2; see
    :func:`~pamid._models._joint.pressures_for_torque_stiffness_kPa`), the contractions are
    eq. 5 and the volumes come from ``volume`` (both muscles alike). Step 0 fills both
    muscles from atmospheric pressure at the first angle; each later step costs eq. 14 per
    muscle. Identical muscles in tension and rigid cables, as eq. 6 and eq. 7 assume (the
    geometry's cable compliance is not used). Use ``vmap`` for batches of trajectories.
    """
    require("p_max_kPa", p_max_kPa, lambda a: a > 0, "> 0")
    beta = jnp.asarray(beta_traj_rad, float)
    if beta.ndim != 1 or beta.shape[0] < 1:
        raise ValueError(
            f"beta_traj_rad must be a 1-D trajectory of at least one angle; got shape {beta.shape}"
        )
    require("p_atm_kPa", p_atm_kPa, lambda a: a > 0, "> 0 (an absolute pressure)")
    require("temperature_K", temperature_K, lambda a: a > 0, "> 0 (an absolute temperature)")
    return _trajectory_energy(
        params,
        geometry,
        volume,
        beta,
        torque_Nm,
        stiffness_Nm_per_rad,
        p_max_kPa,
        p_atm_kPa,
        temperature_K,
    )


@jax.jit
def _trajectory_energy(
    params,
    geometry,
    volume,
    beta,
    torque_Nm,
    stiffness_Nm_per_rad,
    p_max_kPa,
    p_atm_kPa,
    temperature_K,
):
    torque = jnp.broadcast_to(jnp.asarray(torque_Nm, float), beta.shape)
    stiffness = jnp.broadcast_to(jnp.asarray(stiffness_Nm_per_rad, float), beta.shape)
    p_max = jnp.asarray(p_max_kPa, float)

    p1, p2 = pressures_for_torque_stiffness_kPa(params, geometry, beta, torque, stiffness)
    y1, y2 = contractions_mm(geometry, beta)
    pressures = jnp.stack([p1, p2], axis=-1)  # (N, 2)
    volumes = jnp.stack([volume_mm3(volume, y1), volume_mm3(volume, y2)], axis=-1)

    # Start: both muscles at atmospheric pressure at the first angle.
    p_before = jnp.concatenate([jnp.zeros((1, 2)), pressures[:-1]], axis=0)
    v_before = jnp.concatenate([volumes[:1], volumes[:-1]], axis=0)
    work = compressor_work_J(p_before, v_before, pressures, volumes, p_atm_kPa, temperature_K)
    feasible = jnp.all((pressures >= 0.0) & (pressures <= p_max), axis=-1)
    return TrajectoryEnergy(work.sum(), work, p1, p2, feasible)
