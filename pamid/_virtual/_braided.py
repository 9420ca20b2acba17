"""A virtual static bench for the physical braided muscles of
:mod:`pamid._models._cullinan_presets`, and the fit of Cullinan's eq. 3 to it that gives the
stored presets (``TRADITIONAL_FIT``, ``SLEEVE_FIT`` there). The bench is the kind of test
behind eq. 3's A–E: force against contraction at constant pressure, both sweep directions,
load-cell noise and resolution. Units: N, kPa (gauge), mm, s."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pandas as pd

from .._fit._api import fit_least_squares
from .._lanes._batch import pack
from .._models._cullinan_presets import (
    PRESET_SEED,
    TEST_PRESSURES_KPA,
    BraidedPam,
    braided_pam_force_N,
    sleeve_braided_pam,
    traditional_braided_pam,
)

__all__ = ["StaticBenchProtocol", "fit_cullinan_presets", "simulate_braided_pam_bench"]


@dataclasses.dataclass(frozen=True)
class StaticBenchProtocol:
    """Static force–contraction tests of one PAM (the kind of test behind eq. 3's A–E).

    Attributes:
        pressures_kPa: constant gauge pressures, one pair of sweeps each.
        points_per_curve: samples per sweep.
        max_contraction_mm: the rig's travel; a sweep also stops where the true force falls
            to ``min_force_N`` (a muscle cannot hold a length at which it would push).
        min_force_N: see above.
        directions: +1 contracting sweep, −1 extending sweep.
        noise_sd_N: load-cell noise, standard deviation of one reading.
        force_resolution_N: the load cell's reading step (0 for none).
        hysteresis_N: half height of a friction loop: the contracting sweep reads this much
            less, the extending one this much more (0: none).
        seconds_per_point: time between samples, for the ``time_s`` column.
    """

    pressures_kPa: tuple[float, ...] = TEST_PRESSURES_KPA
    points_per_curve: int = 20
    max_contraction_mm: float = 60.0
    min_force_N: float = 20.0
    directions: tuple[int, ...] = (1, -1)
    noise_sd_N: float = 2.0
    force_resolution_N: float = 0.1
    hysteresis_N: float = 0.0
    seconds_per_point: float = 2.0

    def __post_init__(self):
        if self.points_per_curve < 2:
            raise ValueError("points_per_curve must be at least 2")
        if any(d not in (1, -1) for d in self.directions):
            raise ValueError("directions must be +1 (contracting) or -1 (extending)")
        if self.max_contraction_mm <= 0:
            raise ValueError("max_contraction_mm must be positive")


def _sweep_end_mm(muscle: BraidedPam, pressure_kPa: float, protocol: StaticBenchProtocol):
    """Contraction at which the true force falls to ``min_force_N``, capped at the travel."""
    grid = np.linspace(0.0, protocol.max_contraction_mm, 2001)
    force = np.asarray(braided_pam_force_N(muscle, pressure_kPa, grid))
    below = np.nonzero(force < protocol.min_force_N)[0]
    if below.size == 0:
        return protocol.max_contraction_mm
    i = below[0]
    if i == 0:
        return 0.0
    # Linear interpolation between the bracketing grid points.
    f0, f1 = force[i - 1] - protocol.min_force_N, force[i] - protocol.min_force_N
    return float(grid[i - 1] + (grid[i] - grid[i - 1]) * f0 / (f0 - f1))


def simulate_braided_pam_bench(
    key: jax.Array,
    muscle: BraidedPam,
    protocol: StaticBenchProtocol = StaticBenchProtocol(),
    muscle_id: str = "M0001",
) -> pd.DataFrame:
    """Static bench data of the physical muscle, in pamid's bench format.

    Returns a table with muscle, pressure_kPa, contraction_mm, length_mm, l0_mm, force_N,
    direction and time_s; force is the load-cell reading (noise, resolution, hysteresis).
    ``key`` is the only source of randomness.
    """
    l0 = float(muscle.volume.active_length_mm)
    u = np.linspace(0.0, 1.0, protocol.points_per_curve)
    blocks = []
    for p in protocol.pressures_kPa:
        end = _sweep_end_mm(muscle, p, protocol)
        for d in protocol.directions:
            y = end * (u if d == 1 else u[::-1])
            blocks.append((p, d, y))
    y_all = np.concatenate([b[2] for b in blocks])
    p_all = np.concatenate([np.full(b[2].size, b[0]) for b in blocks])
    d_all = np.concatenate([np.full(b[2].size, b[1]) for b in blocks])
    f_true = np.asarray(braided_pam_force_N(muscle, p_all, y_all))
    f_true = f_true - d_all * protocol.hysteresis_N
    noise = protocol.noise_sd_N * np.asarray(jax.random.normal(key, f_true.shape))
    reading = f_true + noise
    if protocol.force_resolution_N > 0:
        reading = np.round(reading / protocol.force_resolution_N) * protocol.force_resolution_N
    return pd.DataFrame(
        {
            "muscle": muscle_id,
            "pressure_kPa": p_all,
            "contraction_mm": y_all,
            "length_mm": l0 - y_all,
            "l0_mm": l0,
            "force_N": np.round(reading, 6),
            "direction": d_all.astype(int),
            "time_s": protocol.seconds_per_point * np.arange(y_all.size, dtype=float),
        }
    )


def fit_cullinan_presets(
    key: jax.Array | None = None,
    protocol: StaticBenchProtocol = StaticBenchProtocol(),
    muscles: dict[str, BraidedPam] | None = None,
):
    """Fit eq. 3 (A–E) to virtual static benches of physical muscles, one batched solve.

    ``muscles`` maps names to physical muscles; by default "traditional" and "sleeve"
    (:func:`traditional_braided_pam`, :func:`sleeve_braided_pam`). Each muscle gets its own
    key, split from ``key`` (default ``jax.random.key(PRESET_SEED)``). Returns
    ``(result, frames)``: a :class:`pamid.FitResult` with one muscle per entry, in order,
    and the bench tables that were fitted. The defaults give the stored presets.
    """
    if key is None:
        key = jax.random.key(PRESET_SEED)
    if muscles is None:
        muscles = {"traditional": traditional_braided_pam(), "sleeve": sleeve_braided_pam()}
    keys = jax.random.split(key, len(muscles))
    frames = [
        simulate_braided_pam_bench(k, muscle, protocol, name)
        for k, (name, muscle) in zip(keys, muscles.items())
    ]
    groups = [
        (
            (f["pressure_kPa"].to_numpy(), f["contraction_mm"].to_numpy()),
            f["force_N"].to_numpy(),
        )
        for f in frames
    ]
    result = fit_least_squares(pack(groups), "cullinan", muscles=tuple(muscles))
    return result, frames
