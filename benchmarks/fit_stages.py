"""Where the time of ``pamid fit FILE --json`` goes, stage by stage, in one process.

    .venv/bin/python benchmarks/fit_stages.py bench.csv [--intervals wald,profile] [--rounds 3]

Stages, as the command runs them: import of the command (loading the ``pamid`` console
script's entry point, ``pamid._cli``), building its argument parser (``pamid --help``
through that entry point, its help text not shown), ``load_bench``, packing the muscles
(``bench_to_fit_data``), the solve, the statistics and Wald intervals, the profile
intervals, the JSON document (``to_dict`` and ``json.dumps``). The first round includes
compilation (the disk caches are used as the command uses them, ``PAMID_CACHE_DIR``:
``pamid.engine.use_disk_caches``); later rounds are warm. Prints one
line per stage: wall and CPU time (all threads) of the first round, then the medians of the
later rounds (CPU time is less disturbed by other processes on a shared machine).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import statistics
import sys
import time
from importlib.metadata import entry_points


class Stages(dict):
    """Stage name → (wall s, CPU s), filled by ``t[name] = t0`` with t0 = ``clocks()``."""

    def __setitem__(self, name, start):
        wall, cpu = clocks()
        super().__setitem__(name, (wall - start[0], cpu - start[1]))


def clocks():
    return time.perf_counter(), time.process_time()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data")
    parser.add_argument("--intervals", default="wald,profile")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)

    (script,) = entry_points(group="console_scripts", name="pamid")
    t0 = time.perf_counter()
    console_main = script.load()  # imports the command's module, as the pamid script does
    t_import = time.perf_counter() - t0
    argv = sys.argv
    t0 = time.perf_counter()
    try:  # the parser is built, then prints its help and exits
        sys.argv = ["pamid", "--help"]
        with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):
            console_main()
    finally:
        sys.argv = argv
    t_parser = time.perf_counter() - t0
    print(f"import pamid._cli {t_import:8.3f} s   (modules loaded: {len(sys.modules)})")
    print(f"argument parser   {t_parser:8.3f} s")

    from pamid import bench_to_fit_data, fit_least_squares, load_bench
    from pamid.engine import get_model, profile_intervals, solve, use_disk_caches, wald_intervals
    from pamid.engine import statistics as fit_statistics

    use_disk_caches()
    intervals = tuple(s for s in args.intervals.split(",") if s)
    rounds = []
    for _ in range(args.rounds):
        t = Stages()
        t0 = clocks()
        bench = load_bench(args.data)
        t["load_bench"] = t0
        spec = get_model("sarosi", bench.frame)
        t0 = clocks()
        data = bench_to_fit_data(bench, spec, curves="bootstrap" in intervals)  # as the command
        t["pack"] = t0
        t0 = clocks()
        theta, _, _ = solve(spec, data)
        t["solve"] = t0
        t0 = clocks()
        sse, jtj_inv, _, n, _ = fit_statistics(spec, theta, data)
        se, _, _, s2, dof = wald_intervals(theta, jtj_inv, sse, n)
        t["statistics + wald"] = t0
        if "profile" in intervals:
            t0 = clocks()
            profile_intervals(spec, data, theta, se, s2, sse, dof, jtj_inv=jtj_inv)
            t["profile"] = t0
        t0 = clocks()
        result = fit_least_squares(bench, spec, intervals=intervals)
        t["fit_least_squares (all of the above but loading)"] = t0
        t0 = clocks()
        text = json.dumps(result.to_dict())
        t["to_dict + json.dumps"] = t0
        rounds.append(t)
        print(f"  round {len(rounds)}: " + ", ".join(f"{k} {v[0]:.3f}" for k, v in t.items()),
              file=sys.stderr)
    print(f"{len(bench.frame)} rows, {len(bench.muscles)} muscles, {len(text) / 1e6:.1f} MB of "
          f"JSON; intervals {','.join(intervals)}")
    print(f"{'stage (seconds)':<50} {'first':>7} {'CPU':>7} {'warm':>7} {'CPU':>7}")
    for name in rounds[0]:
        warm = [statistics.median(r[name][i] for r in rounds[1:]) if len(rounds) > 1
                else float("nan") for i in (0, 1)]
        print(f"{name:<50} {rounds[0][name][0]:7.3f} {rounds[0][name][1]:7.3f} "
              f"{warm[0]:7.3f} {warm[1]:7.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
