"""Time ``pamid.load_bench`` on wide CSV files: 10 rows and thousands of columns.

    .venv/bin/python benchmarks/wide_csv.py [--columns 5000,10000,20000,40000]
        [--rows 10] [--timeout 300]

Each file holds pressure_kPa, force_N and contraction_pct and then numeric covariates
``x3``, ``x4``, ... (random normal numbers written with 4 decimals), 10 data rows. Two
variants per width:

* ``plain``: no quotes, read by the fast column-wise reader;
* ``quoted``: every header quoted (as spreadsheets export them), read by the cell-by-cell
  reader.

Each load runs in a fresh subprocess (imports excluded from the time); a load that takes
longer than ``--timeout`` seconds is reported as such. The loader must be linear in the
number of columns: the time per 1,000 columns is printed too.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CHILD = r"""
import json, sys, time, warnings
import pamid
path = sys.argv[1]
t0 = time.perf_counter()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    bench = pamid.load_bench(path)
print(json.dumps({"wall_s": time.perf_counter() - t0, "columns": bench.frame.shape[1]}))
"""


def write_wide(path: Path, n_columns: int, n_rows: int, quoted: bool) -> None:
    rng = np.random.default_rng(0)
    names = ["pressure_kPa", "force_N", "contraction_pct"]
    names += [f"x{j}" for j in range(3, n_columns)]
    head = ",".join(f'"{name}"' if quoted else name for name in names)
    lines = [head]
    for i in range(n_rows):
        cells = [f"{100 + 50 * i}", f"{200 - 10 * i}", f"{2.0 * i}"]
        cells += [f"{v:.4f}" for v in rng.normal(size=n_columns - 3)]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--columns", default="5000,10000,20000,40000")
    parser.add_argument("--rows", type=int, default=10)
    parser.add_argument("--timeout", type=float, default=300.0)
    args = parser.parse_args()
    widths = [int(w) for w in args.columns.split(",")]
    print("| columns | variant | load_bench | per 1,000 columns |")
    print("| --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for width in widths:
            for variant in ("plain", "quoted"):
                path = Path(tmp) / f"wide_{width}_{variant}.csv"
                write_wide(path, width, args.rows, variant == "quoted")
                try:
                    out = subprocess.run([sys.executable, "-c", CHILD, str(path)],
                                         capture_output=True, text=True, check=True,
                                         timeout=args.timeout)
                except subprocess.TimeoutExpired:
                    print(f"| {width:,} | {variant} | > {args.timeout:g} s (stopped) | |",
                          flush=True)
                    continue
                except subprocess.CalledProcessError as exc:
                    sys.exit(exc.stderr)
                result = json.loads(out.stdout)
                wall = result["wall_s"]
                print(f"| {width:,} | {variant} | {wall:.2f} s | {1000 * wall / width:.3f} s |",
                      flush=True)


if __name__ == "__main__":
    main()
