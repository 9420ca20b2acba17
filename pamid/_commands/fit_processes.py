"""``pamid fit --stream`` in several processes: one per machine or GPU over
``jax.distributed``, or ``--processes N`` on this machine.

Every process reads only its share of the Parquet file (the row groups split evenly, each
split moved to the next start of a muscle: :func:`pamid._data._parquet.parquet_share`),
fits it on its own devices (``jax.local_devices()``: all its GPUs), and the rows are
gathered to process 0 (``jax.experimental.multihost_utils.process_allgather``), which
writes ``--out`` in the file's muscle order and prints the summary. No muscle is fitted
twice and none is sent between processes before the gather.

- ``--processes N``: this command is process 0 and starts N − 1 more on this machine
  (coordinator 127.0.0.1 on a free port), with the same options.
- ``--coordinator HOST:PORT --num-processes N --process-id I``: one process of a job
  started on several machines (a cluster launcher starts each; only process 0 gets
  ``--out``); ``--coordinator auto`` lets JAX find the three on SLURM, Open MPI or
  Kubernetes.

On CPU the gather needs cross-process collectives: gloo is selected before JAX starts.
"""

from __future__ import annotations

import socket
import subprocess
import sys


def add_arguments(parser) -> None:
    from ._common import Positive

    group = parser.add_argument_group("several processes (with --stream)")
    group.add_argument("--processes", type=int, action=Positive, metavar="N",
                       help="fit the file in N processes on this machine, each its own "
                            "share of the muscles (jax.distributed)")
    group.add_argument("--coordinator", metavar="HOST:PORT",
                       help="one process of a job on several machines: process 0's address "
                            "('auto': found by JAX on SLURM, Open MPI, Kubernetes)")
    group.add_argument("--num-processes", type=int, action=Positive, metavar="N",
                       dest="num_processes", help="with --coordinator: processes in the job")
    group.add_argument("--process-id", type=int, metavar="I", dest="process_id",
                       help="with --coordinator: this process' number, 0 … N − 1 (process 0 "
                            "writes --out)")


def start(args) -> None:
    """Join (or, with ``--processes``, start) the processes of a distributed fit; nothing
    for a fit in one process. Called before JAX starts a backend (``jax.distributed``
    must come first)."""
    several = args.processes is not None and args.processes > 1
    joined = args.coordinator is not None
    if not several and not joined:
        if args.num_processes is not None or args.process_id is not None:
            raise ValueError("--num-processes and --process-id go with --coordinator")
        return
    if not args.stream:
        raise ValueError("several processes fit a Parquet file with --stream: add --stream")
    if several and joined:
        raise ValueError("give --processes (this machine) or --coordinator (a job on "
                         "several machines), not both")
    if joined and args.coordinator != "auto" and (
            args.num_processes is None or args.process_id is None):
        raise ValueError("--coordinator HOST:PORT needs --num-processes and --process-id")
    if joined and args.process_id is not None and not (
            0 <= args.process_id < (args.num_processes or 1)):
        raise ValueError(f"--process-id must be 0 … {(args.num_processes or 1) - 1}, "
                         f"got {args.process_id}")
    import jax

    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    if several:
        address = f"127.0.0.1:{_free_port()}"
        args.workers = [subprocess.Popen(_worker_argv(args, address, i),
                                         stdout=subprocess.DEVNULL)
                        for i in range(1, args.processes)]
        jax.distributed.initialize(coordinator_address=address,
                                   num_processes=args.processes, process_id=0)
    elif args.coordinator == "auto":
        jax.distributed.initialize()
    else:
        jax.distributed.initialize(coordinator_address=args.coordinator,
                                   num_processes=args.num_processes,
                                   process_id=args.process_id)


def finish(args, timeout_s: float = 120.0) -> None:
    """Leave the job (every process must: ``jax.distributed.shutdown`` waits for all, and a
    process that ends without it aborts the others at their shutdown), then wait for the
    processes ``--processes`` started; stop any that has not ended within ``timeout_s``."""
    if args.coordinator is None and not (args.processes and args.processes > 1):
        return
    import jax

    try:
        jax.distributed.shutdown()
    except Exception:  # noqa: BLE001 - a job already broken: its processes end anyway
        pass
    for proc in getattr(args, "workers", ()):
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _worker_argv(args, address: str, index: int) -> list[str]:
    """The command of process ``index``: this one's options, without --out and --json."""
    argv = [sys.executable, "-m", "pamid", "fit", str(args.data), "--stream",
            "--chunk-rows", str(args.chunk_rows), "--model", str(args.model),
            "--solver", args.solver, "--intervals", args.intervals, "--seed", str(args.seed),
            "--coordinator", address, "--num-processes", str(args.processes),
            "--process-id", str(index)]
    if args.bounds:
        argv += ["--bounds", args.bounds]
    if args.l0_mm is not None:
        argv += ["--l0-mm", repr(args.l0_mm)]
    if args.keep_censored:
        argv.append("--keep-censored")
    if args.columns:
        argv += ["--columns", ",".join(f"{k}={v}" for k, v in args.columns.items())]
    return argv
