"""``pamid fit DATA --stream``: a bench file bigger than memory, fitted a chunk of whole
muscles at a time.

The file is read a chunk of about ``--chunk-rows`` rows at a time
(:func:`pamid._data._bench.load_bench_chunks`: whole muscles, each chunk checked as a whole
file is), each chunk is fitted by :func:`pamid.fit_least_squares` (the same solver, bounds
and intervals as ``pamid fit``), and only its constants are kept: memory holds one chunk
and the table of results, never the file. The chunks after the first have the first's
shape class (:func:`pamid._lanes._batch.padded_rows`, ``padded_lanes``), so they run the
programs it compiled.

Writes ``constants.parquet`` to ``--out`` (one row per muscle, in file order: its rows,
status, steps, RMSE, R, and per constant its value, standard error and the 95 % interval
the muscle's residual supports, with Wald's and the profile's where they differ) as it goes,
atomically, and ``fit_stream.json`` (the summary, which ``--json`` also prints) and
``rmse_histogram.png``. Exit 0 when every muscle converged, 1 when one did not, 2 for bad
input.
"""

from __future__ import annotations

import json
import re
import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np

#: Not-converged muscles named in the summary (all of them are in constants.parquet).
NAMED = 20


def run_stream(args, startup, intervals: tuple[str, ...]) -> int:
    """The ``--stream`` branch of ``pamid fit`` (module text)."""
    from .._data._bench import load_bench_chunks
    from .._io import final_place, write_atomic, write_text_atomic

    if args.method != "ls":
        raise ValueError("--stream fits by least squares (--method ls); sample a posterior "
                         "of a few muscles with --method mcmc on a file that fits in memory")
    share = _share(args)
    if share is not None and share[0] > 0 and args.out:
        raise ValueError(f"process {share[0]} was given --out: process 0 gathers every "
                         "process' muscles and writes them; start the others without --out")
    if (share is None or share[0] == 0) and not args.out:
        raise ValueError("--stream writes one row per muscle to --out FOLDER/constants.parquet"
                         " (a file too big for memory has too many muscles for the screen): "
                         "give --out")
    if args.bootstrap or "bootstrap" in intervals:
        raise ValueError("--stream computes wald, profile, cluster and hac intervals, not the "
                         "bootstrap (B refits of every muscle); drop --bootstrap and leave it "
                         "out of --intervals")
    from ._reading import reading_options

    t0 = time.perf_counter()
    chunks = load_bench_chunks(args.data, args.chunk_rows, share=share,
                               **reading_options(args))
    spec, bounds = startup.result()  # a bad model or bounds: told before any data are read
    summary = _Summary(args, intervals)
    if share is None:
        out = Path(args.out)

        def write(tmp: str) -> None:
            _stream(chunks, tmp, args, spec, bounds, intervals, summary, t0)

        write_atomic(out / "constants.parquet", write)
    else:
        parts = _stream_share(chunks, args, spec, bounds, intervals, summary, t0, share)
        if share[0] > 0:  # process 0 writes and says everything
            return 0 if summary.not_converged_total == 0 else 1
        out = Path(args.out)
        write_atomic(out / "constants.parquet", lambda tmp: _write_parts(parts, tmp))
    for (category, _), (text, n) in summary.warned.items():
        if n > 1:
            text = text.removeprefix(f"{args.data}: ")
            words = text if len(text) <= 60 else text[:60] + "…"
            warnings.warn(f"{args.data}: the same warning in {n - 1:,} more chunk(s) as in the "
                          f"first ({words})", category, stacklevel=2)
    payload = summary.payload(time.perf_counter() - t0)
    from .._report._plot import plot_rmse_histogram

    plot_rmse_histogram(np.concatenate(summary.rmse) if summary.rmse else np.zeros(0),
                        out / "rmse_histogram.png",
                        f"Fit RMSE across {payload['muscles']:,} muscles of {args.data}")
    write_text_atomic(out / "fit_stream.json", json.dumps(payload, indent=2) + "\n")
    _say(f"wrote constants.parquet, fit_stream.json, rmse_histogram.png to "
         f"{final_place(out)}/")
    if args.json:
        print(json.dumps(payload))
    else:
        print(_text(payload))
    return 0 if payload["not_converged"] == 0 else 1


def _say(message: str) -> None:
    print(f"[pamid]{_WHO[0]} {message}", file=sys.stderr, flush=True)


_WHO = [""]  # " process 1 of 2" where several processes share the file


def _share(args) -> tuple[int, int] | None:
    """(this process' index, the number of processes) where several fit the file together
    (:mod:`pamid._commands.fit_processes`), else None."""
    import jax

    if not (getattr(args, "processes", None) or getattr(args, "coordinator", None)):
        return None
    index, count = jax.process_index(), jax.process_count()
    if count < 2:
        return None
    _WHO[0] = f" process {index} of {count}:"
    return index, count


