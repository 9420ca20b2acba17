"""Time ``pamid.load_bench`` on a large CSV against a plain ``pandas.read_csv``.

    .venv/bin/python benchmarks/load_bench.py [--muscles 10000] [--csv PATH] [--repeats 3]

Writes a virtual-bench CSV of M muscles (Sárosi Table 3-1 constants × (1 + 0.03·normal),
``pamid.simulate_sarosi_bench`` with ``SarosiProtocol(min_force_N=10.0)``: 300 rows per
muscle, columns muscle, pressure_kPa, length_mm, l0_mm, contraction_pct, force_N,
direction, time_s), then loads it in fresh subprocesses, one per contender and repeat, so
that each peak resident memory (``resource.getrusage(RUSAGE_SELF).ru_maxrss``) is that
contender's alone (every child imports pandas and pamid first):

* ``pandas.read_csv`` — the file into a DataFrame, nothing checked (the yardstick);
* ``load_bench`` — pamid's loader (fast path for clean, simple CSV files);
* ``load_bench, slow path`` — the same with the fast path switched off (``PAMID_FAST_CSV=0``:
  the cell-by-cell reader every file went through before), unless ``--skip-slow``;
* ``load_bench, bar`` — the file with its pressure in bar (``pressure_bar``), so that the
  exact decimal conversion of the pressure text is included.

Times are wall-clock seconds of the call alone (imports excluded). Memory: the peak RSS of
the whole process, and the growth, i.e. that peak minus the RSS right before the call (so
without the imports).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHILD = r"""
import json, resource, sys, time, warnings
import pandas as pd
import pamid
mode, path = sys.argv[1], sys.argv[2]
def rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
def current_mb():
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * resource.getpagesize() / 2**20
    except OSError:
        return rss_mb()
before = current_mb()
t0 = time.perf_counter()
if mode == "pandas":
    rows = len(pd.read_csv(path))
else:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pamid.CensoredRowsWarning)
        rows = len(pamid.load_bench(path).frame)
wall = time.perf_counter() - t0
print(json.dumps({"wall_s": wall, "peak_mb": rss_mb(), "before_mb": before, "rows": rows}))
"""


def write_csv(n_muscles: int, path: Path, seed: int = 1) -> None:
    import jax
    import numpy as np

    import pamid

    z = np.random.default_rng(seed).standard_normal((n_muscles, 6))
    thetas = np.asarray(pamid.sarosi.table_3_1().to_vector(), dtype=float) * (1.0 + 0.03 * z)
    frame = pamid.simulate_sarosi_bench(
        jax.random.key(seed),
        pamid.Sarosi.from_vector(thetas),
        pamid.SarosiProtocol(min_force_N=10.0),
    )
    frame.to_csv(path, index=False)


def run_child(mode: str, path: Path) -> dict:
    # The slow path: pamid's public switch, the cell-by-cell reader for every CSV file.
    env = dict(os.environ, PAMID_FAST_CSV="0" if mode == "slow" else "1")
    out = subprocess.run(
        [sys.executable, "-c", CHILD, mode, str(path)],
        check=True,
        capture_output=True,
        text=True,
        env=env,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--muscles", type=int, default=10_000)
    parser.add_argument("--csv", type=Path, help="use (or write, if missing) this CSV file")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-slow", action="store_true", help="do not time the slow path")
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        path = args.csv or Path(tmp) / f"bench_{args.muscles}.csv"
        if not path.exists():
            t0 = time.perf_counter()
            write_csv(args.muscles, path)
            print(f"wrote {path} in {time.perf_counter() - t0:.1f} s", flush=True)
        # The same data with the pressure in bar: exact decimal text, e.g. 300 kPa -> 3 bar.
        bar = Path(tmp) / "bench_bar.csv"
        import pandas as pd

        frame = pd.read_csv(path)
        rows = len(frame)
        frame.insert(1, "pressure_bar", frame.pop("pressure_kPa") / 100.0)
        frame.to_csv(bar, index=False)
        del frame
        size_mb = path.stat().st_size / 1e6
        print(f"file: {path} ({size_mb:.1f} MB, {rows} rows)")

        modes = [("pandas", "pandas.read_csv", path), ("fast", "load_bench", path)]
        if not args.skip_slow:
            modes.append(("slow", "load_bench, slow path", path))
        modes.append(("fast", "load_bench, bar", bar))
        print(f"{'':24} {'median s':>9} {'min s':>7} {'peak RSS MB':>12} {'growth MB':>10}")
        for mode, label, file in modes:
            repeats = 1 if mode == "slow" else args.repeats
            results = [run_child(mode, file) for _ in range(repeats)]
            walls = sorted(r["wall_s"] for r in results)
            peak = max(r["peak_mb"] for r in results)
            grow = max(r["peak_mb"] - r["before_mb"] for r in results)
            print(
                f"{label:24} {walls[len(walls) // 2]:>9.2f} {walls[0]:>7.2f} {peak:>12.0f} "
                f"{grow:>10.0f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
