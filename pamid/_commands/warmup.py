"""``pamid warm-up``: compile, once, the programs a lab's next one-muscle file will run.

A bench file packs to a size class of rows (:func:`pamid._lanes._batch.padded_rows`: powers
of two for a file of one muscle), and the programs of a class, once compiled, are kept on
disk (``PAMID_CACHE_DIR``) for every later file of that class. This command runs `pamid
fit`, `compare` and `diagnose`, exactly as a user runs them (each a process of its own,
``--json``), on a virtual one-muscle file of every class up to ``--max-rows``, so that the
first real file of each class starts warm. The README's set-up (`make demo`) runs it; the
files are virtual benches of Sárosi Table 3-1's muscle (the protocol of
the bundled data set), written to a temporary folder and removed.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMANDS = ("fit", "compare", "diagnose")


def register(subparsers) -> None:
    warm = subparsers.add_parser(
        "warm-up",
        help="compile the programs of one-muscle files of every size class, once",
        description=__doc__.split("\n\n")[1].replace("\n", " "),
    )
    warm.add_argument("--commands", default=",".join(COMMANDS),
                      help="comma-separated commands to compile for: fit, compare, diagnose "
                           "(default all three)")
    warm.add_argument("--max-rows", type=int, default=4096, dest="max_rows", metavar="N",
                      help="largest file to compile for, in rows (default 4096: the classes "
                           "64, 128, …, 4096)")
    warm.add_argument("--json", action="store_true",
                      help="print one JSON object (what was compiled, the seconds) on stdout")
    warm.set_defaults(func=cmd_warm_up)


def size_classes(max_rows: int) -> list[int]:
    """The row classes of one-muscle files up to ``max_rows`` (the one holding it too)."""
    from .._lanes._batch import ROWS_MIN, padded_rows

    top = padded_rows(max(int(max_rows), 1))
    sizes, n = [], ROWS_MIN
    while n <= top:
        sizes.append(padded_rows(n))
        n = padded_rows(n) + 1
    return sizes


def virtual_file(rows: int, folder: Path) -> Path:
    """A one-muscle bench file of exactly ``rows`` rows: the bundled data set's protocol
    with more points per sweep, thinned evenly (every sweep keeps its share of rows)."""
    import jax
    import numpy as np

    from .._models._sarosi import table_3_1
    from .._virtual._default import DEFAULT_SEED, default_protocol
    from .._virtual._sweeps import simulate_sarosi_bench

    points = max(30, -(-rows // 8))  # ≥ rows/10 per sweep after the force floor
    proto = dataclasses.replace(default_protocol(), points_per_curve=points)
    frame = simulate_sarosi_bench(jax.random.key(DEFAULT_SEED), table_3_1(), proto,
                                  muscle_ids=["DMSP-20-400N"])
    if len(frame) < rows:
        raise RuntimeError(f"the virtual bench gave {len(frame)} rows, fewer than {rows}")
    keep = np.unique(np.linspace(0, len(frame) - 1, rows).round().astype(int))
    path = folder / f"warm_{rows}.csv"
    frame.iloc[keep].to_csv(path, index=False)
    return path


def cmd_warm_up(args) -> int:
    from ._common import count

    commands = [c.strip() for c in args.commands.split(",") if c.strip()]
    unknown = [c for c in commands if c not in COMMANDS]
    if unknown or not commands:
        raise ValueError(f"--commands: choose from {', '.join(COMMANDS)}, got "
                         f"{args.commands!r}")
    count("--max-rows", args.max_rows, low=1, high=1_000_000)
    t0 = time.perf_counter()
    classes = size_classes(args.max_rows)
    jobs = [(c, n) for c in commands for n in classes]
    print(f"[pamid] warm-up: compiling {', '.join(commands)} for one-muscle files of "
          f"{classes[0]}–{classes[-1]} rows ({len(classes)} size classes, {len(jobs)} runs); "
          "once per installation", file=sys.stderr, flush=True)
    env = dict(os.environ)  # the commands keep their programs where this one would
    done, failed = [], []
    with tempfile.TemporaryDirectory(prefix="pamid-warm-up-") as tmp:
        files = {n: virtual_file(n, Path(tmp)) for n in classes}

        def run(job):
            command, n = job
            s = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "pamid", command, str(files[n]),
                                   "--json"], capture_output=True, text=True, env=env,
                                  cwd=tmp)
            lines = proc.stderr.strip().splitlines()
            why = next((ln for ln in reversed(lines) if ln.startswith("pamid: error:")),
                       lines[-1] if lines else "")
            return command, n, proc.returncode, time.perf_counter() - s, why

        workers = max(1, min(len(jobs), len(os.sched_getaffinity(0))
                             if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1))
        with concurrent.futures.ThreadPoolExecutor(workers) as pool:
            for i, (command, n, rc, secs, why) in enumerate(pool.map(run, jobs), start=1):
                # exit 1 (a fit that did not converge) still compiled its programs
                ok = rc in (0, 1)
                entry = {"command": command, "rows": n, "seconds": round(secs, 2), "exit": rc}
                if not ok:
                    entry["message"] = why
                (done if ok else failed).append(entry)
                print(f"[pamid] warm-up {i}/{len(jobs)}: {command}, {n} rows: "
                      f"{secs:.1f} s{'' if ok else f' (exit {rc}: {why})'}", file=sys.stderr,
                      flush=True)
    total = time.perf_counter() - t0
    print(f"[pamid] warm-up done in {total:.0f} s", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps({"classes_rows": classes, "runs": done, "failed": failed,
                          "seconds": round(total, 2)}))
    return 0 if not failed else 3