def _stream_share(chunks, args, spec, bounds, intervals, summary, t0, share):
    """This process' share, fitted into memory; then every process' rows and counts
    gathered (``jax.experimental.multihost_utils``): process 0 gets the tables, in process
    order, which is file order. A bad input in any process ends every process (each joins
    the gather first, so none waits for ever), with that process' message."""
    import pyarrow as pa

    from .._errors import BenchDataError

    sink = pa.BufferOutputStream()
    error = None
    try:
        _stream(chunks, sink, args, spec, bounds, intervals, summary, t0, empty_ok=True)
    except (BenchDataError, ValueError) as exc:
        error = str(exc)
    states = [json.loads(b) for b in _exchange(json.dumps(
        {"error": error, **summary.state()}), share)]
    bad = [(i, s["error"]) for i, s in enumerate(states) if s["error"]]
    if bad:
        i, message = bad[0]
        raise ValueError(message if i == share[0] else
                         f"process {i} of {share[1]} stopped: {message}")
    tables = _gather(sink.getvalue().to_pybytes())
    summary.merge(states)
    if share[0] > 0:
        return None
    import pyarrow.parquet as pq

    parts = [pq.read_table(pa.BufferReader(t)) for t in tables if t]
    summary.rmse = [np.asarray(t.column("rmse_N").to_numpy(), float) for t in parts]
    return parts


def _write_parts(parts, path: str) -> None:
    import pyarrow.parquet as pq

    with pq.ParquetWriter(path, parts[0].schema) as writer:
        for table in parts:
            writer.write_table(table.cast(parts[0].schema))


#: How long a process that has fitted its share waits for the others' (``_exchange``): as
#: long as the slowest share takes. A process that dies ends the job sooner (the
#: coordination service's heartbeats).
WAIT_FOR_SHARES_S = 24 * 3600


def _exchange(text: str, share) -> list[str]:
    """``text`` of every process, in process order, on every process, through the job's
    key-value store (``jax.distributed``'s coordination service), which waits for the
    slowest process as long as :data:`WAIT_FOR_SHARES_S`. Not by a collective: gloo sets up
    its connections at the first collective and gives up after 30 s, and a process that
    stopped early at a bad row then failed there ("Gloo context initialization failed:
    DEADLINE_EXCEEDED") while the other still fitted its share (a clean-clone run of the
    tests on a loaded 2-core machine, 2026-12-02). After this exchange every process goes
    on to the gather of the tables at once."""
    from jax._src.distributed import global_state

    client, (index, count) = global_state.client, share
    client.key_value_set(f"pamid/fit-stream/state/{index}", text)
    return [client.blocking_key_value_get(f"pamid/fit-stream/state/{i}",
                                          int(WAIT_FOR_SHARES_S * 1000))
            for i in range(count)]


def _gather(data: bytes) -> list[bytes]:
    """``data`` of every process, in process order, on every process (two all-gathers:
    the sizes, then the bytes padded to the largest)."""
    import os

    from jax.experimental import multihost_utils

    array = np.frombuffer(data, dtype=np.uint8)
    # gloo's C++ says "[Gloo] Rank 0 is connected to 1 peer ranks…" on standard output at
    # the first collective: it goes to standard error, so --json stays one JSON object
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        sizes = np.asarray(multihost_utils.process_allgather(
            np.array([array.size], dtype=np.int64))).reshape(-1)
        padded = np.zeros(max(int(sizes.max()), 1), dtype=np.uint8)
        padded[: array.size] = array
        everything = np.asarray(multihost_utils.process_allgather(padded))
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    return [bytes(row[: int(n)]) for row, n in zip(everything, sizes, strict=True)]


