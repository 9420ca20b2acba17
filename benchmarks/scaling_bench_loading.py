"""Scaling of bench loading with the number of muscles (helper of fit_batch.py).

    .venv/bin/python benchmarks/scaling_bench_loading.py [--sizes 1000 2000 4000]

A small CSV (10 rows per muscle, so that row count does not dominate) is loaded with
``pamid.load_bench`` and packed with ``pamid.bench_to_fit_data``; once more with a single
censored row (force exactly 0 N). If a step is linear in the number of muscles its time
doubles with N; a step that filters the whole table once per muscle grows fourfold.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

import pamid


def frame(n_muscles: int, rows: int = 10) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "muscle": np.repeat([f"M{i:05d}" for i in range(n_muscles)], rows),
            "pressure_kPa": 300.0,
            "contraction_pct": np.tile(np.linspace(0.0, 20.0, rows), n_muscles),
            "force_N": 100.0,
            "l0_mm": 400.0,
        }
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 2000, 4000])
    args = parser.parse_args(argv)
    print(
        f"{'muscles':>8} {'rows':>7} {'load_bench':>11} {'bench_to_fit_data':>18} "
        f"{'load_bench, 1 censored row':>27}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for m in args.sizes:
            f = frame(m)
            path = Path(tmp) / f"b{m}.csv"
            f.to_csv(path, index=False)
            t0 = time.perf_counter()
            bench = pamid.load_bench(path)
            t1 = time.perf_counter()
            pamid.bench_to_fit_data(bench)
            t2 = time.perf_counter()
            f.loc[0, "force_N"] = 0.0
            f.to_csv(path, index=False)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", pamid.CensoredRowsWarning)
                t3 = time.perf_counter()
                pamid.load_bench(path)
                t4 = time.perf_counter()
            print(
                f"{m:>8} {len(f):>7} {t1 - t0:>10.2f}s {t2 - t1:>17.2f}s {t4 - t3:>26.2f}s",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
