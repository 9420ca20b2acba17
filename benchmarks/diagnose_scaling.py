"""Wall time and peak memory of ``pamid diagnose FILE --json`` against the rows of one muscle.

    .venv/bin/python benchmarks/diagnose_scaling.py [--rows 1000 3000 10000 30000 100000]
                                                    [--json] [--keep DIR]

Each file is one muscle from the virtual bench (``pamid.simulate_sarosi_bench``, Sárosi
Table 3-1 constants): 5 pressures × 2 directions × 10 repeats written unaveraged (100
curves), ``rows / 100`` points per sweep, with hysteresis (9 N at 3 bar), temperature
(every sweep at its own temperature) and a rig compliance of 0.002 mm/N hidden in it, so
that the forward selection has several steps to take. The sampling interval shrinks as the
points grow (``seconds_per_point = 200 / points``): every file covers the same test.

Every file is diagnosed twice, each in a fresh subprocess (``python -m pamid diagnose
FILE --json``) with its own empty compilation cache (``PAMID_CACHE_DIR``): *cold* compiles
everything, *warm* reads the compiled programs the cold run left. Peak memory is the
child's maximum resident set size (``os.wait4``'s ``ru_maxrss``; this parent imports only
the standard library, so nothing of its own carries over into the child's figure), and
its CPU time (user + system, from the same call: on a shared machine wall time also counts
the waits for a core). The files are written by a subprocess too. The slope of memory is
fitted by least squares over the warm runs: MB per 1000 rows, and the log-log exponent from
10,000 rows up (1 = linear).

Run it from a tree nobody edits meanwhile: the exported programs' key hashes pamid's sources
(``pamid._lanes._export_cache``), so an edit between the cold and the warm run makes the warm
one trace again.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CURVES = 100  # 5 pressures × 2 directions × 10 repeats

MAKE = r"""
import sys
import jax
import pamid
from pamid import InjectedCompliance, InjectedHysteresis, InjectedTemperature
rows, path = int(sys.argv[1]), sys.argv[2]
points = max(2, rows // 100)
proto = pamid.SarosiProtocol(
    points_per_curve=points, repeats=10, average_repeats=False, min_force_N=10.0,
    seconds_per_point=200.0 / points,
    effects=(InjectedHysteresis(N_at_3_bar=9.0), InjectedTemperature(),
             InjectedCompliance(mm_per_N=0.002)))
frame = pamid.simulate_sarosi_bench(jax.random.key(0), pamid.sarosi.table_3_1(), proto)
frame.to_csv(path, index=False)
print(len(frame))
"""


def make_file(rows: int, path: Path) -> int:
    out = subprocess.run([sys.executable, "-c", MAKE, str(rows), str(path)], check=True,
                         capture_output=True, text=True, cwd=ROOT)
    return int(out.stdout.split()[-1])


def run_diagnose(path: Path, cache: Path, extra: list[str]) -> dict:
    """One ``pamid diagnose`` in a child process: wall time, peak RSS, exit code, JSON."""
    env = dict(os.environ, PAMID_CACHE_DIR=str(cache))
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "pamid", "diagnose", str(path),
                                 "--json", *extra], stdout=out, stderr=err, cwd=ROOT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        text, errors = out.read(), err.read()
    result = {"exit": proc.returncode, "wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime,
              "peak_MB": usage.ru_maxrss / 1024.0}
    if proc.returncode == 0:
        obj = json.loads(text)
        result.update(selected=obj["selected"], n=obj["n"],
                      rows_used=obj.get("rows_used", obj["n"]))
    else:
        result["stderr"] = errors.strip().splitlines()[-1:] if errors.strip() else []
    return result


def fit_line(xs, ys):
    """Least-squares slope and intercept of y against x."""
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sxx
    return slope, my - slope * mx


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, nargs="+",
                        default=[1000, 3000, 10000, 30000, 100000])
    parser.add_argument("--json", action="store_true", help="print the rows as one JSON list")
    parser.add_argument("--keep", help="write the files here (kept) instead of a temp dir")
    parser.add_argument("--extra", default="", help="more options for pamid diagnose, "
                                                    "e.g. '--max-rows 20000'")
    args = parser.parse_args(argv)
    extra = args.extra.split()
    load = os.getloadavg()
    rows_out = []
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(args.keep) if args.keep else Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        for rows in args.rows:
            path = where / f"diagnose_{rows}.csv"
            n = make_file(rows, path)
            cache = Path(tmp) / f"cache_{rows}"
            cold = run_diagnose(path, cache, extra)
            warm = run_diagnose(path, cache, extra)
            row = {"rows": n, "curves": CURVES, "cold": cold, "warm": warm}
            rows_out.append(row)
            print(f"  {n} rows: cold {cold['wall_s']:.1f} s ({cold['cpu_s']:.1f} s CPU), warm "
                  f"{warm['wall_s']:.1f} s ({warm['cpu_s']:.1f} s CPU), "
                  f"peak {warm['peak_MB']:.0f} MB, exit {warm['exit']}",
                  file=sys.stderr, flush=True)
    ok = [r for r in rows_out if r["warm"]["exit"] == 0]
    slope = exponent = math.nan
    if len(ok) >= 2:
        xs = [r["rows"] / 1000.0 for r in ok]
        slope, _ = fit_line(xs, [r["warm"]["peak_MB"] for r in ok])
        big = [r for r in ok if r["rows"] >= 10000] or ok
        if len(big) >= 2:
            exponent, _ = fit_line([math.log(r["rows"]) for r in big],
                                   [math.log(r["warm"]["peak_MB"]) for r in big])
    if args.json:
        print(json.dumps({"rows": rows_out, "MB_per_1000_rows": slope,
                          "load_average": [load[0], os.getloadavg()[0]],
                          "loglog_exponent_10k_up": exponent}))
        return 0
    print(f"load average {load[0]:.1f} at the start, {os.getloadavg()[0]:.1f} at the end "
          f"({os.cpu_count()} cores)")
    print(f"{'rows':>7}  {'cold s':>7}  {'cold CPU s':>10}  {'warm s':>7}  {'warm CPU s':>10}  "
          f"{'peak MB cold':>12}  {'peak MB warm':>12}  {'rows used':>9}  exit  selected")
    for r in rows_out:
        c, w = r["cold"], r["warm"]
        print(f"{r['rows']:>7}  {c['wall_s']:>7.1f}  {c['cpu_s']:>10.1f}  {w['wall_s']:>7.1f}  "
              f"{w['cpu_s']:>10.1f}  {c['peak_MB']:>12.0f}  {w['peak_MB']:>12.0f}  "
              f"{w.get('rows_used', '—')!s:>9}  {w['exit']:>4}  "
              f"{', '.join(w.get('selected', [])) or w.get('stderr', '')}")
    print(f"peak memory (warm) against rows: {slope:.1f} MB per 1000 rows (least squares); "
          f"log-log exponent from 10,000 rows up: {exponent:.2f} (1 = linear)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
