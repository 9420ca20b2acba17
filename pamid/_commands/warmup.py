"""``pamid warm-up``: compile, once, the programs a lab's next file will run.

A bench file packs to a size class of rows (:func:`pamid._lanes._batch.padded_rows`: powers
of two for a file of one muscle), and the programs of a class, once compiled, are kept on
disk (``PAMID_CACHE_DIR``) for every later file of that class. This command runs `pamid
fit`, `compare` and `diagnose`, exactly as a user runs them (each a process of its own,
``--json``), on a virtual one-muscle file of every class up to ``--max-rows``, and `pamid
fit` on a file of many muscles of every class up to ``--batch-max-rows`` (one muscle more
than a call of the fit takes: the calls every larger file runs), so that the first real
file of each class starts warm. The README's set-up (`make demo`) runs it; the files are
virtual benches of Sárosi Table 3-1's muscle (the protocol of the bundled data set),
written to a temporary folder and removed.
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
    warm.add_argument("--batch-max-rows", type=int, default=1024, dest="batch_max_rows",
                      metavar="N",
                      help="largest muscle of a many-muscle file to compile `pamid fit` for, "
                           "in rows (default 1024; 0: none)")
    warm.add_argument("--json", action="store_true",
                      help="print one JSON object (what was compiled, the seconds) on stdout")
    warm.set_defaults(func=cmd_warm_up)


def size_classes(max_rows: int, muscles: int = 1) -> list[int]:
    """The row classes of files of ``muscles`` muscles whose largest has up to ``max_rows``
    rows (the class holding it too); none for ``max_rows`` 0."""
    from .._lanes._sizes import ROWS_MIN, padded_rows

    if max_rows <= 0:
        return []
    top = padded_rows(int(max_rows), muscles)
    sizes, n = [], ROWS_MIN
    while n <= top:
        sizes.append(padded_rows(n, muscles))
        n = sizes[-1] + 1
    return sizes


def batch_muscles() -> int:
    """Muscles of the many-muscle file: one more than a call of the fit takes (pamid's one
    lane sizer, :func:`pamid._lanes._batch.items_per_call`, on this machine's devices), so
    that the fit runs calls of a full chunk of lanes, as it does for every larger file."""
    from .._lanes._batch import items_per_call

    return items_per_call() + 1


def virtual_file(rows: int, folder: Path, muscles: int = 1) -> Path:
    """A bench file of ``muscles`` muscles of exactly ``rows`` rows each: the bundled data
    set's protocol with more points per sweep, thinned evenly (every sweep keeps its share
    of rows); several muscles repeat the first one's rows under their own names."""
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
    frame = frame.iloc[keep]
    if muscles > 1:
        import pandas as pd

        frame = pd.concat([frame.assign(muscle=f"M{i:05d}") for i in range(muscles)])
    path = folder / f"warm_{rows}_{muscles}.csv"
    frame.to_csv(path, index=False)
    return path


def cmd_warm_up(args) -> int:
    from ._common import count

    commands = [c.strip() for c in args.commands.split(",") if c.strip()]
    unknown = [c for c in commands if c not in COMMANDS]
    if unknown or not commands:
        raise ValueError(f"--commands: choose from {', '.join(COMMANDS)}, got "
                         f"{args.commands!r}")
    count("--max-rows", args.max_rows, low=1, high=1_000_000)
    count("--batch-max-rows", args.batch_max_rows, low=0, high=1_000_000)
    t0 = time.perf_counter()
    classes = size_classes(args.max_rows)
    many = batch_muscles() if "fit" in commands and args.batch_max_rows else 1
    batch = size_classes(args.batch_max_rows, many) if many > 1 else []
    # The many-muscle runs first: the longest, they would otherwise end the set-up alone.
    jobs = [("fit", n, many) for n in batch] + [(c, n, 1) for c in commands for n in classes]
    print(f"[pamid] warm-up: compiling {', '.join(commands)} for one-muscle files of "
          f"{classes[0]}–{classes[-1]} rows ({len(classes)} size classes)"
          + (f", and fit for files of {many} muscles or more of {batch[0]}–{batch[-1]} rows "
             f"({len(batch)} classes)" if batch else "")
          + f": {len(jobs)} runs, once per installation", file=sys.stderr, flush=True)
    env = dict(os.environ)  # the commands keep their programs where this one would
    done, failed = [], []
    with tempfile.TemporaryDirectory(prefix="pamid-warm-up-") as tmp:
        files = {(n, m): virtual_file(n, Path(tmp), m) for _, n, m in jobs}

        def run(job):
            command, n, m = job
            s = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "pamid", command, str(files[n, m]),
                                   "--json"], capture_output=True, text=True, env=env,
                                  cwd=tmp)
            lines = proc.stderr.strip().splitlines()
            why = next((ln for ln in reversed(lines) if ln.startswith("pamid: error:")),
                       lines[-1] if lines else "")
            return command, n, m, proc.returncode, time.perf_counter() - s, why

        workers = max(1, min(len(jobs), len(os.sched_getaffinity(0))
                             if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1))
        with concurrent.futures.ThreadPoolExecutor(workers) as pool:
            for i, (command, n, m, rc, secs, why) in enumerate(pool.map(run, jobs), start=1):
                # exit 1 (a fit that did not converge) still compiled its programs
                ok = rc in (0, 1)
                entry = {"command": command, "rows": n, "muscles": m, "seconds": round(secs, 2),
                         "exit": rc}
                if not ok:
                    entry["message"] = why
                (done if ok else failed).append(entry)
                size = f"{n} rows" + (f" × {m} muscles" if m > 1 else "")
                print(f"[pamid] warm-up {i}/{len(jobs)}: {command}, {size}: "
                      f"{secs:.1f} s{'' if ok else f' (exit {rc}: {why})'}", file=sys.stderr,
                      flush=True)
    total = time.perf_counter() - t0
    print(f"[pamid] warm-up done in {total:.0f} s", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps({"classes_rows": classes, "batch_classes_rows": batch,
                          "batch_muscles": many if batch else 0, "runs": done,
                          "failed": failed, "seconds": round(total, 2)}))
    return 0 if not failed else 3
