"""The bundled default data set of ``pamid demo``, and how it was made.

``pamid/data/sarosi_dmsp20_400_virtual.csv`` is NOT a measurement. It was produced by pamid's
own virtual bench (:func:`pamid.simulate_sarosi_bench`) from the constants of Sárosi
Table 3-1 (DMSP-20-400N, l0 = 400 mm), with the protocol below and the PRNG key
``jax.random.key(DEFAULT_SEED)``. ``python scripts/make_default_data.py`` writes it again;
a test checks that the file and a fresh simulation agree.
"""

from __future__ import annotations

from pathlib import Path

import jax

from ._sweeps import SarosiProtocol, simulate_sarosi_bench

DEFAULT_SEED = 20130
DEFAULT_FILE = "sarosi_dmsp20_400_virtual.csv"


def default_protocol() -> SarosiProtocol:
    """Sárosi's protocol (5 pressures, 30 points, both sweeps, 5 repeats averaged) with
    2 N load-cell noise and a hysteresis loop of ±3 N per bar."""
    return SarosiProtocol(min_force_N=10.0, noise_sd_N=2.0, hysteresis_N_per_bar=3.0)


def default_bench_path() -> Path:
    """The bundled data set (a virtual bench of Table 3-1's muscle; module text): the file
    ``pamid demo`` fits, for trying pamid without data of one's own."""
    return Path(__file__).resolve().parent.parent / "data" / DEFAULT_FILE


def simulate_default_bench():
    """The default data set, simulated afresh (a pandas DataFrame)."""
    from .._models._sarosi import table_3_1

    return simulate_sarosi_bench(
        jax.random.key(DEFAULT_SEED), table_3_1(), default_protocol(), muscle_ids=["DMSP-20-400N"]
    )
