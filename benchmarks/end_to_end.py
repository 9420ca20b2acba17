"""End to end, side by side: ``pamid fit`` against the pandas + curve_fit scripts a user writes.

    .venv/bin/python benchmarks/end_to_end.py                    # 10,000 muscles + the real file
    .venv/bin/python benchmarks/end_to_end.py --csv bench.csv --rounds 5
    .venv/bin/python benchmarks/end_to_end.py --skip-real

(a) A CSV of ``--n`` virtual muscles (``fit_batch.make_data``: Table 3-1 ± 3 %, Sárosi's
    protocol, 300 samples each; ``--csv`` uses a file already written):
    ``benchmarks/baseline_curve_fit_script.py FILE`` (pandas, curve_fit per muscle, JSON)
    against ``pamid fit FILE --json`` with its default intervals (Wald and profile) and with
    ``--intervals wald``.
(b) The real file ``--real`` (default ``../shared/data/aarl_festo10mm_isometric.csv``; skipped
    when absent): ``benchmarks/baseline_curve_fit_plots.py FILE DIR`` (pandas, curve_fit,
    one matplotlib figure per muscle) against ``pamid fit FILE --out DIR`` (table, fit.json,
    the command's plots).

Every command is a subprocess; its wall time and its CPU time (user + system, from the
rusage of the children) are recorded. All commands of one part run once per round, in an
order rotated from round to round, so that load from other processes falls on all of them
alike; medians over ``--rounds`` rounds are reported, with the load average before and after.
pamid runs from a snapshot of its source tree (copied to a temporary folder, byte-compiled as
an installed package is, and put first on ``PYTHONPATH``) with its own compilation cache
there: the programs the command keeps on disk are keyed by a hash of pamid's source, so
edits made elsewhere during the run would otherwise make it trace and compile again. One
warm-up call of each pamid command fills that cache first (its time is reported as "cold cache").
"""

from __future__ import annotations

import argparse
import compileall
import datetime
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
NAMES = ("a1", "a2", "a3", "a4", "a5", "a6")


