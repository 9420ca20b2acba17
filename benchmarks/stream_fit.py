"""`pamid fit --stream` on a bench file bigger than memory, beside the SciPy loop.

    .venv/bin/python benchmarks/stream_fit.py                          # 1,000,000 muscles
    .venv/bin/python benchmarks/stream_fit.py --muscles 20000 --file /tmp/b20k.parquet

The file (made once, then reused; never inside the repository): 10,000 virtual Sárosi
muscles (Table 3-1 × (1 + 3 % noise), Sárosi's sweeps, 300 rows each, ``pamid.
simulate_sarosi_bench``), repeated under new muscle names until ``--muscles``, written a
10,000-muscle row group at a time (1,000,000 muscles: 300,000,000 rows, ~1.6 GB of
Parquet, ~19 GB as float64 arrays: more than this machine's memory).

Timed, each a process of its own (wall clock, peak RSS from ``wait4``): `pamid fit FILE
--stream --intervals wald --json` with an empty compilation cache, then again with the
cache it left; beside them, `baseline_curve_fit_script.py` (pandas + ``curve_fit``, one
muscle at a time, standard errors: the loop a user writes) on the first 10,000 muscles,
extrapolated linearly to the file's muscles. Prints one table and, with ``--json``, the rows.
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

ROOT = Path(__file__).resolve().parents[1]
BASE = 10_000


def make_file(path: Path, muscles: int) -> None:
    import jax
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    import pamid

    z = np.asarray(jax.random.normal(jax.random.key(0), (BASE, 6)))
    theta = np.asarray(pamid.sarosi.table_3_1().to_vector()) * (1.0 + 0.03 * z)
    frame = pamid.simulate_sarosi_bench(
        jax.random.key(1), pamid.Sarosi.from_vector(theta), pamid.SarosiProtocol(min_force_N=10.0),
        muscle_ids=[f"M{i:07d}" for i in range(BASE)])
    rows = len(frame) // BASE
    table = pa.Table.from_pandas(frame, preserve_index=False)
    tmp = path.with_name(path.name + ".part")
    with pq.ParquetWriter(tmp, table.schema) as writer:
        for start in range(0, muscles, BASE):
            n = min(BASE, muscles - start)
            names = pa.array(np.repeat([f"M{start + i:07d}" for i in range(n)], rows),
                             type=table.schema.field(0).type)
            part = table.slice(0, n * rows).set_column(0, table.schema.field(0), names)
            writer.write_table(part, row_group_size=len(part))
            print(f"\rwriting {path}: {start + n:,} of {muscles:,} muscles", end="",
                  file=sys.stderr, flush=True)
    os.replace(tmp, path)
    print(file=sys.stderr)


def measured(cmd: list[str], env: dict) -> tuple[float, float, int, str]:
    """Wall seconds, peak RSS (MB, GNU time's %M: a child forked from this process would
    inherit its high-water mark), exit code and stdout of one process."""
    with tempfile.NamedTemporaryFile("r", suffix=".rss") as rss:
        t0 = time.perf_counter()
        proc = subprocess.run(["/usr/bin/time", "-f", "%M", "-o", rss.name, *cmd], env=env,
                              cwd=ROOT, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        kb = float(rss.read().split()[-1])
    return wall, kb / 1024, proc.returncode, proc.stdout


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--muscles", type=int, default=1_000_000)
    ap.add_argument("--file", type=Path, default=Path(tempfile.gettempdir())
                    / "pamid_stream_1M.parquet")
    ap.add_argument("--chunk-rows", type=int, default=1_000_000)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--make", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.make:
        make_file(args.file, args.muscles)
        return 0
    if args.file.exists():
        import pyarrow.parquet as pq

        have = pq.ParquetFile(args.file).metadata.num_rows
        print(f"using {args.file} ({have:,} rows)", file=sys.stderr)
    else:  # in a process of its own: this one stays small (see measured)
        subprocess.run([sys.executable, __file__, "--make", "--muscles", str(args.muscles),
                        "--file", str(args.file)], check=True)
    py = sys.executable
    rows = []
    with tempfile.TemporaryDirectory(prefix="pamid-stream-") as tmp:
        env = {**os.environ, "PAMID_CACHE_DIR": str(Path(tmp) / "cache")}
        for run in ("empty cache", "warm cache"):
            out = Path(tmp) / run.replace(" ", "_")
            wall, rss, code, text = measured(
                [py, "-m", "pamid", "fit", str(args.file), "--stream", "--chunk-rows",
                 str(args.chunk_rows), "--intervals", "wald", "--json", "--out", str(out)], env)
            summary = json.loads(text) if code in (0, 1) else {}
            rows.append({"run": f"pamid fit --stream, {run}", "muscles": summary.get("muscles"),
                         "wall_s": round(wall, 2), "peak_MB": round(rss), "exit": code,
                         "read_s": summary.get("read_s"), "fit_s": summary.get("fit_s"),
                         "not_converged": summary.get("not_converged")})
        import pandas as pd
        import pyarrow.parquet as pq

        head = pq.ParquetFile(args.file).read_row_group(0).to_pandas()
        head = head[head["muscle"].isin(pd.unique(head["muscle"])[:BASE])]
        csv = Path(tmp) / "first.csv"
        head.to_csv(csv, index=False)
        n_ref = head["muscle"].nunique()
        wall, rss, code, _ = measured(
            [py, str(ROOT / "benchmarks" / "baseline_curve_fit_script.py"), str(csv)], env)
        muscles = rows[0]["muscles"] or args.muscles
        rows.append({"run": f"SciPy curve_fit loop, {n_ref:,} muscles", "muscles": n_ref,
                     "wall_s": round(wall, 2), "peak_MB": round(rss), "exit": code})
        rows.append({"run": f"SciPy loop extrapolated to {muscles:,}", "muscles": muscles,
                     "wall_s": round(wall * muscles / n_ref, 1), "peak_MB": None, "exit": None})
    ref = rows[-1]["wall_s"]
    print(f"stream_fit, {time.strftime('%Y-%m-%dT%H:%M:%S%z')}; {os.cpu_count()} CPUs; "
          f"load average {os.getloadavg()[0]:.2f}")
    for r in rows:
        speed = f"  {ref / r['wall_s']:5.2f}× the SciPy loop" if r["run"].startswith("pamid") \
            else ""
        mb = f"{r['peak_MB']:>7,} MB" if r["peak_MB"] is not None else " " * 10
        print(f"  {r['run']:<42} {r['muscles'] or 0:>10,} muscles  {r['wall_s']:>9.2f} s  "
              f"{mb}{speed}")
    if args.json:
        print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
