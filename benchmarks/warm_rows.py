"""The static and Cullinan rows of ``run.py``, warm and with many calls, tree against tree.

    .venv/bin/python benchmarks/warm_rows.py                          # this tree
    git archive 80d0b88 pamid | tar -x -C /tmp/before
    .venv/bin/python benchmarks/warm_rows.py --trees /tmp/before . --alternations 3

``run.py --quick`` times three warm calls a row, too few to tell 0.1 ms at N = 100. Here the
data of ``run.py``'s rows (``fit_batch.make_data``: Sárosi eq. 2.1, Table 3-1 ± 3 %;
``run._cullinan_data``: Cullinan eq. 3) are made once by this tree and stored; then, for
each tree (a folder holding a ``pamid`` package) in turn, one process per tree and round
fits them with ``pamid.fit_least_squares`` (a few warm-up calls, then the median of many
timed ones: 300 calls at N ≤ 100, 60 at N = 1000), the trees alternated from round to round
so that the machine's drift falls on all of them alike. Only the public API is used in the
timed processes, so an earlier revision runs as it is. Prints, per row, each tree's medians.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SIZES = (1, 100, 1000)
MODELS = (("sarosi", "static fit (Sárosi)"), ("cullinan", "Cullinan fit (eq. 3)"))


def make_data(folder: Path, sizes) -> None:
    """Store the packed arrays of every row (x0, x1, y, w, curve)."""
    import numpy as np

    sys.path.insert(0, str(HERE))
    import fit_batch
    import run

    big = max(sizes)
    sarosi = fit_batch.make_data(big)[2]
    cullinan = run._cullinan_data(big)[0]
    for model, data in (("sarosi", sarosi), ("cullinan", cullinan)):
        arrays = {"x0": data.x[0], "x1": data.x[1], "y": data.y, "w": data.w,
                  "curve": data.curve}
        for n in sizes:
            np.savez(folder / f"{model}_{n}.npz",
                     **{k: np.asarray(v)[:n] for k, v in arrays.items()})


def child(folder: Path, sizes) -> None:
    """Time the rows with the pamid on ``sys.path``; one JSON object of medians (s)."""
    import statistics
    import time

    import jax

    jax.config.update("jax_enable_compilation_cache", False)
    import jax.numpy as jnp
    import numpy as np

    import pamid

    out = {}
    for model, _ in MODELS:
        for n in sizes:
            with np.load(folder / f"{model}_{n}.npz") as z:
                data = pamid.FitData(x=(jnp.asarray(z["x0"]), jnp.asarray(z["x1"])),
                                     y=jnp.asarray(z["y"]), w=jnp.asarray(z["w"]),
                                     curve=jnp.asarray(z["curve"]))
            for _ in range(10):
                pamid.fit_least_squares(data, model)
            walls = []
            for _ in range(300 if n <= 100 else 60):
                t = time.perf_counter()
                pamid.fit_least_squares(data, model)
                walls.append(time.perf_counter() - t)
            out[f"{model} {n}"] = statistics.median(walls)
    print(json.dumps({"pamid": pamid.__file__, "medians_s": out}))


def _shown(seconds: float) -> str:
    return f"{seconds * 1e6:.0f} µs" if seconds < 1e-3 else f"{seconds * 1e3:.2f} ms"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trees", nargs="+", default=[str(ROOT)],
                    help="folders that hold a pamid package (default: this repository)")
    ap.add_argument("--alternations", type=int, default=1, help="rounds over the trees")
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)), help="muscle counts")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    sizes = tuple(int(s) for s in args.sizes.split(","))
    if args.child:
        child(Path(args.child), sizes)
        return 0
    trees = [str(Path(t).resolve()) for t in args.trees]
    with tempfile.TemporaryDirectory(prefix="pamid-warm-rows-") as tmp:
        make_data(Path(tmp), sizes)
        runs = {tree: [] for tree in trees}
        for k in range(args.alternations):
            for tree in trees:
                env = dict(os.environ, PYTHONPATH=tree)
                proc = subprocess.run(
                    [sys.executable, __file__, "--child", tmp, "--sizes", args.sizes],
                    capture_output=True, text=True, env=env, cwd=tmp, check=False)
                if proc.returncode != 0:
                    print(proc.stderr[-2000:], file=sys.stderr)
                    return 1
                got = json.loads(proc.stdout.strip().splitlines()[-1])
                if not got["pamid"].startswith(tree):
                    print(f"{tree}: imported {got['pamid']} instead", file=sys.stderr)
                    return 1
                runs[tree].append(got["medians_s"])
                print(f"round {k + 1}, {tree}: done", file=sys.stderr)
    print("row | N | " + " | ".join(trees))
    for model, label in MODELS:
        for n in sizes:
            cells = [", ".join(_shown(r[f"{model} {n}"]) for r in runs[tree]) for tree in trees]
            print(f"{label} | {n} | " + " | ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
