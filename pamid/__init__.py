"""pamid: system identification for pneumatic artificial muscles, built on JAX.

The public API is flat; the modules behind it are private and grouped by concept
(docs/architecture.md): ``_data`` (reading files), ``_virtual`` (the virtual bench),
``_effects`` (effects a model may lack), ``_models`` (force laws), ``_fit`` (batched least
squares and intervals), ``_sim`` (simulators), ``_decays`` (free decays), ``_sampling``
(MCMC), ``_diagnose`` (closing the loop), ``_control`` (positioning control). float64 is
switched on at import, because fitting needs it.
"""

import importlib
import importlib.metadata
from typing import TYPE_CHECKING

import jax

jax.config.update("jax_enable_x64", True)

#: Public name -> (private module, name in it). Modules load on first use (PEP 562), so
#: that ``import pamid`` and the command line do not pay for what they do not touch.
_EXPORTS: dict[str, tuple[str, str]] = {
    "PositioningRig": ("._control._positioning", "PositioningRig"),
    "PositioningRun": ("._control._positioning", "PositioningRun"),
    "sarosi_linear_rig": ("._control._positioning", "linear_rig"),
    "positioning_metrics": ("._control._positioning", "positioning_metrics"),
    "sarosi_rotary_rig": ("._control._positioning", "rotary_rig"),
    "sarosi_from_fit_json": ("._control._positioning", "sarosi_from_fit_json"),
    "simulate_positioning": ("._control._positioning", "simulate_positioning"),
    "sarosi_single_muscle_rig": ("._control._positioning", "single_muscle_rig"),
    "wald_draws": ("._control._positioning", "wald_draws"),
    "SlidingModeController": ("._control._sliding_mode", "SlidingModeController"),
    "plain_switching": ("._control._sliding_mode", "plain_switching"),
    "sliding_mode_voltage": ("._control._sliding_mode", "sliding_mode_voltage"),
    "sliding_surface": ("._control._sliding_mode", "sliding_surface"),
    "TABLE_3_2": ("._control._thermal", "TABLE_3_2"),
    "MuscleThermal": ("._control._thermal", "MuscleThermal"),
    "fit_table_3_2": ("._control._thermal", "fit_table_3_2"),
    "sarosi_at_temperature": ("._control._thermal", "sarosi_at_temperature"),
    "steady_state_temperature_C": ("._control._thermal", "steady_state_temperature_C"),
    "temperature_after_C": ("._control._thermal", "temperature_after_C"),
    "ProportionalValve": ("._control._valve", "ProportionalValve"),
    "orifice_mass_flow_kg_s": ("._control._valve", "orifice_mass_flow_kg_s"),
    "valve_mass_flows_kg_s": ("._control._valve", "valve_mass_flows_kg_s"),
    "BenchData": ("._data._bench", "BenchData"),
    "CensoredRowsWarning": ("._data._bench", "CensoredRowsWarning"),
    "MissingValuesWarning": ("._data._bench", "MissingValuesWarning"),
    "load_bench": ("._data._bench", "load_bench"),
    "SarosiProtocol": ("._virtual._sweeps", "SarosiProtocol"),
    "simulate_sarosi_bench": ("._virtual._sweeps", "simulate_sarosi_bench"),
    "DecayProtocol": ("._virtual._decay", "DecayProtocol"),
    "simulate_decays": ("._virtual._decay", "simulate_decays"),
    "InjectedCompliance": ("._effects._inject", "InjectedCompliance"),
    "InjectedCovariate": ("._effects._inject", "InjectedCovariate"),
    "InjectedDrift": ("._effects._inject", "InjectedDrift"),
    "InjectedHysteresis": ("._effects._inject", "InjectedHysteresis"),
    "InjectedTemperature": ("._effects._inject", "InjectedTemperature"),
    "InjectedViscousDamping": ("._effects._inject", "InjectedViscousDamping"),
    "IsometricProtocol": ("._virtual._isometric", "IsometricProtocol"),
    "simulate_isometric_bench": ("._virtual._isometric", "simulate_isometric_bench"),
    "virtual_lab_file": ("._virtual._isometric", "virtual_lab_file"),
    "write_bench_csv": ("._virtual._isometric", "write_bench_csv"),
    "DeflectionProtocol": ("._virtual._joint", "DeflectionProtocol"),
    "JointSweepProtocol": ("._virtual._joint", "JointSweepProtocol"),
    "deflection_test_stiffness": ("._virtual._joint", "deflection_test_stiffness"),
    "simulate_deflection_test": ("._virtual._joint", "simulate_deflection_test"),
    "simulate_joint_sweep": ("._virtual._joint", "simulate_joint_sweep"),
    "ForceModel": ("._models._protocol", "ForceModel"),
    "ModelDefinitionError": ("._fit._spec", "ModelDefinitionError"),
    "Diagnosis": ("._diagnose._result", "Diagnosis"),
    "diagnose": ("._diagnose._api", "diagnose"),
    "DECAY_EFFECTS": ("._decays._coulomb", "DECAY_EFFECTS"),
    "DecayModelFit": ("._decays._coulomb", "DecayModelFit"),
    "DecayTrialModelFit": ("._decays._coulomb", "DecayTrialModelFit"),
    "coulomb_response": ("._decays._coulomb", "coulomb_response"),
    "fit_decay_models": ("._decays._coulomb", "fit_decay_models"),
    "DecayReport": ("._decays._analysis", "DecayReport"),
    "DecrementEstimate": ("._decays._analysis", "DecrementEstimate"),
    "Extrema": ("._decays._analysis", "Extrema"),
    "TrajectoryFit": ("._decays._analysis", "TrajectoryFit"),
    "analyze_decays": ("._decays._analysis", "analyze_decays"),
    "decrement_estimate": ("._decays._analysis", "decrement_estimate"),
    "find_extrema": ("._decays._analysis", "find_extrema"),
    "fit_decay_trajectories": ("._decays._analysis", "fit_decay_trajectories"),
    "log_decrement_to_zeta": ("._decays._analysis", "log_decrement_to_zeta"),
    "moment_of_inertia_eq12": ("._decays._analysis", "moment_of_inertia_eq12"),
    "DecayData": ("._data._decay_file", "DecayData"),
    "load_decay": ("._data._decay_file", "load_decay"),
    "JointDecayFit": ("._decays._joint_fit", "JointDecayFit"),
    "fit_joint_decays": ("._decays._joint_fit", "fit_joint_decays"),
    "BenchDataError": ("._errors", "BenchDataError"),
    "UntrustedResultError": ("._errors", "UntrustedResultError"),
    "FitResult": ("._fit._api", "FitResult"),
    "bench_to_fit_data": ("._fit._api", "bench_to_fit_data"),
    "fit_least_squares": ("._fit._api", "fit_least_squares"),
    "FitData": ("._fit._batch", "FitData"),
    "use_devices": ("._fit._sharding", "use_devices"),
    "lane_devices": ("._fit._sharding", "lane_devices"),
    "pack_muscles": ("._fit._batch", "pack"),
    "Cullinan": ("._models._cullinan", "Cullinan"),
    "cullinan_force": ("._models._cullinan", "cullinan_force"),
    "cullinan_spring_rate": ("._models._cullinan", "cullinan_spring_rate"),
    "end_fitting_force": ("._models._cullinan", "end_fitting_force"),
    "BraidedPam": ("._models._cullinan_presets", "BraidedPam"),
    "StaticBenchProtocol": ("._virtual._braided", "StaticBenchProtocol"),
    "braided_pam": ("._models._cullinan_presets", "braided_pam"),
    "braided_pam_force_N": ("._models._cullinan_presets", "braided_pam_force_N"),
    "config_a_beta_range_rad": ("._models._cullinan_presets", "config_a_beta_range_rad"),
    "fit_cullinan_presets": ("._virtual._braided", "fit_cullinan_presets"),
    "simulate_braided_pam_bench": ("._virtual._braided", "simulate_braided_pam_bench"),
    "sleeve_joint_A": ("._models._cullinan_presets", "sleeve_joint_A"),
    "sleeve_joint_B": ("._models._cullinan_presets", "sleeve_joint_B"),
    "sleeve_pam": ("._models._cullinan_presets", "sleeve_pam"),
    "traditional_joint": ("._models._cullinan_presets", "traditional_joint"),
    "traditional_pam": ("._models._cullinan_presets", "traditional_pam"),
    "R_AIR_J_PER_KG_K": ("._models._energy", "R_AIR_J_PER_KG_K"),
    "ROOM_TEMPERATURE_K": ("._models._energy", "ROOM_TEMPERATURE_K"),
    "TrajectoryEnergy": ("._models._energy", "TrajectoryEnergy"),
    "air_mass_kg": ("._models._energy", "air_mass_kg"),
    "compressor_work_J": ("._models._energy", "compressor_work_J"),
    "trajectory_energy_J": ("._models._energy", "trajectory_energy_J"),
    "hysteresis_damping": ("._models._hysteresis", "hysteresis_damping"),
    "sarosi_force_integral": ("._models._hysteresis", "sarosi_force_integral"),
    "CULLINAN_CABLE_COMPLIANCE_MM_PER_N": ("._models._joint", "CULLINAN_CABLE_COMPLIANCE_MM_PER_N"),
    "CULLINAN_P_MAX_KPA": ("._models._joint", "CULLINAN_P_MAX_KPA"),
    "CULLINAN_PULLEY_RADIUS_MM": ("._models._joint", "CULLINAN_PULLEY_RADIUS_MM"),
    "AvailableTorque": ("._models._joint", "AvailableTorque"),
    "ClosedSystemStiffness": ("._models._joint", "ClosedSystemStiffness"),
    "IsobaricStiffness": ("._models._joint", "IsobaricStiffness"),
    "JointGeometry": ("._models._joint", "JointGeometry"),
    "MuscleState": ("._models._joint", "MuscleState"),
    "available_torque_Nm": ("._models._joint", "available_torque_Nm"),
    "closed_system_stiffness": ("._models._joint", "closed_system_stiffness"),
    "closed_system_torque_Nm": ("._models._joint", "closed_system_torque_Nm"),
    "contractions_mm": ("._models._joint", "contractions_mm"),
    "joint_stiffness_eq7_Nm_per_rad": ("._models._joint", "joint_stiffness_eq7_Nm_per_rad"),
    "joint_stiffness_Nm_per_rad": ("._models._joint", "joint_stiffness_Nm_per_rad"),
    "joint_torque_eq6_Nm": ("._models._joint", "joint_torque_eq6_Nm"),
    "joint_torque_Nm": ("._models._joint", "joint_torque_Nm"),
    "max_isobaric_stiffness": ("._models._joint", "max_isobaric_stiffness"),
    "muscle_state": ("._models._joint", "muscle_state"),
    "pressures_for_torque_stiffness_kPa": ("._models._joint", "pressures_for_torque_stiffness_kPa"),
    "TABLE_3_1": ("._models._sarosi", "TABLE_3_1"),
    "TABLE_3_1_L0_MM": ("._models._sarosi", "TABLE_3_1_L0_MM"),
    "Sarosi": ("._models._sarosi", "Sarosi"),
    "sarosi_force": ("._models._sarosi", "sarosi_force"),
    "sarosi_force_slope": ("._models._sarosi", "sarosi_force_slope"),
    "sarosi_pressure_for_force": ("._models._sarosi", "sarosi_pressure_for_force"),
    "sarosi_stiffness": ("._models._sarosi", "sarosi_stiffness"),
    "sarosi_stiffness_eq_2_9": ("._models._sarosi", "sarosi_stiffness_eq_2_9"),
    "table_3_1": ("._models._sarosi", "table_3_1"),
    "table_3_1_fit_json": ("._models._sarosi", "table_3_1_fit_json"),
    "PamVolume": ("._models._volume", "PamVolume"),
    "braid_volume_mm3": ("._models._volume", "braid_volume_mm3"),
    "closed_system_pressure_kPa": ("._models._volume", "closed_system_pressure_kPa"),
    "sleeve_pam_volume": ("._models._volume", "sleeve_pam_volume"),
    "traditional_pam_volume": ("._models._volume", "traditional_pam_volume"),
    "pam_volume_mm3": ("._models._volume", "volume_mm3"),
    "load_inference_data": ("._sampling._arviz", "load_inference_data"),
    "DecayPosterior": ("._decays._posterior", "DecayPosterior"),
    "DecayPredictive": ("._decays._posterior", "DecayPredictive"),
    "decay_prior": ("._decays._posterior", "decay_prior"),
    "fit_decay_mcmc": ("._decays._posterior", "fit_decay_mcmc"),
    "McmcBudgetWarning": ("._sampling._mcmc", "McmcBudgetWarning"),
    "McmcResult": ("._sampling._mcmc", "McmcResult"),
    "fit_mcmc": ("._sampling._mcmc", "fit_mcmc"),
    "Prior": ("._sampling._posterior", "Prior"),
    "default_prior": ("._sampling._posterior", "default_prior"),
    "JointArm": ("._sim._joint_sim", "JointArm"),
    "JointArmRun": ("._sim._joint_sim", "JointArmRun"),
    "gravity_moment_Nm": ("._sim._joint_sim", "gravity_moment_Nm"),
    "joint_arm_torque_Nm": ("._sim._joint_sim", "joint_arm_torque_Nm"),
    "joint_equilibrium_rad": ("._sim._joint_sim", "joint_equilibrium_rad"),
    "simulate_joint_arm": ("._sim._joint_sim", "simulate_joint_arm"),
    "LiftingMass": ("._sim._lifting_mass", "LiftingMass"),
    "LiftingMassRun": ("._sim._lifting_mass", "LiftingMassRun"),
    "hysteresis_branches": ("._sim._lifting_mass", "hysteresis_branches"),
    "lifting_mass_equilibrium": ("._sim._lifting_mass", "lifting_mass_equilibrium"),
    "simulate_lifting_mass": ("._sim._lifting_mass", "simulate_lifting_mass"),
    "zeta_from_hysteresis": ("._sim._lifting_mass", "zeta_from_hysteresis"),
    "DampedOscillator": ("._sim._oscillator", "DampedOscillator"),
    "OscillatorRun": ("._sim._oscillator", "OscillatorRun"),
    "oscillator_response": ("._sim._oscillator", "oscillator_response"),
    "simulate_oscillator": ("._sim._oscillator", "simulate_oscillator"),
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    try:
        module, attr = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'pamid' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module, __name__), attr)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__():
    return sorted([*globals(), *_EXPORTS])