class _Summary:
    """What the chunks add up to: counts, statuses, RMSEs and the warnings seen."""

    def __init__(self, args, intervals):
        self.source, self.model, self.solver = str(args.data), args.model, args.solver
        self.intervals, self.chunk_rows = intervals, args.chunk_rows
        self.muscles = self.rows = self.chunks = self.censored = 0
        self.statuses: dict[str, int] = {}
        self.not_converged: list[dict] = []
        self.rmse: list[np.ndarray] = []
        self.units: dict[str, str] = {}
        self.names: tuple[str, ...] = ()
        self.fit_s = self.read_s = 0.0
        self.warned: dict[tuple, tuple[str, int]] = {}  # -> (first text, chunks)
        self.processes: list[dict] = []  # per process, where several share the file

    def add(self, bench, result) -> None:
        self.chunks += 1
        self.muscles += len(result.muscles)
        self.rows += len(bench.frame)
        self.censored += bench.n_censored
        self.names, self.units = result.param_names, dict(result.param_units)
        for status in result.status:
            self.statuses[status] = self.statuses.get(status, 0) + 1
        for i in np.flatnonzero(~np.asarray(result.converged)):
            if len(self.not_converged) < NAMED:
                self.not_converged.append({"muscle": result.muscles[i],
                                           "status": result.status[i],
                                           "why": result.message(i)})
        self.rmse.append(np.asarray(result.rmse_N, float))

    @property
    def not_converged_total(self) -> int:
        return sum(n for s, n in self.statuses.items() if s not in ("converged", "at_bound"))

    def state(self) -> dict:
        """What another process needs of this one's counts (JSON)."""
        return {"muscles": self.muscles, "rows": self.rows, "chunks": self.chunks,
                "censored": self.censored, "statuses": self.statuses,
                "not_converged": self.not_converged, "names": list(self.names),
                "units": self.units, "read_s": self.read_s, "fit_s": self.fit_s,
                "peak_rss_MB": _peak_mb(), "devices": _devices()}

    def merge(self, states: list[dict]) -> None:
        """The counts of every process (their :meth:`state`, in process order)."""
        self.muscles = sum(s["muscles"] for s in states)
        self.rows = sum(s["rows"] for s in states)
        self.chunks = sum(s["chunks"] for s in states)
        self.censored = sum(s["censored"] for s in states)
        self.statuses = {}
        for s in states:
            for k, n in s["statuses"].items():
                self.statuses[k] = self.statuses.get(k, 0) + n
        self.not_converged = [m for s in states for m in s["not_converged"]][:NAMED]
        named = next((s for s in states if s["names"]), None)
        if named is not None:
            self.names, self.units = tuple(named["names"]), named["units"]
        self.processes = [{"process": i, "muscles": s["muscles"], "rows": s["rows"],
                           "read_s": round(s["read_s"], 3), "fit_s": round(s["fit_s"], 3),
                           "peak_rss_MB": s["peak_rss_MB"], "devices": s["devices"]}
                          for i, s in enumerate(states)]

    def payload(self, seconds: float) -> dict:
        rmse = np.concatenate(self.rmse) if self.rmse else np.zeros(0)
        bad = self.not_converged_total
        finite = rmse[np.isfinite(rmse)]
        return {
            "source": self.source, "model": self.model, "solver": self.solver,
            "intervals": list(self.intervals), "muscles": self.muscles, "rows": self.rows,
            "chunks": self.chunks, "chunk_rows": self.chunk_rows,
            "n_censored_dropped": self.censored, "status": self.statuses,
            "not_converged": bad, "not_converged_first": self.not_converged,
            "rmse_N": ({"median": float(np.median(finite)),
                        "p95": float(np.percentile(finite, 95)),
                        "max": float(finite.max())} if finite.size else None),
            "constants": list(self.names), "units": self.units,
            "constants_file": "constants.parquet",
            "seconds": round(seconds, 3), "read_s": round(self.read_s, 3),
            "fit_s": round(self.fit_s, 3),
            "peak_rss_MB": _peak_mb(),
            **({"processes": self.processes} if self.processes else {}),
        }


