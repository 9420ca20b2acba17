"""``pamid fit --stream``: a Parquet file read and fitted a chunk of whole muscles at a time
(issue 29, item 5). Its constants are those of the whole file fitted at once; its checks
and messages are those of ``load_bench``, with the file's row numbers."""

from __future__ import annotations

import json

import jax
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._cli import main
from pamid._data._bench import load_bench_chunks
from pamid._errors import BenchDataError

MUSCLES = 24


@pytest.fixture(scope="module")
def bench_frame():
    """24 Sárosi muscles (Table 3-1 × (1 + 3 % noise)), 180 rows each, 1 N noise."""
    z = np.asarray(jax.random.normal(jax.random.key(5), (MUSCLES, 6)))
    theta = np.asarray(pamid.sarosi.table_3_1().to_vector()) * (1.0 + 0.03 * z)
    return pamid.simulate_sarosi_bench(
        jax.random.key(6), pamid.Sarosi.from_vector(theta),
        pamid.SarosiProtocol(min_force_N=10.0, pressures_kPa=(200.0, 400.0, 600.0)),
        muscle_ids=[f"M{i:02d}" for i in range(MUSCLES)])


def _parquet(tmp_path, frame, name="bench.parquet", row_group=1000):
    path = tmp_path / name
    frame.to_parquet(path, index=False, row_group_size=row_group)
    return path


def test_chunks_are_whole_muscles_with_the_files_row_numbers(tmp_path, bench_frame):
    path = _parquet(tmp_path, bench_frame)
    chunks = list(load_bench_chunks(path, 1000))
    assert len(chunks) > 3
    muscles = [m for c in chunks for m in c.muscles]
    assert muscles == list(pd.unique(bench_frame["muscle"]))  # each once, in file order
    rows = np.concatenate([c.frame["source_row"].to_numpy() for c in chunks])
    assert np.array_equal(rows, np.arange(1, len(bench_frame) + 1))
    # a last chunk of less than half the size joins the one before it
    assert len(chunks[-1].frame) >= 500


def test_stream_gives_the_constants_of_the_whole_file(tmp_path, bench_frame, capsys):
    path = _parquet(tmp_path, bench_frame)
    out = tmp_path / "out"
    code = main(["fit", str(path), "--stream", "--chunk-rows", "1500", "--intervals",
                 "wald,profile", "--json", "--out", str(out)])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0
    assert summary["muscles"] == MUSCLES and summary["rows"] == len(bench_frame)
    assert summary["chunks"] >= 3 and summary["not_converged"] == 0
    assert summary["units"]["a1"] and summary["constants"] == ["a1", "a2", "a3", "a4", "a5",
                                                               "a6"]
    table = pd.read_parquet(out / "constants.parquet")
    assert json.loads((out / "fit_stream.json").read_text())["muscles"] == MUSCLES
    assert (out / "rmse_histogram.png").stat().st_size > 0

    whole = pamid.fit_least_squares(pamid.load_bench(path), "sarosi",
                                    intervals=("wald", "profile"))
    assert list(table["muscle"]) == list(whole.muscles)
    for j, name in enumerate(whole.param_names):
        np.testing.assert_allclose(table[name], whole.theta[:, j], rtol=1e-8)
        np.testing.assert_allclose(table[f"{name}_wald_low"], whole.ci95[:, j, 0], rtol=1e-7)
        np.testing.assert_allclose(table[f"{name}_profile_high"], whole.ci95_profile[:, j, 1],
                                   rtol=1e-6)
    np.testing.assert_allclose(table["rmse_N"], whole.rmse_N, rtol=1e-8)
    assert list(table["status"]) == list(whole.status)
    assert (table["n_rows"] == whole.n).all()


@pytest.mark.parametrize("column, value", [("force_N", np.nan), ("muscle", None),
                                           ("muscle", "  ")])
def test_a_bad_cell_is_named_by_its_row_in_the_file(tmp_path, bench_frame, column, value):
    frame = bench_frame.copy()
    frame.loc[3000, column] = value  # in a later chunk
    path = _parquet(tmp_path, frame)
    with pytest.raises(BenchDataError) as whole:
        pamid.load_bench(path)
    with pytest.raises(BenchDataError) as chunked:
        list(load_bench_chunks(path, 1000))
    assert str(chunked.value) == str(whole.value)
    assert "row 3001" in str(chunked.value)


def test_labels_read_as_the_whole_file_reads_them(tmp_path, bench_frame):
    """Muscle ids with blanks around them are the ids without (as load_bench reads them)."""
    frame = bench_frame.assign(muscle=" " + bench_frame["muscle"] + " ")
    path = _parquet(tmp_path, frame)
    chunks = list(load_bench_chunks(path, 1000))
    assert [m for c in chunks for m in c.muscles] == list(pamid.load_bench(path).muscles)
    assert chunks[0].muscles[0] == "M00"


