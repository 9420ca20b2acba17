"""Time the candidate ``.xlsx`` readers on a 100,000-row bench sheet.

    .venv/bin/python benchmarks/read_xlsx.py [--rows 100000] [--repeats 3]

Writes one sheet (openpyxl, write-only mode) with the columns of a bench file — muscle
(text), trial (text), time_s, pressure_kPa, contraction_pct, force_N, direction,
temperature_C — then reads every cell into Python columns with:

* ``openpyxl`` — ``load_workbook(read_only=True, data_only=True)``, ``iter_rows(values_only=True)``;
* ``python-calamine`` — ``CalamineWorkbook.from_path(...).get_sheet_by_index(0).to_python()``;
* ``fastexcel`` — ``read_excel(...).load_sheet(0, header_row=None)``, then its Arrow columns
  (skipped when not installed: pamid does not depend on it);
* ``load_bench`` — pamid's loader on the same file (whichever reader it uses, plus the checks).

Times are wall-clock seconds (median of the repeats), in this process.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
import warnings
from pathlib import Path


def write_sheet(path: Path, rows: int) -> None:
    import numpy as np
    from openpyxl import Workbook

    rng = np.random.default_rng(0)
    wb = Workbook(write_only=True)
    ws = wb.create_sheet("Data")
    ws.append(["muscle", "trial", "time_s", "pressure_kPa", "contraction_pct", "force_N",
               "direction", "temperature_C"])
    per = 500
    for i in range(rows):
        k = i % per
        ws.append([f"M{i // (per * 4):03d}", f"T{(i // per) % 4}", k * 0.01,
                   float(np.round(rng.uniform(0, 600), 3)), float(np.round(k / per * 30, 4)),
                   float(np.round(rng.uniform(1, 900), 3)), 1 if k < per // 2 else -1,
                   float(np.round(21 + rng.normal(), 2))])
    wb.save(path)


def read_openpyxl(path: Path) -> int:
    from openpyxl import load_workbook

    wb = load_workbook(path, read_only=True, data_only=True)
    try:
        rows = list(wb.worksheets[0].iter_rows(values_only=True))
    finally:
        wb.close()
    columns = list(zip(*rows, strict=True))
    return len(columns[0]) - 1


def read_calamine(path: Path) -> int:
    from python_calamine import CalamineWorkbook

    rows = CalamineWorkbook.from_path(str(path)).get_sheet_by_index(0).to_python()
    columns = list(zip(*rows, strict=True))
    return len(columns[0]) - 1


def read_fastexcel(path: Path) -> int:
    import fastexcel

    sheet = fastexcel.read_excel(str(path)).load_sheet(0, header_row=None)
    table = sheet.to_arrow()
    columns = [table.column(j).to_pylist() for j in range(table.num_columns)]
    return len(columns[0]) - 1


def read_load_bench(path: Path) -> int:
    import pamid

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return len(pamid.load_bench(path).frame)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.xlsx"
        t0 = time.perf_counter()
        write_sheet(path, args.rows)
        print(f"wrote {args.rows} rows ({path.stat().st_size / 1e6:.1f} MB) in "
              f"{time.perf_counter() - t0:.1f} s")
        for label, read in (("openpyxl", read_openpyxl), ("python-calamine", read_calamine),
                            ("fastexcel", read_fastexcel), ("load_bench", read_load_bench)):
            walls = []
            try:
                for _ in range(args.repeats):
                    t0 = time.perf_counter()
                    n = read(path)
                    walls.append(time.perf_counter() - t0)
            except ImportError as exc:  # fastexcel is not a dependency of pamid
                print(f"{label:16} not installed ({exc.name})")
                continue
            print(f"{label:16} {statistics.median(walls):7.2f} s (min {min(walls):.2f} s), "
                  f"{n} rows", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
