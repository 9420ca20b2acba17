"""The first `pamid fit` after installing (an empty cache): this tree against another, beside SciPy.

    .venv/bin/python benchmarks/first_fit.py                          # this tree, 3 rounds
    git worktree add /tmp/before HEAD~1                               # the tree to compare
    .venv/bin/python benchmarks/first_fit.py --other /tmp/before --rounds 5

Each round runs, in alternating order, `pamid fit FILE --json` from this tree's package and
(with ``--other``) from the other tree's, each a process of its own with a compilation cache
that holds nothing (``PAMID_CACHE_DIR`` new): the run a lab makes first, before `pamid
warm-up` or on a file of a size class it never compiled. Both packages run from
byte-compiled snapshots (as ``latency.py``'s), so writing ``.pyc`` files is not timed. Beside
them, each round, ``baseline_scipy_wald.py`` on the same file (pandas + ``curve_fit``, three
starts, Wald intervals). Prints the medians and the ratio of each to the script's; the JSON
of the two packages is compared, every key but ``seconds``.
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
BUNDLED = ROOT / "pamid" / "data" / "sarosi_dmsp20_400_virtual.csv"


def timed(cmd, env) -> tuple[float, subprocess.CompletedProcess]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, timeout=900)
    return time.perf_counter() - t0, proc


def snapshot(tree: Path, into: Path) -> Path:
    shutil.copytree(tree / "pamid", into / "pamid", ignore=shutil.ignore_patterns("__pycache__"))
    compileall.compile_dir(into / "pamid", quiet=1)
    return into


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--file", type=Path, default=BUNDLED, help="bench file (the bundled one)")
    parser.add_argument("--other", type=Path, help="another tree of pamid (a worktree)")
    parser.add_argument("--this", type=Path, default=ROOT,
                        help="the tree measured as 'this tree' (this checkout)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--intervals", default=None, help="pamid fit's --intervals (its default)")
    args = parser.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="pamid-first-fit-"))
    py = sys.executable
    trees = {"this tree": args.this.resolve()}
    if args.other:
        trees["other tree"] = args.other.resolve()
    print(f"first fit, {datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds')}; "
          f"{os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.2f}; {args.file}",
          flush=True)
    try:
        envs = {}
        for i, (name, tree) in enumerate(trees.items()):
            src = snapshot(tree, tmp / f"src{i}")
            envs[name] = {**os.environ,
                          "PYTHONPATH": str(src) + os.pathsep + os.environ.get("PYTHONPATH", "")}
        extra = ["--intervals", args.intervals] if args.intervals else []
        times: dict[str, list[float]] = {name: [] for name in [*trees, "SciPy"]}
        answers = {}
        for r in range(args.rounds):
            order = list(trees) if r % 2 == 0 else list(reversed(trees))
            for name in order:
                cache = tmp / f"cache-{r}-{name.split()[0]}"
                env = {**envs[name], "PAMID_CACHE_DIR": str(cache)}
                wall, proc = timed([py, "-m", "pamid", "fit", str(args.file), "--json", *extra],
                                   env)
                if proc.returncode not in (0, 1):
                    raise SystemExit(f"{name}: exit {proc.returncode}: {proc.stderr[-1500:]}")
                answer = json.loads(proc.stdout)
                answer.pop("seconds", None)
                answers.setdefault(name, answer)
                times[name].append(wall)
                shutil.rmtree(cache, ignore_errors=True)
            wall, proc = timed([py, str(HERE / "baseline_scipy_wald.py"), str(args.file)],
                               dict(os.environ))
            if proc.returncode != 0:
                raise SystemExit(f"baseline_scipy_wald.py failed: {proc.stderr[-1500:]}")
            times["SciPy"].append(wall)
            print(f"  round {r + 1}: " + "  ".join(f"{k} {v[-1]:.2f} s" for k, v in times.items()),
                  flush=True)
        scipy = statistics.median(times["SciPy"])
        for name, values in times.items():
            med = statistics.median(values)
            print(f"  {name:10s} median {med:6.2f} s  ({min(values):.2f}–{max(values):.2f})"
                  f"  ratio {med / scipy:5.2f}× SciPy")
        if len(answers) == 2:
            same = answers["this tree"] == answers["other tree"]
            print("  the two trees' JSON: " + ("the same" if same else "DIFFERENT"))
        print(f"load average at the end {os.getloadavg()[0]:.2f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