def test_a_muscle_that_comes_back_is_refused_with_its_row(tmp_path, bench_frame):
    first = bench_frame[bench_frame["muscle"] == "M00"]
    again = pd.concat([bench_frame, first.assign(time_s=first["time_s"] + 1e4)])
    path = _parquet(tmp_path, again)
    with pytest.raises(BenchDataError, match=rf"row {len(bench_frame) + 1}.*comes back"):
        list(load_bench_chunks(path, 1000))


def test_what_stream_refuses(tmp_path, bench_frame, capsys):
    csv = tmp_path / "bench.csv"
    bench_frame.to_csv(csv, index=False)
    out = str(tmp_path / "out")
    assert main(["fit", str(csv), "--stream", "--out", out]) == 2
    assert "only Parquet files can be read a part at a time" in capsys.readouterr().err
    path = _parquet(tmp_path, bench_frame)
    assert main(["fit", str(path), "--stream"]) == 2
    assert "give --out" in capsys.readouterr().err
    assert main(["fit", str(path), "--stream", "--bootstrap", "10", "--out", out]) == 2
    assert "drop --bootstrap" in capsys.readouterr().err
    assert main(["fit", str(path), "--stream", "--sep", ";", "--out", out]) == 2
    assert "(--sep) applies to CSV files only" in capsys.readouterr().err  # load_bench's words
    with pytest.raises(SystemExit):
        main(["fit", str(path), "--stream", "--chunk-rows", "0", "--out", out])
    assert "must be an integer ≥ 1" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_warning_of_every_chunk_is_shown_once_and_counted(tmp_path, bench_frame, capsys):
    frame = bench_frame.copy()
    frame.loc[frame.index % 400 == 7, "force_N"] = 0.0  # censored rows in every chunk
    path = _parquet(tmp_path, frame)
    code = main(["fit", str(path), "--stream", "--chunk-rows", "1500", "--intervals", "wald",
                 "--json", "--out", str(tmp_path / "out")])
    assert code == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["n_censored_dropped"] == int((frame["force_N"] == 0).sum())
    # the first chunk's warning, then one line that counts the others
    assert captured.err.count("censored rows") == 2, captured.err
    assert f"the same warning in {summary['chunks'] - 1} more chunk(s)" in captured.err


# -- several processes (jax.distributed) ---------------------------------------------------------


@pytest.mark.parametrize("count", [1, 2, 3, 5])
def test_shares_hold_every_muscle_once_in_file_order(tmp_path, bench_frame, count):
    """Row groups of 1,000 rows and muscles of 180: the splits fall inside muscles and move
    to the next start of one."""
    path = _parquet(tmp_path, bench_frame, row_group=1000)
    muscles, rows = [], []
    for index in range(count):
        for chunk in load_bench_chunks(path, 700, share=(index, count)):
            muscles += list(chunk.muscles)
            rows.append(chunk.frame["source_row"].to_numpy())
    assert muscles == list(pd.unique(bench_frame["muscle"]))
    assert np.array_equal(np.concatenate(rows), np.arange(1, len(bench_frame) + 1))


def test_what_several_processes_refuse(tmp_path, bench_frame, capsys):
    path = _parquet(tmp_path, bench_frame)
    assert main(["fit", str(path), "--processes", "2", "--out", str(tmp_path / "o")]) == 2
    assert "add --stream" in capsys.readouterr().err
    assert main(["fit", str(path), "--stream", "--coordinator", "127.0.0.1:1", "--out",
                 str(tmp_path / "o")]) == 2
    assert "needs --num-processes and --process-id" in capsys.readouterr().err
    assert main(["fit", str(path), "--stream", "--process-id", "1", "--out",
                 str(tmp_path / "o")]) == 2
    assert "go with --coordinator" in capsys.readouterr().err


#: Options of ``pamid fit`` a worker of ``--processes`` does not take from process 0: what
#: only process 0 does (--out, --json), what makes the job (the processes' own options), and
#: what --stream refuses before any worker starts (MCMC, the bootstrap, plots, CSV and
#: spreadsheet reading).
NOT_FORWARDED = {"out", "json", "processes", "coordinator", "num_processes", "process_id",
                 "method", "walkers", "max_steps", "thin", "likelihood", "nu", "sampler",
                 "bootstrap", "max_plots", "sep", "decimal", "sheet", "header_row"}