def _stream(chunks, path, args, spec, bounds, intervals, summary: _Summary, t0,
            empty_ok: bool = False) -> None:
    """Fit every chunk and append its rows to the Parquet file at ``path`` (a path or an
    Arrow output stream); ``empty_ok``: a share without a muscle writes nothing."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from .._fit._api import fit_least_squares

    writer = None
    try:
        while True:
            t_read = time.perf_counter()
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                bench = next(chunks, None)
            summary.read_s += time.perf_counter() - t_read
            _pass_on(caught, summary)
            if bench is None:
                break
            t_fit = time.perf_counter()
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                result = fit_least_squares(bench, args.model, solver=args.solver,
                                           intervals=intervals, bounds=bounds)
            _pass_on(caught, summary)
            summary.fit_s += time.perf_counter() - t_fit
            table = pa.Table.from_pandas(_rows(result), preserve_index=False)
            if writer is None:
                meta = {b"pamid": json.dumps({
                    "model": args.model, "units": dict(result.param_units),
                    "intervals": list(intervals)}).encode()}
                writer = pq.ParquetWriter(path, table.schema.with_metadata(meta))
            writer.write_table(table.cast(writer.schema))
            summary.add(bench, result)
            first, last = bench.frame["source_row"].iloc[[0, -1]]
            _say(f"chunk {summary.chunks}: {len(result.muscles):,} muscles "
                 f"(rows {first:,}–{last:,}), {summary.muscles:,} muscles so far, "
                 f"{time.perf_counter() - t0:.1f} s{_memory()}")
            del bench, result, table
            _give_back_freed_memory()
    finally:
        if writer is not None:
            writer.close()
    if writer is None and not empty_ok:  # no muscle at all: the loader has said why
        raise ValueError(f"{args.data}: no muscle to fit")


def _give_back_freed_memory() -> None:
    """Return freed memory to the system once the process has grown by
    :data:`TRIM_GROWTH_BYTES` since it last did (glibc's ``malloc_trim``; elsewhere nothing).
    glibc keeps the freed blocks of the chunks' arrays, whose sizes differ by a few rows
    from chunk to chunk: 1,000,000 muscles grew the process from 1.0 to 2.5 GB without it.
    A trim after every chunk held 1.4 GB but cost 37 % more time (every chunk's arrays
    faulted in anew); one per 512 MB of growth bounds it at no visible cost."""
    global _TRIM, _TRIMMED_AT
    now = _resident_bytes()
    if now is None or now < _TRIMMED_AT + TRIM_GROWTH_BYTES:
        return
    if _TRIM is None:
        import ctypes

        try:
            _TRIM = ctypes.CDLL(None).malloc_trim
        except (OSError, AttributeError):
            _TRIM = False
    if _TRIM:
        _TRIM(0)
    _TRIMMED_AT = _resident_bytes() or now


#: Growth of the resident memory after which :func:`_give_back_freed_memory` trims.
TRIM_GROWTH_BYTES = 512 * 2**20
_TRIM = None
_TRIMMED_AT = 0


def _resident_bytes() -> int | None:
    """The process's resident memory, where /proc tells it."""
    try:
        return int(Path("/proc/self/statm").read_text().split()[1]) * resource.getpagesize()
    except (OSError, ValueError, IndexError):
        return None


def _devices() -> list[str]:
    """The devices this process fits on (``jax.local_devices()``)."""
    import jax

    return [str(d) for d in jax.local_devices()]


def _peak_mb() -> float:
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)


def _memory() -> str:
    """", memory 1.2 GB": the process's resident memory now, where /proc tells it."""
    now = _resident_bytes()
    return "" if now is None else f", memory {now / 1e9:.2f} GB"


def _pass_on(caught, summary: _Summary) -> None:
    """Show a chunk's warnings once: the same warning of a later chunk is counted, and the
    count shown at the end of the run."""
    for w in caught:
        text = str(w.message)
        key = (w.category, re.sub(r"\d[\d,.]*", "#", text))  # the same words, other counts
        if key not in summary.warned:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
            summary.warned[key] = (text, 0)
        first, n = summary.warned[key]
        summary.warned[key] = (first, n + 1)


def _rows(result):
    """One row per muscle of a chunk (module text)."""
    import pandas as pd

    shown_ci, _ = result.shown_intervals()
    n = len(result.muscles)
    data = {
        "muscle": list(result.muscles),
        "n_rows": np.asarray(result.n, np.int64),
        "status": list(result.status),
        "converged": np.asarray(result.converged, bool),
        "n_steps": np.asarray(result.n_steps, np.int64),
        "rmse_N": np.asarray(result.rmse_N, float),
        "r": np.asarray(result.r, float),
        "interval": [result.shown_of(i) for i in range(n)],
    }
    for j, name in enumerate(result.param_names):
        data[name] = result.theta[:, j]
        data[f"{name}_se"] = result.se[:, j]
        data[f"{name}_low"] = shown_ci[:, j, 0]
        data[f"{name}_high"] = shown_ci[:, j, 1]
        data[f"{name}_wald_low"] = result.ci95[:, j, 0]
        data[f"{name}_wald_high"] = result.ci95[:, j, 1]
        if result.ci95_profile is not None:
            data[f"{name}_profile_low"] = result.ci95_profile[:, j, 0]
            data[f"{name}_profile_high"] = result.ci95_profile[:, j, 1]
    return pd.DataFrame(data)


def _text(payload: dict) -> str:
    lines = [f"{payload['source']}: {payload['muscles']:,} muscles, {payload['rows']:,} rows "
             f"in {payload['chunks']} chunks, {payload['seconds']:.1f} s "
             f"(reading {payload['read_s']:.1f} s, fitting {payload['fit_s']:.1f} s), "
             f"peak memory {payload['peak_rss_MB']:,.0f} MB",
             "status: " + ", ".join(f"{k} {v:,}" for k, v in payload["status"].items())]
    if payload["rmse_N"]:
        r = payload["rmse_N"]
        lines.append(f"RMSE [N]: median {r['median']:.4g}, 95th percentile {r['p95']:.4g}, "
                     f"max {r['max']:.4g}")
    for bad in payload["not_converged_first"]:
        lines.append(f"  NOT CONVERGED {bad['muscle']}: {bad['status']}"
                     + (f" ({bad['why']})" if bad["why"] else ""))
    lines.append("constants (one row per muscle): constants.parquet in --out")
    return "\n".join(lines)
