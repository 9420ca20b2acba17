"""A lab's next file: `pamid fit`, `compare` and `diagnose` on new one-muscle files, beside SciPy.

    .venv/bin/python benchmarks/latency.py                       # sizes 150, 600, 2000 rows
    .venv/bin/python benchmarks/latency.py --sizes 300 --skip-10k --skip-setup
    .venv/bin/python benchmarks/latency.py --json latency.json

Every command is a process of its own, as a user runs it, timed by its wall clock; pamid
runs from a byte-compiled snapshot of its source tree (as ``end_to_end.py`` does) with a
compilation cache of the benchmark's own. For each size n, two new one-muscle files are
drawn from a virtual bench of Sárosi Table 3-1's muscle (the bundled data set's protocol,
rows thinned at random, in order): A of n rows and B of about 0.93·n rows, the same size
class (``pamid._lanes._batch.padded_rows``) but another row count. Per command:

- **empty cache**: the command on A with a cache that holds nothing (the first run after
  installing without `pamid warm-up`);
- **new file, warm class**: then on B (a row count never seen, its class compiled by A);
- **same file again**: on B once more;
- **after set-up** (without ``--skip-setup``): the command on a third file C of n rows
  with only what `pamid warm-up` (the README's set-up, `make demo`: fit, compare and
  diagnose on its virtual sweeps) left in a fresh cache.

Without ``--skip-measured``, where ``../shared/data`` is beside the repository: the same
after set-up on two measured files that are not shaped like warm-up's virtual sweeps: the
static force map of Martens & Boblan 2017 (85 rows, no time column) and one muscle of the
AARL isometric tests (every 8th row of ``Festo10mm_lc20cm``: 1,369 rows, trials, valve
transients).

Beside each, in the same run: ``baseline_scipy_wald.py`` on the same file (pandas +
``curve_fit`` from three starts, Wald intervals: the script a user writes; median of
``--rounds`` runs). The ratio is pamid's time over the script's (≤ 1 means pamid is as fast).
Without ``--skip-10k``: a file of 10,000 virtual muscles (``fit_batch.make_data``), `pamid
fit --json` with an empty cache, with the cache set-up left (a file nobody ran, whose
class of 512-muscle calls `pamid warm-up` compiled on its own virtual file), and again warm,
beside ``baseline_curve_fit_script.py`` (one start per muscle: the loop of
``end_to_end.py``).
"""

from __future__ import annotations

import argparse
import compileall
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
COMMANDS = ("fit", "compare", "diagnose")


def run(cmd, env, cwd, timeout=1800) -> dict:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd,
                          timeout=timeout)
    return {"wall_s": time.perf_counter() - t0, "rc": proc.returncode,
            "stderr": proc.stderr[-1500:]}


def one_muscle_files(folder: Path, n: int, seed: int, env, py) -> dict:
    """Files A (n rows), B (≈ 0.93 n rows, same class) and C (n rows, other rows)."""
    code = f"""
import jax, numpy as np
import pamid
from pamid.engine import padded_rows
n = {n}
# the bundled data set's protocol (pamid/_virtual/_default.py), more points per sweep
proto = pamid.SarosiProtocol(min_force_N=10.0, noise_sd_N=2.0, hysteresis_N_per_bar=3.0,
                             points_per_curve=max(30, -(-3 * n // 8)))
frame = pamid.simulate_sarosi_bench(jax.random.key({seed}), pamid.sarosi.table_3_1(), proto,
                                    muscle_ids=["DMSP-20-400N"])
rng = np.random.default_rng({seed})
m = int(0.93 * n)
while padded_rows(m) != padded_rows(n):
    m += 1
for name, rows in (("A", n), ("B", m), ("C", n)):
    keep = np.sort(rng.choice(len(frame), rows, replace=False))
    frame.iloc[keep].to_csv(r"{folder}" + f"/{{name}}_{n}.csv", index=False)
"""
    subprocess.run([py, "-c", code], check=True, env=env, cwd=folder)
    return {k: folder / f"{k}_{n}.csv" for k in "ABC"}


