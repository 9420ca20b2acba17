"""Fit a Parquet bench file with several JAX processes (``jax.distributed``), one share each.

    # every process of a job (one per machine, or per GPU), e.g. from a cluster launcher:
    .venv/bin/python benchmarks/distributed_fit.py BENCH.parquet --out fit.json \\
        --coordinator HOST:PORT --num-processes N --process-id I
    # on SLURM / Open MPI / Kubernetes JAX finds those three itself:
    .venv/bin/python benchmarks/distributed_fit.py BENCH.parquet --out fit.json --auto
    # N processes on this machine (coordinator 127.0.0.1 on a free port), to try it out:
    .venv/bin/python benchmarks/distributed_fit.py BENCH.parquet --out fit.json --local-processes 2
    # a virtual bench file of M Sárosi muscles to fit (refuses to overwrite a file):
    .venv/bin/python benchmarks/distributed_fit.py BENCH.parquet --simulate M

Every process reads the file's ``muscle`` column, takes its contiguous share of the muscle
ids (in order of first appearance; ``numpy.array_split`` over the processes), reads only
the rows of those muscles (a pyarrow filter), checks and loads them with
:func:`pamid.load_bench` and fits them with :func:`pamid.fit_least_squares` on its own
devices (all its GPUs, sharded along the muscle axis). The per-muscle results (the JSON of
``pamid fit --json``) are gathered to process 0 with
``jax.experimental.multihost_utils.process_allgather`` and written there atomically, in the
file's muscle order. No muscle is fitted twice and none is sent between processes before
the gather; a muscle's result does not depend on which process fitted it beyond rounding
(batches of other sizes differ in the last bits).

On CPU the gather needs cross-process collectives: this script selects gloo
(``jax_cpu_collectives_implementation``). A load error names the process's share file (a
temporary Parquet file with that process's rows), not the original.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def spawn_local(argv: list[str], n: int, timeout: float | None) -> int:
    """Run this script as ``n`` processes on this machine; the exit status of the worst."""
    coordinator = f"127.0.0.1:{_free_port()}"
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                __file__,
                *argv,
                "--coordinator",
                coordinator,
                "--num-processes",
                str(n),
                "--process-id",
                str(i),
            ]
        )
        for i in range(n)
    ]
    codes = []
    for p in procs:
        try:
            codes.append(p.wait(timeout=timeout))
        except subprocess.TimeoutExpired:
            p.kill()
            codes.append(124)
    return max(codes, key=abs)


def muscle_share(path: Path, index: int, count: int) -> list:
    """The muscle ids of process ``index`` of ``count``: a contiguous block of the ids in
    order of first appearance."""
    import numpy as np
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    ids = pc.unique(pq.read_table(path, columns=["muscle"]).column("muscle")).to_pylist()
    blocks = np.array_split(np.arange(len(ids)), count)
    return [ids[i] for i in blocks[index]]


def read_share(path: Path, muscles: list, tmp: Path):
    """Load the rows of ``muscles`` only, with pamid's checks, through a share file."""
    import pyarrow.parquet as pq

    import pamid

    table = pq.read_table(path, filters=[("muscle", "in", muscles)])
    share = tmp / f"{path.stem}.share.parquet"
    pq.write_table(table, share)
    return pamid.load_bench(share)


def gather_json(obj) -> list:
    """``obj`` (JSON-able) of every process, in process order, on every process."""
    import numpy as np
    from jax.experimental import multihost_utils

    data = np.frombuffer(json.dumps(obj).encode(), dtype=np.uint8)
    sizes = multihost_utils.process_allgather(np.array([data.size], dtype=np.int64))
    padded = np.zeros(int(sizes.max()), dtype=np.uint8)
    padded[: data.size] = data
    everything = multihost_utils.process_allgather(padded)
    return [
        json.loads(bytes(row[: int(size)]).decode())
        for row, size in zip(everything, sizes.reshape(-1), strict=True)
    ]


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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bench", type=Path, help="bench file (Parquet) with a muscle column")
    ap.add_argument("--out", type=Path, help="JSON result, written by process 0")
    ap.add_argument("--model", default="sarosi", choices=("sarosi", "cullinan"))
    ap.add_argument("--intervals", default="wald", help="comma-separated: wald,profile")
    ap.add_argument("--coordinator", help="HOST:PORT of process 0")
    ap.add_argument("--num-processes", type=int)
    ap.add_argument("--process-id", type=int)
    ap.add_argument("--auto", action="store_true", help="let JAX detect the cluster")
    ap.add_argument("--local-processes", type=int, help="spawn this many processes here")
    ap.add_argument("--timeout", type=float, default=600.0, help="for --local-processes")
    ap.add_argument("--simulate", type=int, metavar="M", help="write a virtual bench and stop")
    ap.add_argument("--seed", type=int, default=0, help="for --simulate")
    args = ap.parse_args(argv)

    if args.simulate:
        simulate(args.bench, args.simulate, args.seed)
        return 0
    if args.out is None:
        ap.error("--out is required")
    if args.local_processes:
        raw = list(argv if argv is not None else sys.argv[1:])
        i = raw.index("--local-processes")
        return spawn_local(raw[:i] + raw[i + 2 :], args.local_processes, args.timeout)

    import jax

    # Before anything touches a backend (importing pamid does: module-level arrays).
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    if args.auto:
        jax.distributed.initialize()
    else:
        if None in (args.coordinator, args.num_processes, args.process_id):
            ap.error("give --coordinator, --num-processes and --process-id (or --auto)")
        jax.distributed.initialize(
            coordinator_address=args.coordinator,
            num_processes=args.num_processes,
            process_id=args.process_id,
        )

    import pamid
    from pamid.io import refuse_overwrite_input, write_text_atomic

    refuse_overwrite_input(args.out, [args.bench])
    index, count = jax.process_index(), jax.process_count()
    t0 = time.perf_counter()
    muscles = muscle_share(args.bench, index, count)
    mine, t_load, t_fit = {"muscles": []}, 0.0, 0.0
    if muscles:  # fewer muscles than processes leaves the last ones idle
        with tempfile.TemporaryDirectory(prefix=f"pamid-share{index}-") as tmp:
            bench = read_share(args.bench, muscles, Path(tmp))
        t_load = time.perf_counter() - t0
        intervals = tuple(s.strip() for s in args.intervals.split(",") if s.strip())
        t0 = time.perf_counter()
        mine = pamid.fit_least_squares(bench, args.model, intervals=intervals).to_dict()
        t_fit = time.perf_counter() - t0
    mine["process"] = {
        "index": index,
        "muscles": len(muscles),
        "devices": [str(d) for d in jax.local_devices()],
        "load_s": t_load,
        "fit_s": t_fit,
    }
    parts = gather_json(mine)
    if index == 0:
        result = {k: v for k, v in parts[0].items() if k not in ("muscles", "process")}
        result["muscles"] = [m for p in parts for m in p["muscles"]]
        result["processes"] = [p["process"] for p in parts]
        write_text_atomic(args.out, json.dumps(result, indent=1) + "\n")
        n_ok = sum(m["converged"] for m in result["muscles"])
        print(
            f"{len(result['muscles'])} muscles fitted by {count} processes "
            f"({n_ok} converged); wrote {args.out}",
            flush=True,
        )
    jax.distributed.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
