"""Cullinan, McGinn and Kelly's sleeve muscles and antagonistic joint as pamid reproduces
them: the eq.-numbered functions, the muscle and joint presets, the paper's constants.

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints" (eq. 1–14), with the braided-muscle volume of its
ref. [21] (Chou & Hannaford 1996). ``pamid.cullinan.joint_torque_eq6_Nm(...)``,
``pamid.cullinan.sleeve_joint_A()``: the paper's artefacts live here, the workflows
(:func:`pamid.fit_least_squares`, :func:`pamid.simulate_joint_arm`, …) in ``pamid``.
:class:`Cullinan` and :class:`PamVolume` are in both: a workflow takes them as arguments.
"""

from ._decays._analysis import moment_of_inertia_eq12
from ._models._cullinan import Cullinan, cullinan_force, cullinan_spring_rate, end_fitting_force
from ._models._cullinan_presets import (
    BLADDER_SHEAR_MODULUS_MPA,
    CULLINAN_ACTIVE_LENGTH_MM,
    CULLINAN_BLADDER_DIAMETER_MM,
    CULLINAN_BLADDER_WALL_MM,
    DEAD_VOLUME_MM3,
    ELEMENT_DIAMETER_MM,
    REST_BRAID_ANGLE_DEG,
    SLEEVE_FIT,
    SLEEVE_G_N_S_PER_MM,
    TEST_PRESSURES_KPA,
    TRADITIONAL_FIT,
    TRADITIONAL_G_N_S_PER_MM,
    BraidedPam,
    braided_pam,
    braided_pam_force_N,
    config_a_beta_range_rad,
    sleeve_braided_pam,
    sleeve_joint_A,
    sleeve_joint_B,
    sleeve_pam,
    sleeve_volume,
    traditional_braided_pam,
    traditional_joint,
    traditional_pam,
    traditional_volume,
)
from ._models._energy import (
    R_AIR_J_PER_KG_K,
    ROOM_TEMPERATURE_K,
    TrajectoryEnergy,
    air_mass_kg,
    compressor_work_J,
    trajectory_energy_J,
)
from ._models._joint import (
    CULLINAN_CABLE_COMPLIANCE_MM_PER_N,
    CULLINAN_P_MAX_KPA,
    CULLINAN_PULLEY_RADIUS_MM,
    CULLINAN_TRADITIONAL_BETA_RANGE_RAD,
    AvailableTorque,
    ClosedSystemStiffness,
    IsobaricStiffness,
    JointGeometry,
    MuscleState,
    available_torque_Nm,
    closed_system_stiffness,
    closed_system_torque_Nm,
    contractions_mm,
    joint_stiffness_eq7_Nm_per_rad,
    joint_stiffness_Nm_per_rad,
    joint_torque_eq6_Nm,
    joint_torque_Nm,
    max_isobaric_stiffness,
    muscle_state,
    pressures_for_torque_stiffness_kPa,
)
from ._models._volume import (
    PamVolume,
    braid_volume_mm3,
    closed_system_pressure_kPa,
    sleeve_pam_volume,
    traditional_pam_volume,
)
from ._models._volume import volume_mm3 as pam_volume_mm3
from ._sim._joint_sim import gravity_moment_Nm, joint_arm_torque_Nm
from ._virtual._braided import fit_cullinan_presets

__all__ = [
    # The muscle: eq. 1–3.
    "Cullinan", "cullinan_force", "cullinan_spring_rate", "end_fitting_force",
    # Muscles like Cullinan's from a physical braided-muscle model, and their eq. 3 fits.
    "BLADDER_SHEAR_MODULUS_MPA", "CULLINAN_ACTIVE_LENGTH_MM", "CULLINAN_BLADDER_DIAMETER_MM",
    "CULLINAN_BLADDER_WALL_MM", "DEAD_VOLUME_MM3", "ELEMENT_DIAMETER_MM",
    "REST_BRAID_ANGLE_DEG", "SLEEVE_FIT", "SLEEVE_G_N_S_PER_MM", "TEST_PRESSURES_KPA",
    "TRADITIONAL_FIT", "TRADITIONAL_G_N_S_PER_MM", "BraidedPam", "braided_pam",
    "braided_pam_force_N", "fit_cullinan_presets", "sleeve_braided_pam", "sleeve_pam",
    "traditional_braided_pam", "traditional_pam",
    # The joint: eq. 4–7, Sections IV–V, and its configurations (traditional, A, B).
    "CULLINAN_CABLE_COMPLIANCE_MM_PER_N", "CULLINAN_P_MAX_KPA", "CULLINAN_PULLEY_RADIUS_MM",
    "CULLINAN_TRADITIONAL_BETA_RANGE_RAD", "AvailableTorque", "ClosedSystemStiffness",
    "IsobaricStiffness", "JointGeometry", "MuscleState", "available_torque_Nm",
    "closed_system_stiffness", "closed_system_torque_Nm", "config_a_beta_range_rad",
    "contractions_mm", "joint_stiffness_Nm_per_rad", "joint_stiffness_eq7_Nm_per_rad",
    "joint_torque_Nm", "joint_torque_eq6_Nm", "max_isobaric_stiffness", "muscle_state",
    "pressures_for_torque_stiffness_kPa", "sleeve_joint_A", "sleeve_joint_B",
    "traditional_joint",
    # Volume (Chou & Hannaford, ref. [21]) and the sealed muscle's pressure (Section V).
    "PamVolume", "braid_volume_mm3", "closed_system_pressure_kPa", "pam_volume_mm3",
    "sleeve_pam_volume", "sleeve_volume", "traditional_pam_volume", "traditional_volume",
    # Energy: Section VII, eq. 13–14.
    "R_AIR_J_PER_KG_K", "ROOM_TEMPERATURE_K", "TrajectoryEnergy", "air_mass_kg",
    "compressor_work_J", "trajectory_energy_J",
    # The arm: Section VI, eq. 12.
    "gravity_moment_Nm", "joint_arm_torque_Nm", "moment_of_inertia_eq12",
]