def scipy_time(py, path, env, cwd, rounds, script="baseline_scipy_wald.py") -> float:
    times = []
    for _ in range(rounds):
        rec = run([py, str(HERE / script), str(path)], env, cwd)
        if rec["rc"] != 0:
            raise SystemExit(f"{script} failed on {path}: {rec['stderr']}")
        times.append(rec["wall_s"])
    return statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="150,600,2000", help="rows of the files")
    parser.add_argument("--commands", default=",".join(COMMANDS))
    parser.add_argument("--rounds", type=int, default=3, help="runs of the SciPy script")
    parser.add_argument("--skip-10k", action="store_true")
    parser.add_argument("--skip-setup", action="store_true")
    parser.add_argument("--skip-measured", action="store_true",
                        help="skip the measured files of ../shared/data after set-up")
    parser.add_argument("--json", metavar="PATH", help="also write every number as JSON")
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]
    commands = [c for c in args.commands.split(",") if c]
    tmp = Path(tempfile.mkdtemp(prefix="pamid-latency-"))
    py = sys.executable
    result = {"date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
              "cpu_count": os.cpu_count(), "loadavg_start": os.getloadavg(), "rows": []}
    print(f"latency, {result['date']}; {os.cpu_count()} CPUs; load average "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    try:
        snapshot = tmp / "src"
        shutil.copytree(ROOT / "pamid", snapshot / "pamid",
                        ignore=shutil.ignore_patterns("__pycache__"))
        compileall.compile_dir(snapshot / "pamid", quiet=1)
        base_env = dict(os.environ)
        base_env["PYTHONPATH"] = str(snapshot) + os.pathsep + base_env.get("PYTHONPATH", "")

        def env_with(cache: Path) -> dict:
            cache.mkdir(parents=True, exist_ok=True)
            return {**base_env, "PAMID_CACHE_DIR": str(cache)}

        pamid = [py, "-m", "pamid"]
        rows = result["rows"]

        def record(command, n, scenario, path, pamid_s, rc, scipy_s):
            row = {"command": command, "rows": n, "scenario": scenario, "file": path.name,
                   "pamid_s": round(pamid_s, 3), "exit": rc, "scipy_s": round(scipy_s, 3),
                   "ratio": round(pamid_s / scipy_s, 2)}
            rows.append(row)
            print(f"  {command:<9} {n:>5} rows  {scenario:<24} pamid {pamid_s:6.2f} s (exit "
                  f"{rc})  SciPy {scipy_s:5.2f} s  ratio {row['ratio']:5.2f}×", flush=True)

        setup_cache = None
        if not args.skip_setup:
            setup_cache = tmp / "cache-setup"
            rec = run([*pamid, "warm-up"], env_with(setup_cache), tmp, timeout=3600)
            result["setup_s"] = round(rec["wall_s"], 1)
            print(f"set-up (pamid warm-up: fit, compare, diagnose): {rec['wall_s']:.1f} s, "
                  f"exit {rec['rc']}", flush=True)
        for n in sizes:
            folder = tmp / f"n{n}"
            folder.mkdir()
            files = one_muscle_files(folder, n, 1000 + n, base_env, py)
            scipy = {k: scipy_time(py, p, base_env, folder, args.rounds)
                     for k, p in files.items()}
            for command in commands:
                env = env_with(tmp / f"cache-{command}-{n}")
                for scenario, key in (("empty cache", "A"), ("new file, warm class", "B"),
                                      ("same file again", "B")):
                    rec = run([*pamid, command, str(files[key]), "--json"], env, folder)
                    record(command, n, scenario, files[key], rec["wall_s"], rec["rc"],
                           scipy[key])
                if setup_cache is not None:
                    rec = run([*pamid, command, str(files["C"]), "--json"],
                              env_with(setup_cache), folder)
                    record(command, n, "after set-up", files["C"], rec["wall_s"], rec["rc"],
                           scipy["C"])
        shared = ROOT.parent / "shared" / "data"
        if setup_cache is not None and not args.skip_measured and shared.is_dir():
            import pandas as pd

            folder = tmp / "measured"
            folder.mkdir()
            martens = shared / "martens_dmsp10_250.csv"
            aarl = pd.read_csv(shared / "aarl_festo10mm_isometric.csv")
            one = folder / "aarl_lc20cm_every8.csv"
            aarl[aarl["muscle"] == "Festo10mm_lc20cm"].iloc[::8].to_csv(one, index=False)
            for path in (martens, one):
                n = len(pd.read_csv(path))
                ref = scipy_time(py, path, base_env, folder, args.rounds)
                for command in commands:
                    rec = run([*pamid, command, str(path), "--json"], env_with(setup_cache),
                              folder)
                    record(command, n, "measured, after set-up", path, rec["wall_s"],
                           rec["rc"], ref)
        if not args.skip_10k:
            sys.path.insert(0, str(HERE))
            from fit_batch import make_data

            csv = tmp / "bench_10000.csv"
            make_data(10000)[0].to_csv(csv, index=False)
            env = env_with(tmp / "cache-10k")
            ref = scipy_time(py, csv, base_env, tmp, 1, "baseline_curve_fit_script.py")
            scenarios = [("empty cache", env), ("same file again", env)]
            if setup_cache is not None:  # set-up compiled the class of 512+ muscles' calls
                scenarios.insert(1, ("after set-up", env_with(setup_cache)))
            for scenario, scenario_env in scenarios:
                rec = run([*pamid, "fit", str(csv), "--json"], scenario_env, tmp)
                row = {"command": "fit", "muscles": 10000, "scenario": scenario,
                       "pamid_s": round(rec["wall_s"], 3), "exit": rec["rc"],
                       "scipy_s": round(ref, 3), "speedup": round(ref / rec["wall_s"], 2)}
                rows.append(row)
                print(f"  fit 10,000 muscles  {scenario:<18} pamid {rec['wall_s']:6.2f} s  "
                      f"SciPy loop {ref:6.2f} s  speedup {row['speedup']:.2f}×", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    result["loadavg_end"] = os.getloadavg()
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