if TYPE_CHECKING:  # for type checkers and editors: the same names, imported eagerly
    from ._control._positioning import PositioningRig as PositioningRig
    from ._control._positioning import PositioningRun as PositioningRun
    from ._control._positioning import linear_rig as sarosi_linear_rig
    from ._control._positioning import positioning_metrics as positioning_metrics
    from ._control._positioning import rotary_rig as sarosi_rotary_rig
    from ._control._positioning import sarosi_from_fit_json as sarosi_from_fit_json
    from ._control._positioning import simulate_positioning as simulate_positioning
    from ._control._positioning import single_muscle_rig as sarosi_single_muscle_rig
    from ._control._positioning import wald_draws as wald_draws
    from ._control._sliding_mode import SlidingModeController as SlidingModeController
    from ._control._sliding_mode import plain_switching as plain_switching
    from ._control._sliding_mode import sliding_mode_voltage as sliding_mode_voltage
    from ._control._sliding_mode import sliding_surface as sliding_surface
    from ._control._thermal import TABLE_3_2 as TABLE_3_2
    from ._control._thermal import MuscleThermal as MuscleThermal
    from ._control._thermal import fit_table_3_2 as fit_table_3_2
    from ._control._thermal import sarosi_at_temperature as sarosi_at_temperature
    from ._control._thermal import steady_state_temperature_C as steady_state_temperature_C
    from ._control._thermal import temperature_after_C as temperature_after_C
    from ._control._valve import ProportionalValve as ProportionalValve
    from ._control._valve import orifice_mass_flow_kg_s as orifice_mass_flow_kg_s
    from ._control._valve import valve_mass_flows_kg_s as valve_mass_flows_kg_s
    from ._data._bench import BenchData as BenchData
    from ._data._bench import CensoredRowsWarning as CensoredRowsWarning
    from ._data._bench import MissingValuesWarning as MissingValuesWarning
    from ._data._bench import load_bench as load_bench
    from ._data._decay_file import DecayData as DecayData
    from ._data._decay_file import load_decay as load_decay
    from ._decays._analysis import DecayReport as DecayReport
    from ._decays._analysis import DecrementEstimate as DecrementEstimate
    from ._decays._analysis import Extrema as Extrema
    from ._decays._analysis import TrajectoryFit as TrajectoryFit
    from ._decays._analysis import analyze_decays as analyze_decays
    from ._decays._analysis import decrement_estimate as decrement_estimate
    from ._decays._analysis import find_extrema as find_extrema
    from ._decays._analysis import fit_decay_trajectories as fit_decay_trajectories
    from ._decays._analysis import log_decrement_to_zeta as log_decrement_to_zeta
    from ._decays._analysis import moment_of_inertia_eq12 as moment_of_inertia_eq12
    from ._decays._coulomb import DECAY_EFFECTS as DECAY_EFFECTS
    from ._decays._coulomb import DecayModelFit as DecayModelFit
    from ._decays._coulomb import DecayTrialModelFit as DecayTrialModelFit
    from ._decays._coulomb import coulomb_response as coulomb_response
    from ._decays._coulomb import fit_decay_models as fit_decay_models
    from ._decays._joint_fit import JointDecayFit as JointDecayFit
    from ._decays._joint_fit import fit_joint_decays as fit_joint_decays
    from ._decays._posterior import DecayPosterior as DecayPosterior
    from ._decays._posterior import DecayPredictive as DecayPredictive
    from ._decays._posterior import decay_prior as decay_prior
    from ._decays._posterior import fit_decay_mcmc as fit_decay_mcmc
    from ._diagnose._api import diagnose as diagnose
    from ._diagnose._result import Diagnosis as Diagnosis
    from ._effects._inject import InjectedCompliance as InjectedCompliance
    from ._effects._inject import InjectedCovariate as InjectedCovariate
    from ._effects._inject import InjectedDrift as InjectedDrift
    from ._effects._inject import InjectedHysteresis as InjectedHysteresis
    from ._effects._inject import InjectedTemperature as InjectedTemperature
    from ._effects._inject import InjectedViscousDamping as InjectedViscousDamping
    from ._errors import BenchDataError as BenchDataError
    from ._errors import UntrustedResultError as UntrustedResultError
    from ._fit._api import FitResult as FitResult
    from ._fit._api import bench_to_fit_data as bench_to_fit_data
    from ._fit._api import fit_least_squares as fit_least_squares
    from ._fit._batch import FitData as FitData
    from ._fit._batch import pack as pack_muscles
    from ._fit._sharding import lane_devices as lane_devices
    from ._fit._sharding import use_devices as use_devices
    from ._fit._spec import ModelDefinitionError as ModelDefinitionError
    from ._models._cullinan import Cullinan as Cullinan
    from ._models._cullinan import cullinan_force as cullinan_force
    from ._models._cullinan import cullinan_spring_rate as cullinan_spring_rate
    from ._models._cullinan import end_fitting_force as end_fitting_force
    from ._models._cullinan_presets import BraidedPam as BraidedPam
    from ._models._cullinan_presets import braided_pam as braided_pam
    from ._models._cullinan_presets import braided_pam_force_N as braided_pam_force_N
    from ._models._cullinan_presets import config_a_beta_range_rad as config_a_beta_range_rad
    from ._models._cullinan_presets import sleeve_joint_A as sleeve_joint_A
    from ._models._cullinan_presets import sleeve_joint_B as sleeve_joint_B
    from ._models._cullinan_presets import sleeve_pam as sleeve_pam
    from ._models._cullinan_presets import traditional_joint as traditional_joint
    from ._models._cullinan_presets import traditional_pam as traditional_pam
    from ._models._energy import R_AIR_J_PER_KG_K as R_AIR_J_PER_KG_K
    from ._models._energy import ROOM_TEMPERATURE_K as ROOM_TEMPERATURE_K
    from ._models._energy import TrajectoryEnergy as TrajectoryEnergy
    from ._models._energy import air_mass_kg as air_mass_kg
    from ._models._energy import compressor_work_J as compressor_work_J
    from ._models._energy import trajectory_energy_J as trajectory_energy_J
    from ._models._hysteresis import hysteresis_damping as hysteresis_damping
    from ._models._hysteresis import sarosi_force_integral as sarosi_force_integral
    from ._models._joint import (
        CULLINAN_CABLE_COMPLIANCE_MM_PER_N as CULLINAN_CABLE_COMPLIANCE_MM_PER_N,
    )
    from ._models._joint import CULLINAN_P_MAX_KPA as CULLINAN_P_MAX_KPA
    from ._models._joint import CULLINAN_PULLEY_RADIUS_MM as CULLINAN_PULLEY_RADIUS_MM
    from ._models._joint import AvailableTorque as AvailableTorque
    from ._models._joint import ClosedSystemStiffness as ClosedSystemStiffness
    from ._models._joint import IsobaricStiffness as IsobaricStiffness
    from ._models._joint import JointGeometry as JointGeometry
    from ._models._joint import MuscleState as MuscleState
    from ._models._joint import available_torque_Nm as available_torque_Nm
    from ._models._joint import closed_system_stiffness as closed_system_stiffness
    from ._models._joint import closed_system_torque_Nm as closed_system_torque_Nm
    from ._models._joint import contractions_mm as contractions_mm
    from ._models._joint import joint_stiffness_eq7_Nm_per_rad as joint_stiffness_eq7_Nm_per_rad
    from ._models._joint import joint_stiffness_Nm_per_rad as joint_stiffness_Nm_per_rad
    from ._models._joint import joint_torque_eq6_Nm as joint_torque_eq6_Nm
    from ._models._joint import joint_torque_Nm as joint_torque_Nm
    from ._models._joint import max_isobaric_stiffness as max_isobaric_stiffness
    from ._models._joint import muscle_state as muscle_state
    from ._models._joint import (
        pressures_for_torque_stiffness_kPa as pressures_for_torque_stiffness_kPa,
    )
    from ._models._protocol import ForceModel as ForceModel
    from ._models._sarosi import TABLE_3_1 as TABLE_3_1
    from ._models._sarosi import TABLE_3_1_L0_MM as TABLE_3_1_L0_MM
    from ._models._sarosi import Sarosi as Sarosi
    from ._models._sarosi import sarosi_force as sarosi_force
    from ._models._sarosi import sarosi_force_slope as sarosi_force_slope
    from ._models._sarosi import sarosi_pressure_for_force as sarosi_pressure_for_force
    from ._models._sarosi import sarosi_stiffness as sarosi_stiffness
    from ._models._sarosi import sarosi_stiffness_eq_2_9 as sarosi_stiffness_eq_2_9
    from ._models._sarosi import table_3_1 as table_3_1
    from ._models._sarosi import table_3_1_fit_json as table_3_1_fit_json
    from ._models._volume import PamVolume as PamVolume
    from ._models._volume import braid_volume_mm3 as braid_volume_mm3
    from ._models._volume import closed_system_pressure_kPa as closed_system_pressure_kPa
    from ._models._volume import sleeve_pam_volume as sleeve_pam_volume
    from ._models._volume import traditional_pam_volume as traditional_pam_volume
    from ._models._volume import volume_mm3 as pam_volume_mm3
    from ._sampling._arviz import load_inference_data as load_inference_data
    from ._sampling._mcmc import McmcBudgetWarning as McmcBudgetWarning
    from ._sampling._mcmc import McmcResult as McmcResult
    from ._sampling._mcmc import fit_mcmc as fit_mcmc
    from ._sampling._posterior import Prior as Prior
    from ._sampling._posterior import default_prior as default_prior
    from ._sim._joint_sim import JointArm as JointArm
    from ._sim._joint_sim import JointArmRun as JointArmRun
    from ._sim._joint_sim import gravity_moment_Nm as gravity_moment_Nm
    from ._sim._joint_sim import joint_arm_torque_Nm as joint_arm_torque_Nm
    from ._sim._joint_sim import joint_equilibrium_rad as joint_equilibrium_rad
    from ._sim._joint_sim import simulate_joint_arm as simulate_joint_arm
    from ._sim._lifting_mass import LiftingMass as LiftingMass
    from ._sim._lifting_mass import LiftingMassRun as LiftingMassRun
    from ._sim._lifting_mass import hysteresis_branches as hysteresis_branches
    from ._sim._lifting_mass import lifting_mass_equilibrium as lifting_mass_equilibrium
    from ._sim._lifting_mass import simulate_lifting_mass as simulate_lifting_mass
    from ._sim._lifting_mass import zeta_from_hysteresis as zeta_from_hysteresis
    from ._sim._oscillator import DampedOscillator as DampedOscillator
    from ._sim._oscillator import OscillatorRun as OscillatorRun
    from ._sim._oscillator import oscillator_response as oscillator_response
    from ._sim._oscillator import simulate_oscillator as simulate_oscillator
    from ._virtual._braided import StaticBenchProtocol as StaticBenchProtocol
    from ._virtual._braided import fit_cullinan_presets as fit_cullinan_presets
    from ._virtual._braided import simulate_braided_pam_bench as simulate_braided_pam_bench
    from ._virtual._decay import DecayProtocol as DecayProtocol
    from ._virtual._decay import simulate_decays as simulate_decays
    from ._virtual._isometric import IsometricProtocol as IsometricProtocol
    from ._virtual._isometric import simulate_isometric_bench as simulate_isometric_bench
    from ._virtual._isometric import virtual_lab_file as virtual_lab_file
    from ._virtual._isometric import write_bench_csv as write_bench_csv
    from ._virtual._joint import DeflectionProtocol as DeflectionProtocol
    from ._virtual._joint import JointSweepProtocol as JointSweepProtocol
    from ._virtual._joint import deflection_test_stiffness as deflection_test_stiffness
    from ._virtual._joint import simulate_deflection_test as simulate_deflection_test
    from ._virtual._joint import simulate_joint_sweep as simulate_joint_sweep
    from ._virtual._sweeps import SarosiProtocol as SarosiProtocol
    from ._virtual._sweeps import simulate_sarosi_bench as simulate_sarosi_bench

__version__ = importlib.metadata.version("pamid")
