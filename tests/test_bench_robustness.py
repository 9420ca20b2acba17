"""Bench and decay files that are not regular files, and very wide files.

A pipe (``pamid fit <(cat f.csv)``), ``/dev/stdin`` or a FIFO can be read only once: the
loader reads its bytes once and hands them to every reader (the fast one, the cell-by-cell
one, the header peek of ``pamid diagnose``), and gives up with a message when nothing arrives
(a FIFO nobody writes to). Wide files load in time linear in their number of columns.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pamid
from pamid import BenchDataError, load_bench, load_decay
from pamid._data import _csv, _streams

# Quoted headers and labels (as spreadsheets export them): the fast reader passes such a
# file on to the cell-by-cell reader, which must see the same bytes.
QUOTED = (
    '"muscle","pressure_kPa","force_N","contraction_pct"\n'
    '"A",100,200,1.0\n'
    '"A",200,300,2.5\n'
    '"A",300,400,3.0\n'
    '"B",100,210,1.5\n'
)
BAD_CELL = QUOTED.replace('"A",200,300,2.5', '"A",200,abc,2.5')
PLAIN = QUOTED.replace('"', "")


def decay_csv(n: int = 60) -> str:
    t = np.arange(n) * 0.01
    angle = 0.1 * np.exp(-0.5 * t) * np.cos(2 * np.pi * 2.0 * t)
    rows = "".join(f"{ti:.2f},{a:.6f}\n" for ti, a in zip(t, angle, strict=True))
    return "time_s,angle_rad\n" + rows


class Pipe:
    """An anonymous pipe whose read end is the path ``/dev/fd/N`` (as ``<(cat f)`` gives),
    fed by a thread that writes ``data`` and closes its end."""

    def __init__(self, data: bytes, delay_s: float = 0.0):
        self.read_fd, write_fd = os.pipe()
        self.path = f"/dev/fd/{self.read_fd}"

        def write():
            if delay_s:
                threading.Event().wait(delay_s)
            with os.fdopen(write_fd, "wb") as out:
                out.write(data)

        self.thread = threading.Thread(target=write, daemon=True)
        self.thread.start()

    def close(self):
        self.thread.join(timeout=30)
        os.close(self.read_fd)


@pytest.fixture
def pipe():
    made = []

    def make(text: str | bytes, delay_s: float = 0.0) -> str:
        data = text.encode() if isinstance(text, str) else text
        made.append(Pipe(data, delay_s))
        return made[-1].path

    yield make
    for p in made:
        p.close()


def test_quoted_csv_through_a_pipe_loads_as_the_file_does(pipe, tmp_path):
    path = tmp_path / "q.csv"
    path.write_text(QUOTED)
    from_file = load_bench(path)
    from_pipe = load_bench(pipe(QUOTED))
    pd.testing.assert_frame_equal(from_pipe.frame, from_file.frame, check_exact=True)
    assert from_pipe.muscles == ("A", "B")
    assert from_pipe.path.startswith("/dev/fd/")


def test_plain_csv_through_a_pipe_takes_the_fast_reader(pipe, monkeypatch, tmp_path):
    used = []
    real = _csv._read_csv_fast

    def spy(path, shown, **options):
        table = real(path, shown, **options)
        used.append(table is not None)
        return table

    monkeypatch.setattr(_csv, "_read_csv_fast", spy)
    path = tmp_path / "p.csv"
    path.write_text(PLAIN)
    from_pipe = load_bench(pipe(PLAIN))
    assert used == [True]
    pd.testing.assert_frame_equal(from_pipe.frame, load_bench(path).frame, check_exact=True)


def test_bad_cell_through_a_pipe_gives_the_real_message(pipe):
    # Before: "the file is empty (0 bytes)" (the fast reader had used the stream up).
    path = pipe(BAD_CELL)
    with pytest.raises(BenchDataError, match=r"column 'force_N', row 2 \(line 3\): 'abc' is "
                                             r"not a number") as info:
        load_bench(path)
    assert "empty" not in str(info.value)


def test_pipe_whose_writer_is_slow_is_waited_for(pipe, monkeypatch):
    monkeypatch.setattr(_streams, "STREAM_TIMEOUT_S", 20.0)
    assert load_bench(pipe(QUOTED, delay_s=0.3)).muscles == ("A", "B")


def test_empty_pipe_says_so(pipe):
    with pytest.raises(BenchDataError, match="no data: the stream ended before its first byte"):
        load_bench(pipe(b""))


def test_fifo_without_writer_gives_up_with_a_message(tmp_path, monkeypatch):
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    monkeypatch.setattr(_streams, "STREAM_TIMEOUT_S", 0.3)
    with pytest.raises(BenchDataError, match=r"fifo.csv: no data arrived within 0.3 s \(a pipe "
                                             r"or FIFO with no writer\?\)"):
        load_bench(fifo)
    with pytest.raises(BenchDataError, match="no data arrived within 0.3 s"):
        load_decay(fifo)


def test_fifo_with_a_late_writer_loads(tmp_path):
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)

    def write():
        threading.Event().wait(0.2)
        with open(fifo, "w") as out:  # blocks until the loader has opened the FIFO
            out.write(QUOTED)

    writer = threading.Thread(target=write, daemon=True)
    writer.start()
    bench = load_bench(fifo)
    writer.join(timeout=30)
    assert bench.muscles == ("A", "B") and len(bench) == 4


def test_cli_fifo_without_writer_exits_2_with_one_line(tmp_path, monkeypatch, capsys):
    from pamid._cli import main

    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    monkeypatch.setattr(_streams, "STREAM_TIMEOUT_S", 0.3)
    reads = []
    real = _streams._read_stream

    def spy(*args):
        reads.append(args[0])
        return real(*args)

    monkeypatch.setattr(_streams, "_read_stream", spy)
    # diagnose peeks at the header first (decay file or bench file?), then loads: the FIFO
    # is waited for once, and the one error reported.
    for command in (["fit", str(fifo), "--json"], ["diagnose", str(fifo), "--json"]):
        reads.clear()
        assert main(command) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1] == (f"pamid: error: {fifo}: no data arrived within 0.3 s (a pipe or FIFO "
                           "with no writer?)")
        assert sum(line.startswith("pamid: error:") for line in err) == 1
        assert len(reads) == 1


def test_header_peek_leaves_the_pipe_to_the_loader(pipe):
    from pamid._diagnose._api import _is_decay_file

    path = pipe(decay_csv())
    assert _is_decay_file(Path(path))
    data = load_decay(path)  # the bytes the peek read, not a pipe emptied by it
    assert len(data) == 60 and data.trials == ("1",)
    bench_path = pipe(QUOTED)
    assert not _is_decay_file(Path(bench_path))
    assert load_bench(bench_path).muscles == ("A", "B")


def test_decay_file_through_a_pipe(pipe, tmp_path):
    path = tmp_path / "d.csv"
    path.write_text(decay_csv())
    pd.testing.assert_frame_equal(load_decay(pipe(decay_csv())).frame, load_decay(path).frame,
                                  check_exact=True)


def test_one_reader_registry_decides_every_format():
    from pamid._data._readers import CSV, FORMATS, READERS, reader_for

    csv, parquet, sheets = FORMATS
    assert csv is CSV
    assert {suffix: reader.name for suffix, reader in READERS.items()} == {
        ".csv": "CSV files", ".tsv": "CSV files", ".txt": "CSV files",
        ".parquet": "Parquet files", ".pq": "Parquet files",
        ".xlsx": "spreadsheets", ".xlsm": "spreadsheets", ".xlsb": "spreadsheets",
        ".xls": "spreadsheets", ".ods": "spreadsheets",
    }
    # A regular file (no bytes given) by its extension alone; an unknown one is CSV.
    assert reader_for(Path("a.PQ"), None) is parquet
    assert reader_for(Path("a.ODS"), None) is sheets
    assert reader_for(Path("a.dat"), None) is csv
    assert reader_for(Path("a"), None) is csv
    # A stream by its first bytes, unless its name has a binary format's extension.
    assert reader_for(Path("/dev/fd/5"), b"PAR1\x15\x04") is parquet
    assert reader_for(Path("/dev/fd/5"), b"PK\x03\x04\x14\x00") is sheets
    assert reader_for(Path("/dev/fd/5"), b"\xd0\xcf\x11\xe0\xa1\xb1") is sheets
    assert reader_for(Path("fifo.csv"), b"PAR1\x15\x04") is parquet
    assert reader_for(Path("/dev/fd/5"), b"time_s,angle_rad\n") is csv
    assert reader_for(Path("f.xlsx"), b"PAR1\x15\x04") is sheets
    assert [r.name for r in FORMATS if "decimal" in r.options] == ["CSV files", "spreadsheets"]


@pytest.mark.parametrize("kind", ["parquet", "xlsx", "parquet through a pipe"])
def test_decay_file_in_every_format_of_the_registry(kind, pipe, tmp_path):
    from pamid._data._readers import column_names
    from pamid._diagnose._api import _is_decay_file

    csv_path = tmp_path / "d.csv"
    csv_path.write_text(decay_csv())
    expected = load_decay(csv_path).frame
    frame = pd.read_csv(csv_path)
    if kind == "xlsx":
        from openpyxl import Workbook

        path = tmp_path / "d.xlsx"
        workbook = Workbook()
        workbook.active.append(list(frame.columns))
        for row in frame.itertuples(index=False):
            workbook.active.append([float(v) for v in row])
        workbook.save(path)
    else:
        path = tmp_path / "d.parquet"
        frame.to_parquet(path, index=False)
        if kind == "parquet through a pipe":
            path = pipe(path.read_bytes())
    assert column_names(path) == ["time_s", "angle_rad"]  # a pipe's bytes kept for the loader
    assert _is_decay_file(Path(path))
    pd.testing.assert_frame_equal(load_decay(path).frame, expected, check_exact=True)


def test_parquet_through_a_pipe_is_recognised_by_its_bytes(pipe, tmp_path):
    path = tmp_path / "b.parquet"
    pd.read_csv(io.StringIO(PLAIN)).to_parquet(path)
    from_pipe = load_bench(pipe(path.read_bytes()))
    pd.testing.assert_frame_equal(from_pipe.frame, load_bench(path).frame, check_exact=True)


def test_dev_stdin_in_a_subprocess(tmp_path, cli_env):
    env = cli_env
    cli = [sys.executable, "-m", "pamid._cli"]
    bad = subprocess.run(cli + ["fit", "/dev/stdin", "--json"], input=BAD_CELL,
                         capture_output=True, text=True, env=env, timeout=300)
    assert bad.returncode == 2
    assert bad.stderr.strip() == ("pamid: error: /dev/stdin, column 'force_N', row 2 (line 3): "
                                  "'abc' is not a number")
    assert bad.stdout == ""
    # `cat f.csv | pamid fit /dev/stdin --json`: 4 rows, 2 muscles (too few rows to converge:
    # exit 1, with the JSON all the same)
    good = subprocess.run(cli + ["fit", "/dev/stdin", "--json", "--intervals", "wald"],
                          input=QUOTED, capture_output=True, text=True, env=env, timeout=300)
    assert good.returncode in (0, 1), good.stderr
    payload = json.loads(good.stdout)
    assert [m["muscle"] for m in payload["muscles"]] == ["A", "B"]
    assert [m["n"] for m in payload["muscles"]] == [3, 1]
    # `pamid fit /dev/stdin < f.csv`: stdin is a regular file then, read as one.
    path = tmp_path / "q.csv"
    path.write_text(QUOTED)
    with open(path) as stdin:
        redirected = subprocess.run(
            [sys.executable, "-c", "import pamid, json; b = pamid.load_bench('/dev/stdin'); "
                                   "print(json.dumps([list(b.muscles), len(b)]))"],
            stdin=stdin, capture_output=True, text=True, env=env, timeout=300)
    assert redirected.returncode == 0, redirected.stderr
    assert json.loads(redirected.stdout) == [["A", "B"], 4]


def test_dev_null_is_an_empty_stream():
    with pytest.raises(BenchDataError, match="/dev/null: no data: the stream ended"):
        load_bench("/dev/null")


def test_dev_zero_stops_as_binary():
    with pytest.raises(BenchDataError, match="binary data"):
        load_bench("/dev/zero")


# ---------------------------------------------------------------------------------------
# Wide files: linear in the number of columns
# ---------------------------------------------------------------------------------------


def wide_csv(n_columns: int, n_rows: int = 10, *, quoted: bool = False, text_at=None) -> str:
    rng = np.random.default_rng(1)
    names = ["pressure_kPa", "force_N", "contraction_pct"]
    names += [f"x{j}" for j in range(3, n_columns)]
    values = rng.normal(size=(n_rows, n_columns - 3)).round(4)
    lines = [",".join(f'"{n}"' if quoted else n for n in names)]
    for i in range(n_rows):
        cells = [str(100 + 50 * i), str(200 - 10 * i), str(2.0 * i)]
        cells += [repr(float(v)) for v in values[i]]
        if text_at is not None:
            cells[text_at] = f"note{i}"
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


@pytest.mark.timeout(60)
@pytest.mark.parametrize("quoted", [False, True], ids=["plain", "quoted"])
def test_twenty_thousand_columns_load(tmp_path, quoted):
    path = tmp_path / "wide.csv"
    path.write_text(wide_csv(20_000, quoted=quoted))
    bench = load_bench(path)
    assert len(bench) == 10
    assert len(bench.covariates) == 19_997
    assert bench.covariates[:2] == ("x3", "x4") and bench.covariates[-1] == "x19999"
    expected = pd.read_csv(path)
    np.testing.assert_array_equal(bench.frame["x19999"].to_numpy(),
                                  expected["x19999"].to_numpy())
    np.testing.assert_array_equal(bench.frame["force_N"].to_numpy(), 200.0 - 10 * np.arange(10))


def test_wide_file_readers_agree(tmp_path, monkeypatch):
    """The fast reader checks wide files in blocks of columns; a text column, blanks in an
    optional column and a bad cell in a required one read as the cell-by-cell reader reads
    them."""
    monkeypatch.setattr(_csv, "_BLOCK_CELLS", 64)  # blocks of 6 columns of 10 rows
    text = wide_csv(40, text_at=17)
    lines = text.splitlines()
    lines[3] = ",".join(c if j != 25 else "" for j, c in enumerate(lines[3].split(",")))
    path = tmp_path / "w.csv"
    path.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings(record=True) as fast_warnings:
        warnings.simplefilter("always")
        fast = load_bench(path)
    assert len(fast_warnings) == 1 and "x25" in str(fast_warnings[0].message)
    monkeypatch.setattr(_csv, "_FAST_CSV", False)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        slow = load_bench(path)
    pd.testing.assert_frame_equal(fast.frame, slow.frame, check_exact=True)
    assert fast.covariates == slow.covariates and "x17" not in fast.covariates
    assert np.isnan(fast.frame["x25"][2])
    monkeypatch.setattr(_csv, "_FAST_CSV", True)
    lines[5] = ",".join(c if j != 1 else "" for j, c in enumerate(lines[5].split(",")))
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(BenchDataError, match=r"column 'force_N', row 5 \(line 6\): empty cell"):
        load_bench(path)


def test_fast_reader_takes_a_wide_file(tmp_path):
    path = tmp_path / "wide.csv"
    path.write_text(wide_csv(300))
    table = _csv._read_csv_fast(path, str(path))
    assert table is not None and len(table.names) == 300
    # muscle, the 300 columns, source_row
    assert pamid.load_bench(path).frame.shape == (10, 1 + 300 + 1)


def test_the_environment_switches_the_fast_reader_off(tmp_path, monkeypatch):
    # PAMID_FAST_CSV=0 (how benchmarks/load_bench.py times the cell-by-cell reader): the
    # fast reader is not tried, and the table is the same.
    path = tmp_path / "wide.csv"
    path.write_text(wide_csv(20))
    fast = pamid.load_bench(path)
    tried = []
    monkeypatch.setattr(_csv, "_read_csv_fast", lambda *a, **k: tried.append(a))
    monkeypatch.setenv("PAMID_FAST_CSV", "0")
    slow = pamid.load_bench(path)
    assert tried == []
    pd.testing.assert_frame_equal(fast.frame, slow.frame, check_exact=True)
    monkeypatch.setenv("PAMID_FAST_CSV", "1")
    pamid.load_bench(path)
    assert len(tried) == 1


def test_numbers_pyarrow_parses_read_as_the_cell_by_cell_reader_reads_them(tmp_path, monkeypatch):
    # The fast reader has pyarrow parse known numeric columns as float64 (no byte-level check
    # of the cells): every cell must give the cell-by-cell reader's number or, where that
    # reader refuses the cell, its error; random cells over the characters of numbers, and
    # cells pyarrow reads that float() would read differently or not at all.
    rng = np.random.default_rng(7)
    alphabet = np.array(list("0123456789+-.eE"))
    cells = ["".join(rng.choice(alphabet, size=rng.integers(1, 9))) for _ in range(150)]
    cells += ["1.", ".5", "+.5e-3", "-0", "0001", "1e400", "-1e-400", "nan", "NaN", "-nan",
              "inf", "+inf", "Infinity", "1_0", "١٠", "0x10", "1e", "e1", "1,5", "1e5.0",
              "0.1000000000000000055511151231257827021181583404541015625", "9007199254740993"]
    for j, cell in enumerate(cells):
        path = tmp_path / f"c{j}.csv"
        path.write_text(f"pressure_kPa,force_N,contraction_pct,time_s\n{cell},10,5,0\n"
                        f"200,10,{cell},1\n")
        outcomes = []
        for fast in (True, False):
            monkeypatch.setattr(_csv, "_FAST_CSV", fast)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    outcomes.append(load_bench(path).frame)
            except BenchDataError as err:
                outcomes.append(str(err))
        if isinstance(outcomes[1], str):
            assert outcomes[0] == outcomes[1], cell
        else:
            pd.testing.assert_frame_equal(outcomes[0], outcomes[1], check_exact=True)
            assert np.signbit(outcomes[0]["pressure_kPa"][0]) == np.signbit(float(cell)), cell
    # a blank or a tab anywhere: the numbers are read as text, cell by cell where they must
    path = tmp_path / "blank.csv"
    path.write_text("muscle,pressure_kPa,force_N,contraction_pct\nA, 100,10,5\nA,200,20,5\n")
    table = _csv._read_csv_fast(path, str(path))
    assert table is None or table.columns["pressure_kPa"].values is None
    assert load_bench(path).frame["pressure_kPa"].tolist() == [100.0, 200.0]
