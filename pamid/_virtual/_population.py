"""A virtual population of muscles of many resting lengths, with a known population law.

Each muscle is tested as the AARL lab tests its 10 mm muscles (``aarl_festo10mm_isometric``
in the shared data): clamped at 0, 25, 50 and 75 % of its maximal contraction ε_max while
the pressure steps up to 620 kPa, each length ``repeats`` times. The true force is the
population law at the muscle's descriptors — by default the normalized law of Bolen et al.
2026 (:class:`pamid._models._bolen.Bolen2026`) with ε_max = e0 + e1·ln(l0/200 mm) — times a
factor of the muscle's own, exp(τ·z) with z standard normal (the spread of muscles about the
population: tube batch, clamping), plus white noise. The file holds ``muscle``, ``l0_mm``,
``l620_mm`` (= l0·(1 − ε_max)), ``diameter_mm``, ``trial``, ``pressure_kPa``,
``contraction_pct`` and ``force_N``: the bench-file format; rows where the true force is not
positive (a slack muscle) are left out, as the AARL file leaves them out.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._models._bolen import Bolen2026

#: ε_max of the virtual population, (e0 [%], e1 [% per e-fold of l0]) about l0 = 200 mm:
#: near the AARL file's (15.7 % at 83 mm, 17.8 % at 382 mm).
EMAX_LAW_PCT = (16.8, 1.4)
EMAX_L0_REF_MM = 200.0


def population_emax_pct(l0_mm, law=EMAX_LAW_PCT):
    """ε_max in % of the virtual population at resting lengths ``l0_mm``."""
    return law[0] + law[1] * np.log(np.asarray(l0_mm, np.float64) / EMAX_L0_REF_MM)


def simulate_population_bench(
    key: jax.Array,
    l0_mm: Sequence[float],
    *,
    law: Bolen2026 | Callable = Bolen2026(),
    emax_law: tuple[float, float] = EMAX_LAW_PCT,
    spread: float = 0.0,
    noise_N: float = 2.0,
    pressures_kPa: Sequence[float] = tuple(np.linspace(20.0, 620.0, 16)),
    fractions: Sequence[float] = (0.0, 0.25, 0.5, 0.75),
    repeats: int = 2,
    diameter_mm: float = 10.0,
    muscle_ids: Sequence[str] | None = None,
) -> pd.DataFrame:
    """Isometric tests of muscles of resting lengths ``l0_mm`` drawn from a population with
    a known law (module text).

    Args:
        key: the only source of randomness.
        l0_mm: one resting length per muscle.
        law: the population law, a :class:`Bolen2026` (its constants) or any
            ``law(pressure_kPa, contraction_ratio, l0_mm, emax_ratio) -> force_N``.
        emax_law: (e0, e1) of ε_max = e0 + e1·ln(l0/200 mm), in %.
        spread: τ of the muscles' factor exp(τ·z) about the law (0: every muscle on it).
        noise_N: standard deviation of the white force noise.
        pressures_kPa, fractions, repeats: the test: each contraction fraction of ε_max
            held while the pressure takes each level, ``repeats`` times.
    """
    l0 = np.asarray(l0_mm, dtype=np.float64)
    m = l0.size
    ids = list(muscle_ids) if muscle_ids is not None else [f"V{i:02d}" for i in range(m)]
    emax = population_emax_pct(l0, emax_law)
    p = np.asarray(pressures_kPa, np.float64)
    fr = np.asarray(fractions, np.float64)
    # (muscle, fraction, repeat, pressure) grid, flattened in that order.
    mi, fi, ri, pi = (a.ravel() for a in np.meshgrid(np.arange(m), np.arange(fr.size),
                                                     np.arange(repeats), np.arange(p.size),
                                                     indexing="ij"))
    contraction = fr[fi] * emax[mi]
    k_spread, k_noise = jax.random.split(key)
    factor = np.exp(spread * np.asarray(jax.random.normal(k_spread, (m,))))
    true = np.asarray(law(jnp.asarray(p[pi]), jnp.asarray(contraction / 100.0),
                          jnp.asarray(l0[mi]), jnp.asarray(emax[mi] / 100.0)))
    force = true * factor[mi] + noise_N * np.asarray(
        jax.random.normal(k_noise, (mi.size,)))
    keep = true > 0.0  # a slack muscle pushes nothing: its rows are not in a bench file
    return pd.DataFrame({
        "muscle": np.asarray(ids)[mi],
        "l0_mm": l0[mi],
        "l620_mm": (l0 * (1.0 - emax / 100.0))[mi],
        "diameter_mm": np.full(mi.size, diameter_mm),
        "trial": [f"k{int(round(100 * fr[f]))}_r{r}" for f, r in zip(fi, ri, strict=True)],
        "pressure_kPa": p[pi],
        "contraction_pct": contraction,
        "force_N": force,
    })[keep].reset_index(drop=True)