def test_a_worker_process_gets_every_option_that_changes_its_fit():
    """``fit_processes._worker_argv`` writes process 0's options again for the others: each
    option of ``pamid fit`` either reaches them with its value or is one that must not
    (NOT_FORWARDED); a new option fails here until it is one or the other."""
    from pamid._cli import _parser
    from pamid._commands import fit_processes

    parser = _parser()
    argv = ["fit", "bench.parquet", "--stream", "--processes", "2", "--out", "o", "--json",
            "--chunk-rows", "777", "--model", "cullinan", "--solver", "levenberg-marquardt",
            "--intervals", "wald,hac", "--seed", "5", "--bounds", "A=0:", "--l0-mm", "250.5",
            "--keep-censored", "--columns", "force_N=F,pressure_kPa=p"]
    args = parser.parse_args(argv)
    worker = fit_processes._worker_argv(args, "127.0.0.1:1234", 1)
    assert worker[1:3] == ["-m", "pamid"]
    again = parser.parse_args(worker[3:])
    plumbing = {"func", "prepare", "before_jax", "outputs", "command"}
    options = set(vars(args)) - plumbing
    compared = options - NOT_FORWARDED
    assert {k: getattr(again, k) for k in compared} == {k: getattr(args, k) for k in compared}
    defaults = parser.parse_args(["fit", "bench.parquet"])
    changed = {k for k in compared if getattr(args, k) != getattr(defaults, k)}
    assert changed == compared - {"data"}, "set every forwarded option above"
    assert (again.coordinator, again.num_processes, again.process_id, again.out) == (
        "127.0.0.1:1234", 2, 1, None)


def test_jobs_of_two_processes_one_after_another_on_one_cache(tmp_path, bench_frame, cli_env):
    """Three jobs of two processes (``--processes 2``) on one new cache of compiled programs:
    a good file, the same file again, and a file with a bad row in process 1's share. The
    first two give the one-process constants, each process on its own device; the third ends
    both processes with the row's message. A program kept on disk is bound to its process'
    device: before the cache's key named the process, the second job read the other
    process' program and its processes stopped on a coordination error (every time)."""
    import subprocess

    from conftest import PAMID

    env = {**cli_env, "PAMID_CACHE_DIR": str(tmp_path / "cache")}
    good = _parquet(tmp_path, bench_frame, name="good.parquet", row_group=1000)
    frame = bench_frame.copy()
    frame.loc[len(frame) - 10, "force_N"] = np.nan  # in the second process' share
    bad = _parquet(tmp_path, frame, name="bad.parquet", row_group=1000)
    one = tmp_path / "one"
    assert main(["fit", str(good), "--stream", "--chunk-rows", "1500", "--intervals",
                 "wald,profile", "--out", str(one)]) == 0
    expected = pd.read_parquet(one / "constants.parquet")
    whole = pamid.fit_least_squares(pamid.load_bench(good), "sarosi",
                                    intervals=("wald", "profile"))
    for job, path in enumerate([good, good, bad]):
        out = tmp_path / f"job{job}"
        proc = subprocess.run(
            PAMID + ["fit", str(path), "--stream", "--chunk-rows", "1500", "--intervals",
                     "wald,profile", "--processes", "2", "--json", "--out", str(out)],
            capture_output=True, text=True, env=env, timeout=600)
        assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
        if path == bad:
            assert proc.returncode == 2, proc.stderr[-3000:]
            assert f"process 1 of 2 stopped: {bad}" in proc.stderr
            assert f"row {len(frame) - 9}" in proc.stderr
            assert not out.exists()
            continue
        assert proc.returncode == 0, (job, proc.stderr[-3000:])
        summary = json.loads(proc.stdout)  # one JSON object: gloo's line went to stderr
        assert summary["muscles"] == MUSCLES
        assert [p["process"] for p in summary["processes"]] == [0, 1]
        # rows 1–2,160 and 2,161–4,320: the row groups of 1,000 split muscles of 180 rows,
        # and each share moves its split to the next start of a muscle
        assert [p["muscles"] for p in summary["processes"]] == [12, 12]
        assert [len(p["devices"]) for p in summary["processes"]] == [1, 1]
        assert len({d for p in summary["processes"] for d in p["devices"]}) == 2
        assert "process 1 of 2: chunk" in proc.stderr
        table = pd.read_parquet(out / "constants.parquet")
        assert list(table["muscle"]) == list(expected["muscle"])
        for name in ("a1", "a2", "a3", "a4", "a5", "a6", "rmse_N", "a3_wald_high",
                     "a1_profile_low"):
            np.testing.assert_allclose(table[name], expected[name], rtol=1e-8)
        np.testing.assert_allclose(table[list(whole.param_names)].to_numpy(), whole.theta,
                                   rtol=1e-10)  # the one-process fit of the whole file
        assert table["converged"].all()
    assert any((tmp_path / "cache").rglob("*.xla"))  # the jobs did keep programs there
