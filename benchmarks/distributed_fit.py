"""`pamid fit --stream` in one process and in several, on one Parquet bench file.

    .venv/bin/python benchmarks/distributed_fit.py BENCH.parquet --processes 2
    # a virtual bench file of M Sárosi muscles to time (refuses to overwrite a file):
    .venv/bin/python benchmarks/distributed_fit.py BENCH.parquet --simulate M

The several-process fit is the command's own (``pamid fit --stream --processes N`` on one
machine; ``--coordinator HOST:PORT --num-processes N --process-id I`` for one process per
machine or GPU: :mod:`pamid._commands.fit_processes`). This script times it beside the
one-process run on the same file (each a process of its own, the compilation cache warm
from a first run) and checks that both give the same constants, in the same order.
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


def simulate(path: Path, n_muscles: int, seed: int) -> None:
    """A virtual bench of ``n_muscles`` Sárosi muscles (Table 3-1 × (1 + 0.03·normal))."""
    import jax
    import numpy as np

    import pamid
    from pamid.io import write_frame_atomic

    if path.exists():
        raise SystemExit(f"{path} exists; not overwriting it")
    key_theta, key_noise = jax.random.split(jax.random.key(seed))
    z = np.asarray(jax.random.normal(key_theta, (n_muscles, 6)))
    theta = np.asarray(pamid.sarosi.table_3_1().to_vector()) * (1.0 + 0.03 * z)
    frame = pamid.simulate_sarosi_bench(
        key_noise, pamid.Sarosi.from_vector(theta), pamid.SarosiProtocol(min_force_N=10.0)
    )
    write_frame_atomic(path, frame)
    print(f"wrote {path}: {n_muscles} muscles, {len(frame)} rows")


def timed_fit(bench: Path, out: Path, extra: list[str], intervals: str) -> tuple[float, dict]:
    cmd = [sys.executable, "-m", "pamid", "fit", str(bench), "--stream", "--intervals",
           intervals, "--json", "--out", str(out), *extra]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(cmd)} ended {proc.returncode}:\n{proc.stderr[-2000:]}")
    return wall, json.loads(proc.stdout)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bench", type=Path, help="bench file (Parquet) with a muscle column")
    ap.add_argument("--processes", type=int, default=2)
    ap.add_argument("--intervals", default="wald", help="comma-separated: wald,profile")
    ap.add_argument("--simulate", type=int, metavar="M", help="write a virtual bench and stop")
    ap.add_argument("--seed", type=int, default=0, help="for --simulate")
    args = ap.parse_args(argv)
    if args.simulate:
        simulate(args.bench, args.simulate, args.seed)
        return 0
    import pandas as pd

    with tempfile.TemporaryDirectory(prefix="pamid-distributed-") as tmp:
        timed_fit(args.bench, Path(tmp) / "warm", [], args.intervals)  # fills the cache
        one_s, one = timed_fit(args.bench, Path(tmp) / "one", [], args.intervals)
        many_s, many = timed_fit(args.bench, Path(tmp) / "many",
                                 ["--processes", str(args.processes)], args.intervals)
        a = pd.read_parquet(Path(tmp) / "one" / "constants.parquet")
        b = pd.read_parquet(Path(tmp) / "many" / "constants.parquet")
    same_order = list(a["muscle"]) == list(b["muscle"])
    names = one["constants"]
    diff = float(((b[names] - a[names]).abs() / a[names].abs().clip(lower=1e-300)).max().max())
    print(f"distributed_fit, {time.strftime('%Y-%m-%dT%H:%M:%S%z')}; {os.cpu_count()} CPUs; "
          f"{one['muscles']:,} muscles, {one['rows']:,} rows")
    print(f"  one process            {one_s:8.2f} s  (read {one['read_s']:.1f} s, fit "
          f"{one['fit_s']:.1f} s)")
    print(f"  {args.processes} processes            {many_s:8.2f} s  ({one_s / many_s:.2f}× "
          "the one process)")
    for p in many.get("processes", []):
        print(f"    process {p['process']}: {p['muscles']:,} muscles, read {p['read_s']:.1f} s, "
              f"fit {p['fit_s']:.1f} s, {p['peak_rss_MB']:,.0f} MB, devices {p['devices']}")
    print(f"  same muscles in the same order: {same_order}; largest relative difference of "
          f"a constant: {diff:.1e}")
    return 0 if same_order else 1


if __name__ == "__main__":
    raise SystemExit(main())