def run(cmd, env, timeout):
    """Run ``cmd`` in ``env["PAMID_CACHE_DIR"]``'s folder (not in the repository, whose
    ``pamid`` ``python -m`` would import before the snapshot); wall and CPU seconds (user +
    system of the child), exit code, stdout."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout,
                              cwd=Path(env["PAMID_CACHE_DIR"]).parent)
    except subprocess.TimeoutExpired:
        return {"wall_s": time.perf_counter() - t0, "cpu_s": float("nan"), "rc": None,
                "stdout": "", "stderr": "timed out"}
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "rc": proc.returncode, "stdout": proc.stdout,
            "stderr": proc.stderr[-2000:]}


def constants(stdout: str):
    """(muscle ids, constants (M, 6)) from a JSON document on stdout, or None."""
    try:
        doc = json.loads(stdout)
    except json.JSONDecodeError:
        return None
    muscles = doc["muscles"]
    return ([m.get("muscle") for m in muscles],
            np.array([[m["params"][n]["value"] for n in NAMES] for m in muscles]))


def side_by_side(commands: dict, rounds: int, env: dict, timeout: float, prepare=None):
    """Run every command once per round (rotated order); per command the list of runs."""
    runs = {name: [] for name in commands}
    names = list(commands)
    for r in range(rounds):
        order = names[r % len(names):] + names[: r % len(names)]
        for name in order:
            if prepare is not None:
                prepare(name)
            rec = run(commands[name], env, timeout)
            runs[name].append(rec)
            print(f"  round {r + 1}: {name}: {rec['wall_s']:.2f} s wall, {rec['cpu_s']:.2f} s "
                  f"CPU, exit {rec['rc']}", flush=True)
    return runs


def summary(runs: dict) -> dict:
    out = {}
    for name, recs in runs.items():
        out[name] = {
            "wall_s": [r["wall_s"] for r in recs],
            "cpu_s": [r["cpu_s"] for r in recs],
            "median_wall_s": statistics.median(r["wall_s"] for r in recs),
            "median_cpu_s": statistics.median(r["cpu_s"] for r in recs),
            "exit": [r["rc"] for r in recs],
        }
    return out


def table(rows, base_name, out):
    base = out[base_name]
    print(f"  {'command':<58} {'wall (median)':>13} {'CPU (median)':>12} {'wall ratio':>10}")
    for name in rows:
        s = out[name]
        ratio = base["median_wall_s"] / s["median_wall_s"]
        s["speedup_wall_vs_baseline"] = ratio
        s["speedup_cpu_vs_baseline"] = base["median_cpu_s"] / s["median_cpu_s"]
        print(f"  {name:<58} {s['median_wall_s']:11.2f} s {s['median_cpu_s']:10.2f} s "
              f"{ratio:9.2f}×")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10000, help="muscles of the virtual file")
    parser.add_argument("--csv", help="use this bench CSV for (a) instead of making one")
    parser.add_argument("--real", default=str(ROOT.parent / "shared" / "data"
                                              / "aarl_festo10mm_isometric.csv"))
    parser.add_argument("--skip-real", action="store_true")
    parser.add_argument("--skip-virtual", action="store_true")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--timeout", type=float, default=600.0)
    parser.add_argument("--json", metavar="PATH", help="also write every number as JSON")
    parser.add_argument("--pamid-src", default=str(ROOT / "pamid"),
                        help="the pamid package to run (default this tree's; e.g. an earlier "
                             "revision unpacked with `git archive REV | tar -x -C DIR`)")
    args = parser.parse_args(argv)

    tmp = Path(tempfile.mkdtemp(prefix="pamid-e2e-"))
    results = {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "cpu_count": os.cpu_count(),
        "loadavg_start": os.getloadavg(),
        "rounds": args.rounds,
    }
    print(f"end to end, {results['date']}; {os.cpu_count()} CPUs; load average "
          f"{os.getloadavg()[0]:.2f}; medians of {args.rounds} rounds")
    try:
        snapshot = tmp / "src"
        shutil.copytree(args.pamid_src, snapshot / "pamid",
                        ignore=shutil.ignore_patterns("__pycache__"))
        # Byte-compiled, as an installed package is (pip compiles it): with
        # PYTHONDONTWRITEBYTECODE set, every run would compile pamid's sources again
        # (~0.1 s of each pamid run).
        compileall.compile_dir(snapshot / "pamid", quiet=1)
        env = dict(os.environ)
        env["PYTHONPATH"] = str(snapshot) + os.pathsep + env.get("PYTHONPATH", "")
        env["PAMID_CACHE_DIR"] = str(tmp / "cache")
        py = sys.executable
        # `python -m pamid`; a revision from before pamid/__main__.py runs its CLI module.
        entry = "pamid" if (snapshot / "pamid" / "__main__.py").exists() else "pamid._cli"
        pamid_cmd = [py, "-m", entry, "fit"]
        (tmp / "cache").mkdir()
        where = run([py, "-c", "import pamid; print(pamid.__file__)"], env, 120)["stdout"]
        if not where.strip().startswith(str(snapshot)):
            raise SystemExit(f"the snapshot is not the pamid imported: {where.strip()}")
        print(f"pamid from {args.pamid_src} (snapshot in {snapshot})")

        if not args.skip_virtual:
            if args.csv:
                csv = Path(args.csv)
            else:
                sys.path.insert(0, str(HERE))
                from fit_batch import make_data

                csv = tmp / f"bench_{args.n}.csv"
                make_data(args.n)[0].to_csv(csv, index=False)
            print(f"\n(a) {csv.name}: {sum(1 for _ in open(csv)) - 1} rows")
            commands = {
                "pandas + curve_fit script": [py, str(HERE / "baseline_curve_fit_script.py"),
                                              str(csv)],
                "pamid fit FILE --json (default: wald, profile)": [*pamid_cmd, str(csv), "--json"],
                "pamid fit FILE --json --intervals wald": [*pamid_cmd, str(csv), "--json",
                                                           "--intervals", "wald"],
            }
            cold = {name: run(cmd, env, args.timeout) for name, cmd in commands.items()
                    if name.startswith("pamid")}
            for name, rec in cold.items():
                print(f"  cold cache: {name}: {rec['wall_s']:.2f} s wall, exit {rec['rc']}")
            runs = side_by_side(commands, args.rounds, env, args.timeout)
            out = summary(runs)
            for name, rec in cold.items():
                out[name]["cold_cache_wall_s"] = rec["wall_s"]
            ref = constants(runs["pandas + curve_fit script"][-1]["stdout"])
            for name in list(commands)[1:]:
                mine = constants(runs[name][-1]["stdout"])
                if ref is not None and mine is not None and ref[0] == mine[0]:
                    out[name]["max_rel_diff_vs_curve_fit"] = float(
                        np.max(np.abs(mine[1] - ref[1]) / np.abs(ref[1])))
            print()
            table(list(commands)[1:], "pandas + curve_fit script", out)
            results["virtual"] = {"csv": str(csv), "commands": {k: " ".join(v) for k, v in
                                                                commands.items()}, **out}

        real = Path(args.real)
        if not args.skip_real and real.exists():
            probe = run([*pamid_cmd, str(real), "--json"], env, args.timeout)
            print(f"\n(b) {real.name}: `pamid fit --json` exit {probe['rc']} (cold cache "
                  f"{probe['wall_s']:.2f} s)")
            if probe["rc"] in (0, 1):
                plots = tmp / "plots"
                commands = {
                    "pandas + curve_fit + matplotlib script": [
                        py, str(HERE / "baseline_curve_fit_plots.py"), str(real),
                        str(plots / "baseline")],
                    "pamid fit FILE --out DIR": [*pamid_cmd, str(real), "--out",
                                                 str(plots / "pamid")],
                }
                run(commands["pamid fit FILE --out DIR"], env, args.timeout)  # warm-up: plots

                def fresh(name):
                    shutil.rmtree(plots, ignore_errors=True)

                runs = side_by_side(commands, args.rounds, env, args.timeout, prepare=fresh)
                out = summary(runs)
                print()
                table(["pamid fit FILE --out DIR"], "pandas + curve_fit + matplotlib script", out)
                out["pamid fit FILE --out DIR"]["files"] = sorted(
                    p.name for p in (plots / "pamid").glob("*"))
                results["real"] = {"csv": str(real), **out}
            else:
                results["real"] = {"skipped": probe["stderr"][-500:]}
                print(f"  skipped: {probe['stderr'][-300:]}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    results["loadavg_end"] = os.getloadavg()
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}")
    if args.json:
        from pamid.io import write_text_atomic

        write_text_atomic(args.json, json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
