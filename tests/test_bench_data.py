"""Tests for the bench-data loader (pamid._data._bench), units and atomic output writers."""

from __future__ import annotations

import os
import warnings
from decimal import Decimal
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pamid._data import _csv
from pamid._data._bench import BenchData, CensoredRowsWarning, load_bench
from pamid._errors import BenchDataError
from pamid._io import (
    refuse_overwrite_input,
    save_figure_atomic,
    write_atomic,
    write_bytes_atomic,
    write_frame_atomic,
    write_text_atomic,
)
from pamid._units import (
    ATMOSPHERE_KPA,
    KPA_PER_BAR,
    KPA_PER_PA,
    KPA_PER_PSI,
    pressure_text_to_kPa,
    pressure_to_kPa,
)

MARTENS = Path("/work/shared/data/martens_dmsp10_250.csv")

BASIC = """\
muscle,pressure_kPa,contraction_pct,force_N
A,100,0,150.5
A,100,5,120.25
A,200,10,200
B,300,15,250
"""


def write(tmp_path: Path, text: str, name: str = "bench.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def csv_rows(header: str, rows: list[str]) -> str:
    return "\n".join([header, *rows]) + "\n"


def raises(path, match, **kwargs) -> BenchDataError:
    with pytest.raises(BenchDataError, match=match) as info:
        load_bench(path, **kwargs)
    return info.value


# ----------------------------------------------------------------------------------------
# Units
# ----------------------------------------------------------------------------------------


def test_unit_constants():
    assert KPA_PER_BAR == 100.0
    assert KPA_PER_PA == 1e-3
    assert ATMOSPHERE_KPA == 101.325
    assert KPA_PER_PSI == pytest.approx(4.4482216152605 / 0.0254**2 / 1000, rel=1e-15)


def test_pressure_to_kPa_units():
    assert pressure_to_kPa([2.5], "bar")[0] == 250.0
    assert pressure_to_kPa(250_000.0, "Pa") == 250.0
    assert pressure_to_kPa([1.0], "psi")[0] == KPA_PER_PSI
    np.testing.assert_array_equal(pressure_to_kPa([1.0, 2.0], "kPa"), [1.0, 2.0])
    with pytest.raises(ValueError, match="unknown pressure unit 'atm'.*kPa, bar, Pa, psi"):
        pressure_to_kPa([1.0], "atm")
    with pytest.raises(ValueError, match="unknown pressure unit"):
        pressure_text_to_kPa(["1"], "mmHg")


def test_pressure_text_conversion_is_exact():
    assert pressure_text_to_kPa(["2.505"], "bar")[0] == 250.5
    assert pressure_text_to_kPa(["250500"], "Pa")[0] == 250.5
    assert pressure_text_to_kPa(["1"], "psi")[0] == KPA_PER_PSI


# ----------------------------------------------------------------------------------------
# Loading: positive cases
# ----------------------------------------------------------------------------------------


def test_basic_csv(tmp_path):
    data = load_bench(write(tmp_path, BASIC))
    assert isinstance(data, BenchData)
    assert data.path == str(tmp_path / "bench.csv")
    assert data.has_muscle_column
    assert data.muscles == ("A", "B")
    assert data.covariates == ()
    assert data.n_censored == 0
    assert data.pressure_unit_in_file == "kPa"
    assert data.l0_mm == {"A": None, "B": None}
    frame = data.frame
    assert list(frame.columns) == [
        "muscle",
        "pressure_kPa",
        "contraction_pct",
        "force_N",
        "source_row",
    ]
    for name in ("pressure_kPa", "contraction_pct", "force_N"):
        assert frame[name].dtype == np.float64
    assert frame["force_N"].tolist() == [150.5, 120.25, 200.0, 250.0]
    assert frame["source_row"].tolist() == [1, 2, 3, 4]
    assert len(data.for_muscle("B")) == 1
    assert data.for_muscle("A")["contraction_pct"].tolist() == [0.0, 5.0, 10.0]
    with pytest.raises(KeyError, match="no muscle 'C'"):
        data.for_muscle("C")


def test_no_muscle_column(tmp_path):
    path = write(tmp_path, "pressure_kPa,contraction_pct,force_N\n100,0,10\n200,5,20\n")
    data = load_bench(path)
    assert not data.has_muscle_column
    assert data.muscles == ("muscle",)
    assert data.frame["muscle"].tolist() == ["muscle", "muscle"]


KPA = ["0", "12.3", "250.5", "312.7", "600", "-50.25"]
BAR = ["0", "0.123", "2.505", "3.127", "6", "-0.5025"]
PA = ["0", "12300", "250500", "312700", "600000", "-50250"]


@pytest.mark.parametrize(("unit", "cells"), [("kPa", KPA), ("bar", BAR), ("Pa", PA)])
def test_pressure_units_convert_exactly(tmp_path, unit, cells):
    rows = [f"{p},5,10" for p in cells]
    path = write(tmp_path, csv_rows(f"pressure_{unit},contraction_pct,force_N", rows))
    data = load_bench(path)
    assert data.pressure_unit_in_file == unit
    assert data.frame["pressure_kPa"].tolist() == [float(p) for p in KPA]


def test_pressure_psi(tmp_path):
    cells = ["1", "10", "14.5", "87.0226"]
    rows = [f"{p},5,10" for p in cells]
    path = write(tmp_path, csv_rows("pressure_psi,contraction_pct,force_N", rows))
    data = load_bench(path)
    got = data.frame["pressure_kPa"].to_numpy()
    assert got[0] == KPA_PER_PSI
    exact = [float(Decimal(c) * Decimal("4.4482216152605") / Decimal("0.64516")) for c in cells]
    assert got.tolist() == exact
    np.testing.assert_allclose(got, np.array(cells, dtype=float) * KPA_PER_PSI, rtol=1e-15)


def test_length_with_l0_column(tmp_path):
    text = csv_rows(
        "muscle,pressure_kPa,length_mm,l0_mm,force_N",
        ["A,100,250,250,10", "A,100,200,250,20", "B,100,90,100,30"],
    )
    data = load_bench(write(tmp_path, text))
    assert data.frame["contraction_pct"].tolist() == [0.0, 20.0, 10.0]
    assert data.l0_mm == {"A": 250.0, "B": 100.0}
    assert data.frame["length_mm"].tolist() == [250.0, 200.0, 90.0]
    assert data.frame["l0_mm"].tolist() == [250.0, 250.0, 100.0]


def test_length_with_l0_argument(tmp_path):
    text = csv_rows("pressure_kPa,length_mm,force_N", ["100,250,10", "100,225,20"])
    data = load_bench(write(tmp_path, text), l0_mm=250)
    assert data.frame["contraction_pct"].tolist() == [0.0, 10.0]
    assert data.l0_mm == {"muscle": 250.0}


def test_contraction_preferred_over_length(tmp_path):
    text = csv_rows(
        "pressure_kPa,length_mm,contraction_pct,force_N", ["100,250,1.5,10", "100,240,4,20"]
    )
    data = load_bench(write(tmp_path, text))
    assert data.frame["contraction_pct"].tolist() == [1.5, 4.0]
    assert data.frame["length_mm"].tolist() == [250.0, 240.0]


def test_multi_muscle_order_and_string_ids(tmp_path):
    rows = ["B,100,1,10", "007,100,1,10", "B,200,2,20", "C,100,1,10", "007,300,3,30"]
    data = load_bench(
        write(tmp_path, csv_rows("muscle,pressure_kPa,contraction_pct,force_N", rows))
    )
    assert data.muscles == ("B", "007", "C")
    assert data.for_muscle("007")["pressure_kPa"].tolist() == [100.0, 300.0]
    assert data.for_muscle("007")["source_row"].tolist() == [2, 5]


def test_optional_columns_and_covariates(tmp_path):
    header = (
        "muscle,time_s,pressure_bar,contraction_pct,force_N,direction,temperature_C,cycle,"
        "velocity_mm_s,supply_flow,note"
    )
    rows = [
        "A,0.0,1,0,10,1,21.5,1,0.0,3,start",
        "A,0.5,2,5,20,1,21.6,1,2.5,4,",
        "A,1.0,2,4,18,-1,21.7,2,-1.0,5,slow leak",
    ]
    data = load_bench(write(tmp_path, csv_rows(header, rows)))
    assert data.covariates == ("velocity_mm_s", "supply_flow")
    frame = data.frame
    assert list(frame.columns) == [
        "muscle",
        "pressure_kPa",
        "contraction_pct",
        "force_N",
        "time_s",
        "direction",
        "temperature_C",
        "cycle",
        "velocity_mm_s",
        "supply_flow",
        "note",
        "source_row",
    ]
    assert frame["direction"].tolist() == [1, 1, -1]
    assert frame["cycle"].tolist() == [1, 1, 2]
    assert frame["supply_flow"].dtype == np.float64
    assert frame["note"].tolist() == ["start", "", "slow leak"]
    assert frame["pressure_kPa"].tolist() == [100.0, 200.0, 200.0]


def test_time_increases_per_muscle_interleaved(tmp_path):
    rows = ["A,0,100,1,10", "B,0,100,1,10", "A,1,100,1,10", "B,0.5,100,1,10"]
    data = load_bench(
        write(tmp_path, csv_rows("muscle,time_s,pressure_kPa,contraction_pct,force_N", rows))
    )
    assert data.frame["time_s"].tolist() == [0.0, 0.0, 1.0, 0.5]


CENSORED = csv_rows(
    "muscle,pressure_kPa,contraction_pct,force_N",
    ["A,100,0,50", "A,100,10,0", "A,200,0,100", "A,200,20,0", "A,200,10,-0.0", "A,300,5,80"],
)


def test_censored_rows_dropped_with_warning(tmp_path):
    path = write(tmp_path, CENSORED)
    with pytest.warns(CensoredRowsWarning, match=r"dropped 3 censored rows \(force_N exactly 0\)"):
        data = load_bench(path)
    assert data.n_censored == 3
    assert len(data.frame) == 3
    assert data.frame["source_row"].tolist() == [1, 3, 6]
    assert data.frame["force_N"].tolist() == [50.0, 100.0, 80.0]
    assert data.frame.index.tolist() == [0, 1, 2]


def test_censored_rows_kept_on_request(tmp_path):
    path = write(tmp_path, CENSORED)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data = load_bench(path, keep_censored=True)
    assert data.n_censored == 0
    assert len(data.frame) == 6
    assert data.frame["source_row"].tolist() == [1, 2, 3, 4, 5, 6]


def test_muscle_with_only_censored_rows_is_left_out(tmp_path):
    text = csv_rows("muscle,pressure_kPa,contraction_pct,force_N", ["A,100,0,5", "B,100,0,0"])
    with pytest.warns(CensoredRowsWarning, match="dropped 1 censored rows.*'B'"):
        data = load_bench(write(tmp_path, text))
    assert data.muscles == ("A",)


def test_on_rows_gets_the_rows_each_muscle_keeps_before_the_frame_is_made(tmp_path):
    text = csv_rows("muscle,pressure_kPa,contraction_pct,force_N",
                    ["A,100,0,5", "B,100,0,0", "A,200,0,9", "C,100,0,4", "A,300,0,0",
                     "C,200,0,7"])
    seen = []
    with pytest.warns(CensoredRowsWarning):
        data = load_bench(write(tmp_path, text), on_rows=lambda rows: seen.append(rows.tolist()))
    assert data.muscles == ("A", "C") and seen == [[2, 2]]  # B's only row was censored
    seen.clear()
    load_bench(write(tmp_path, text), keep_censored=True,
               on_rows=lambda rows: seen.append(rows.tolist()))
    assert seen == [[3, 1, 2]]


@pytest.mark.skipif(not MARTENS.exists(), reason="shared Martens data file not available")
def test_martens_file():
    with pytest.warns(CensoredRowsWarning, match="dropped 45 censored rows"):
        data = load_bench(MARTENS)
    assert data.n_censored == 45
    assert len(data.frame) == 85 - 45
    assert data.muscles == ("DMSP-10-250",)
    assert (data.frame["force_N"] != 0).all()
    kept = load_bench(MARTENS, keep_censored=True)
    assert len(kept.frame) == 85
    np.testing.assert_allclose(
        kept.frame["contraction_pct"], 100 * (250 - kept.frame["length_mm"]) / 250, atol=0.05
    )


@pytest.mark.parametrize("suffix", [".parquet", ".pq"])
def test_parquet_round_trip(tmp_path, suffix):
    original = pd.DataFrame(
        {
            "muscle": ["A", "A", "B", "B"],
            "pressure_bar": [1.0, 2.5, 3.0, 0.0],
            "contraction_pct": [0.0, 10.0, 5.0, 12.0],
            "force_N": [10.0, 0.0, 30.5, 40.0],
            "cycle": [1, 1, 2, 2],
            "humidity": [0.4, 0.5, 0.5, 0.6],
            "note": ["x", "y", None, "z"],
        }
    )
    path = tmp_path / f"bench{suffix}"
    original.to_parquet(path)
    with pytest.warns(CensoredRowsWarning, match="dropped 1 censored"):
        data = load_bench(path)
    assert data.pressure_unit_in_file == "bar"
    assert data.muscles == ("A", "B")
    assert data.covariates == ("humidity",)
    assert data.frame["pressure_kPa"].tolist() == [100.0, 300.0, 0.0]
    assert data.frame["source_row"].tolist() == [1, 3, 4]
    assert data.frame["cycle"].tolist() == [1, 2, 2]
    kept = load_bench(path, keep_censored=True)
    pd.testing.assert_series_equal(
        kept.frame["force_N"], original["force_N"], check_names=False, check_index=False
    )

    # and back: writing the frame as Parquet and loading it again gives the same frame
    out = tmp_path / "again.parquet"
    write_frame_atomic(out, kept.frame.drop(columns="source_row"))
    again = load_bench(out, keep_censored=True)
    pd.testing.assert_frame_equal(again.frame, kept.frame)


def test_csv_round_trip_through_write_frame(tmp_path):
    data = load_bench(write(tmp_path, BASIC))
    out = tmp_path / "out.csv"
    write_frame_atomic(out, data.frame.drop(columns="source_row"))
    again = load_bench(out)
    pd.testing.assert_frame_equal(again.frame, data.frame)


def test_semicolon_and_blank_lines(tmp_path):
    text = "\nmuscle;pressure_kPa;contraction_pct;force_N\nA;100;0;10\n\nA;100;5;oops\n"
    err = raises(write(tmp_path, text), "'oops' is not a number")
    assert (err.column, err.row, err.line) == ("force_N", 2, 5)


# ----------------------------------------------------------------------------------------
# Loading: errors
# ----------------------------------------------------------------------------------------


def test_missing_file(tmp_path):
    err = raises(tmp_path / "nope.csv", "nope.csv: file not found")
    assert err.path == str(tmp_path / "nope.csv")
    raises(tmp_path / "nope.parquet", "file not found")


def test_directory(tmp_path):
    (tmp_path / "d.csv").mkdir()
    raises(tmp_path / "d.csv", "is a directory")


@pytest.mark.parametrize("name", ["empty.csv", "empty.parquet"])
def test_empty_file(tmp_path, name):
    (tmp_path / name).write_bytes(b"")
    raises(tmp_path / name, r"empty \(0 bytes\)")


def test_only_blank_lines(tmp_path):
    raises(write(tmp_path, "\n\n  \n"), "only blank lines")


def test_header_without_rows(tmp_path):
    raises(write(tmp_path, "pressure_kPa,contraction_pct,force_N\n"), "no data rows")


def test_parquet_without_rows(tmp_path):
    frame = pd.DataFrame({"pressure_kPa": [], "contraction_pct": [], "force_N": []})
    frame.to_parquet(tmp_path / "e.parquet")
    raises(tmp_path / "e.parquet", "no data rows")


def test_binary_bytes(tmp_path):
    path = tmp_path / "noise.csv"
    path.write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 2000, dtype=np.uint8)))
    raises(path, "not a table: the file holds binary data")
    png = tmp_path / "image.csv"
    png.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + b"\x01" * 50)
    raises(png, "binary data")


def test_parquet_with_csv_extension(tmp_path):
    path = tmp_path / "data.csv"
    pd.DataFrame({"pressure_kPa": [1.0]}).to_parquet(path)
    raises(path, "Parquet file, not CSV")


def test_corrupt_parquet(tmp_path):
    path = write(tmp_path, BASIC, name="bench.parquet")
    raises(path, "cannot read it as Parquet")


def test_text_without_recognisable_columns(tmp_path):
    path = write(tmp_path, "Dear diary,\ntoday the muscle worked.\n", name="notes.txt")
    err = raises(
        path,
        r"none of the required columns.*pressure_kPa.*force_N.*contraction_pct.*"
        r"Columns found: Dear diary",
    )
    assert err.column is None


def test_missing_required_column(tmp_path):
    err = raises(
        write(tmp_path, "muscle,pressure_kPa,contraction_pct\nA,1,2\n"),
        r"missing required column: force_N\. Columns found: muscle, pressure_kPa, "
        r"contraction_pct",
    )
    assert err.column == "force_N"
    err = raises(
        write(tmp_path, "pressure_kPa,force_N\n1,2\n"), "missing required column: contraction_pct"
    )
    assert err.column == "contraction_pct"
    raises(write(tmp_path, "force_N,contraction_pct\n1,2\n"), "missing required column: pressure")


@pytest.mark.parametrize(
    ("column", "accepted"),
    [
        ("pressure_atm", "kPa, bar, Pa, psi"),
        ("force_kN", "N"),
        ("force_lbf", "N"),
        ("time_ms", "s"),
        ("temperature_F", "C"),
        ("contraction_frac", "pct"),
        ("length_cm", "mm"),
        ("l0_m", "mm"),
        ("velocity_m_s", "mm_s"),
    ],
)
def test_unknown_unit(tmp_path, column, accepted):
    text = csv_rows(f"pressure_kPa,contraction_pct,force_N,{column}", ["1,2,3,4"])
    if column.startswith("pressure"):
        text = csv_rows(f"{column},contraction_pct,force_N", ["1,2,3"])
    err = raises(write(tmp_path, text), f"unknown unit .*accepted units: {accepted}")
    assert err.column == column
    assert f"column '{column}'" in str(err)


@pytest.mark.parametrize(
    ("column", "right"), [("pressure_kpa", "pressure_kPa"), ("force_n", "force_N")]
)
def test_unit_case_matters(tmp_path, column, right):
    text = csv_rows("pressure_kPa,contraction_pct,force_N", ["1,2,3"]).replace(right, column)
    err = raises(write(tmp_path, text), f"case-sensitive: name the column {right}")
    assert err.column == column


def test_quantity_without_unit(tmp_path):
    text = csv_rows("pressure,contraction_pct,force_N", ["1,2,3"])
    err = raises(write(tmp_path, text), "no unit in the column name.*kPa, bar, Pa, psi")
    assert err.column == "pressure"


def test_two_pressure_units(tmp_path):
    text = csv_rows("pressure_kPa,pressure_bar,contraction_pct,force_N", ["100,1,2,3"])
    err = raises(write(tmp_path, text), "more than one pressure column.*ambiguous")
    assert err.column == "pressure_bar"


def test_duplicate_column_csv(tmp_path):
    text = csv_rows("pressure_kPa,force_N,contraction_pct,force_N", ["100,1,2,3"])
    err = raises(write(tmp_path, text), r"appears twice in the header \(columns 2 and 4\)")
    assert err.column == "force_N"


def test_duplicate_column_parquet(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_arrays(
        [pa.array([100.0]), pa.array([1.0]), pa.array([2.0]), pa.array([3.0])],
        names=["pressure_kPa", "force_N", "contraction_pct", "force_N"],
    )
    pq.write_table(table, tmp_path / "dup.parquet")
    err = raises(tmp_path / "dup.parquet", "appears twice")
    assert err.column == "force_N"


def test_non_numeric_cell_reports_row_and_line(tmp_path):
    rows = [f"{100 + i},5,{10 + i}" for i in range(10)]
    rows[6] = "106,5,abc"
    rows[8] = "108,5,xyz"
    err = raises(
        write(tmp_path, csv_rows("pressure_kPa,contraction_pct,force_N", rows)),
        r"column 'force_N', row 7 \(line 8\): 'abc' is not a number",
    )
    assert (err.column, err.row, err.line) == ("force_N", 7, 8)


def test_first_offending_row_across_columns(tmp_path):
    rows = ["100,5,10", "100,5,bad", "100,x,10"]
    err = raises(write(tmp_path, csv_rows("pressure_kPa,contraction_pct,force_N", rows)), "bad")
    assert (err.column, err.row) == ("force_N", 2)


def test_empty_cell(tmp_path):
    rows = ["100,5,10", "100,,10"]
    err = raises(
        write(tmp_path, csv_rows("pressure_kPa,contraction_pct,force_N", rows)), "empty cell"
    )
    assert (err.column, err.row, err.line) == ("contraction_pct", 2, 3)


@pytest.mark.parametrize(
    ("cell", "what"), [("nan", "NaN"), ("NaN", "NaN"), ("inf", "infinite"), ("-inf", "infinite")]
)
def test_nan_and_inf(tmp_path, cell, what):
    rows = ["100,5,10", "100,5,11", f"100,5,{cell}"]
    err = raises(write(tmp_path, csv_rows("pressure_kPa,contraction_pct,force_N", rows)), what)
    assert (err.column, err.row) == ("force_N", 3)


def test_nan_in_parquet(tmp_path):
    frame = pd.DataFrame(
        {"pressure_kPa": [1.0, 2.0, 3.0], "contraction_pct": [1, 2, 3], "force_N": [1, np.nan, 3]}
    )
    frame.to_parquet(tmp_path / "nan.parquet")
    err = raises(tmp_path / "nan.parquet", r"row 2: (NaN|missing value)")
    assert (err.column, err.row, err.line) == ("force_N", 2, None)


def test_nan_in_covariate(tmp_path):
    rows = ["100,5,10,1", "100,5,11,nan"]
    text = csv_rows("pressure_kPa,contraction_pct,force_N,humidity", rows)
    err = raises(write(tmp_path, text), "NaN")
    assert (err.column, err.row) == ("humidity", 2)


def test_negative_absolute_pressure(tmp_path):
    rows = ["0,5,10", "-1.01325,5,10", "-1.1,5,10"]
    text = csv_rows("pressure_bar,contraction_pct,force_N", rows)
    err = raises(write(tmp_path, text), r"gauge pressure -1.1 bar .*negative absolute pressure")
    assert (err.column, err.row) == ("pressure_bar", 3)


@pytest.mark.parametrize("value", ["60", "-15", "50.01"])
def test_contraction_out_of_range(tmp_path, value):
    rows = ["100,5,10", f"100,{value},10"]
    text = csv_rows("pressure_kPa,contraction_pct,force_N", rows)
    err = raises(write(tmp_path, text), r"outside the physical range -10 % to 50 %")
    assert (err.column, err.row) == ("contraction_pct", 2)


def test_contraction_from_length_out_of_range(tmp_path):
    text = csv_rows("pressure_kPa,length_mm,force_N", ["100,250,10", "100,100,10"])
    err = raises(
        write(tmp_path, text), "contraction of 60 %, outside the physical range", l0_mm=250
    )
    assert (err.column, err.row) == ("length_mm", 2)


def test_length_not_positive(tmp_path):
    text = csv_rows("pressure_kPa,length_mm,l0_mm,force_N", ["100,250,250,10", "100,0,250,10"])
    err = raises(write(tmp_path, text), "length_mm must be a positive length")
    assert (err.column, err.row) == ("length_mm", 2)


def test_l0_not_positive(tmp_path):
    text = csv_rows("pressure_kPa,length_mm,l0_mm,force_N", ["100,250,-250,10"])
    err = raises(write(tmp_path, text), "l0_mm must be a positive length")
    assert (err.column, err.row) == ("l0_mm", 1)
    text = csv_rows("pressure_kPa,length_mm,force_N", ["100,250,10"])
    err = raises(write(tmp_path, text), "l0_mm argument must be a positive length", l0_mm=0)
    assert err.column is None


def test_missing_l0(tmp_path):
    text = csv_rows("pressure_kPa,length_mm,force_N", ["100,250,10"])
    err = raises(write(tmp_path, text), "add an l0_mm column or pass .*--l0-mm")
    assert err.column == "length_mm"


def test_l0_varies_within_muscle(tmp_path):
    rows = ["A,100,250,250,10", "B,100,90,100,10", "A,100,240,260,10"]
    text = csv_rows("muscle,pressure_kPa,length_mm,l0_mm,force_N", rows)
    err = raises(write(tmp_path, text), "constant within a muscle")
    assert (err.column, err.row) == ("l0_mm", 3)
    assert "'A'" in str(err)


def test_l0_column_disagrees_with_argument(tmp_path):
    text = csv_rows("pressure_kPa,length_mm,l0_mm,force_N", ["100,240,250,10"])
    err = raises(write(tmp_path, text), "l0_mm argument is 300", l0_mm=300)
    assert err.column == "l0_mm"


@pytest.mark.parametrize("value", ["0", "2", "0.5", "up"])
def test_bad_direction(tmp_path, value):
    rows = ["100,5,10,1", "100,5,10,-1", f"100,5,10,{value}"]
    text = csv_rows("pressure_kPa,contraction_pct,force_N,direction", rows)
    match = "not a number" if value == "up" else r"direction must be \+1 .* or -1"
    err = raises(write(tmp_path, text), match)
    assert (err.column, err.row) == ("direction", 3)


def test_cycle_not_whole(tmp_path):
    text = csv_rows("pressure_kPa,contraction_pct,force_N,cycle", ["100,5,10,1", "100,5,10,1.5"])
    err = raises(write(tmp_path, text), "cycle must be a whole number")
    assert (err.column, err.row) == ("cycle", 2)


@pytest.mark.parametrize("bad_time", ["0.5", "1.0"])
def test_time_not_increasing(tmp_path, bad_time):
    rows = ["A,0,100,1,10", "B,5,100,1,10", "A,1.0,100,1,10", f"A,{bad_time},100,1,10"]
    text = csv_rows("muscle,time_s,pressure_kPa,contraction_pct,force_N", rows)
    err = raises(write(tmp_path, text), r"not later than 1.0 s on row 3 of muscle 'A'")
    assert (err.column, err.row, err.line) == ("time_s", 4, 5)


def test_ragged_row(tmp_path):
    text = csv_rows("pressure_kPa,contraction_pct,force_N", ["100,5,10", "100,5"])
    err = raises(write(tmp_path, text), "2 cells but the header .* names 3 columns")
    assert (err.row, err.line) == (2, 3)


def test_trailing_delimiters_are_tolerated(tmp_path):
    text = "pressure_kPa,contraction_pct,force_N,\n100,5,10,\n200,5,10,,\n"
    assert len(load_bench(write(tmp_path, text)).frame) == 2


def test_all_rows_censored(tmp_path):
    text = csv_rows("pressure_kPa,contraction_pct,force_N", ["100,5,0", "200,5,0"])
    raises(write(tmp_path, text), "all 2 data rows have force_N exactly 0")


def test_empty_muscle_id(tmp_path):
    text = csv_rows("muscle,pressure_kPa,contraction_pct,force_N", ["A,100,5,1", ",100,5,1"])
    err = raises(write(tmp_path, text), "empty muscle id")
    assert (err.column, err.row) == ("muscle", 2)


def test_reserved_column_name(tmp_path):
    text = csv_rows("pressure_kPa,contraction_pct,force_N,source_row", ["100,5,1,1"])
    err = raises(write(tmp_path, text), "reserved")
    assert err.column == "source_row"


def test_error_is_a_value_error(tmp_path):
    with pytest.raises(ValueError):
        load_bench(tmp_path / "missing.csv")


# ----------------------------------------------------------------------------------------
# Loading: the fast CSV reader gives what the cell-by-cell reader gives
# ----------------------------------------------------------------------------------------


def load_fast_and_slow(monkeypatch, path, **kwargs) -> tuple[BenchData, BenchData]:
    """Load ``path`` with the fast CSV reader (asserting that it read the file) and with the
    cell-by-cell reader alone, and check that both give the same BenchData."""
    used = []

    def spy(path, shown, **options):
        table = real(path, shown, **options)
        used.append(table is not None)
        return table

    real = _csv._read_csv_fast
    with monkeypatch.context() as patch:
        patch.setattr(_csv, "_read_csv_fast", spy)
        with warnings.catch_warnings(record=True) as fast_warnings:
            warnings.simplefilter("always")
            fast = load_bench(path, **kwargs)
    assert used == [True], "the fast reader did not take the file"
    with monkeypatch.context() as patch:
        patch.setattr(_csv, "_FAST_CSV", False)
        with warnings.catch_warnings(record=True) as slow_warnings:
            warnings.simplefilter("always")
            slow = load_bench(path, **kwargs)
    assert_same_bench(fast, slow)
    assert [str(w.message) for w in fast_warnings] == [str(w.message) for w in slow_warnings]
    return fast, slow


def assert_same_bench(a: BenchData, b: BenchData) -> None:
    pd.testing.assert_frame_equal(a.frame, b.frame, check_exact=True)
    assert a.frame["muscle"].dtype == b.frame["muscle"].dtype
    for name in (
        "path",
        "has_muscle_column",
        "muscles",
        "l0_mm",
        "covariates",
        "n_censored",
        "pressure_unit_in_file",
    ):
        assert getattr(a, name) == getattr(b, name), name
    assert [type(v) for v in a.l0_mm.values()] == [type(v) for v in b.l0_mm.values()]


def slow_error(monkeypatch, path, **kwargs) -> BenchDataError:
    with monkeypatch.context() as patch:
        patch.setattr(_csv, "_FAST_CSV", False)
        with pytest.raises(BenchDataError) as info:
            load_bench(path, **kwargs)
    return info.value


def bench_text(rng, n_muscles=3, rows=40, *, unit="kPa", interleave=False, censor=True) -> str:
    """A clean bench CSV with many kinds of column (numbers written in varied ways)."""
    header = (
        f"muscle,time_s,pressure_{unit},length_mm,l0_mm,contraction_pct,force_N,direction,"
        "cycle,temperature_C,velocity_mm_s,humidity,note"
    )
    scale = {"kPa": 1.0, "bar": 0.01, "Pa": 1000.0, "psi": 1 / KPA_PER_PSI}[unit]
    ids = [f"M{i:03d}" for i in range(n_muscles)]
    ids[-1] = "Müller 7"
    order = (
        [i % n_muscles for i in range(rows)]
        if interleave
        else sorted(i % n_muscles for i in range(rows))
    )
    clock = dict.fromkeys(range(n_muscles), 0.0)
    lines = [header]
    for k, m in enumerate(order):
        clock[m] += float(rng.choice([0.5, 1.0, 2.25]))
        l0 = [250.0, 400.5, 100.0][m % 3]
        pct = round(float(rng.uniform(0, 30)), int(rng.integers(0, 6)))
        force = 0.0 if censor and k % 7 == 3 else float(rng.uniform(1, 900))
        pressure = round(float(rng.choice([100, 250.5, 312.7, rng.uniform(0, 600)])), 3) * scale
        cells = [
            ids[m],
            repr(clock[m]),
            rng.choice([repr(pressure), f"{pressure:.6g}", f"{pressure:e}"]),
            f"{l0 * (1 - pct / 100):.4f}",
            rng.choice(["250", "250.0", "2.5e2"]) if l0 == 250.0 else repr(l0),
            repr(pct),
            rng.choice([repr(force), f"{force:.3f}", "0" if force == 0 else f"{force:.2e}"]),
            rng.choice(["1", "-1", "+1", "1.0"]),
            str(1 + k // 10),
            f"{rng.uniform(15, 30):.2f}",
            repr(float(rng.normal())),
            rng.choice(["0.5", ".61", "1e-3", "7"]),
            rng.choice(["", "ok", "slow leak", "3", "n/a"]),
        ]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("unit", ["kPa", "bar", "Pa", "psi"])
@pytest.mark.parametrize("interleave", [False, True])
@pytest.mark.parametrize("keep_censored", [False, True])
def test_fast_reader_matches_slow_reader(tmp_path, monkeypatch, unit, interleave, keep_censored):
    rng = np.random.default_rng([len(unit), interleave, keep_censored])
    path = write(tmp_path, bench_text(rng, rows=60, unit=unit, interleave=interleave))
    fast, _ = load_fast_and_slow(monkeypatch, path, keep_censored=keep_censored)
    assert fast.covariates == ("velocity_mm_s", "humidity")
    assert fast.muscles == ("M000", "M001", "Müller 7")
    assert fast.l0_mm == {"M000": 250.0, "M001": 400.5, "Müller 7": 100.0}
    assert "note" in fast.frame
    assert (fast.n_censored > 0) != keep_censored


@pytest.mark.parametrize(
    "text",
    [
        BASIC,
        CENSORED,
        "pressure_kPa,contraction_pct,force_N\n100,0,10\n200,5,20\n",  # no muscle column
        csv_rows(  # l0 column, several muscles
            "muscle,pressure_kPa,length_mm,l0_mm,force_N",
            ["A,100,250,250,10", "A,100,200,250,20", "B,100,90,100,30", "A,1e2,2.4e2,2.5e2,1"],
        ),
        csv_rows(  # contraction as a length, with l0
            "muscle,pressure_bar,contraction_mm,l0_mm,force_N",
            ["A,2.505,10,250,10", "B,3.127,5.5,100,20", "A,0,0,250,1"],
        ),
        csv_rows(  # a column that is text because one cell is not a number
            "pressure_psi,contraction_pct,force_N,remark,count",
            ["14.5,1,10,1e,3", "87.0226,2,20,0.5,4", "1,3,30,,5"],
        ),
        # CRLF line ends, a byte order mark, blank lines (and blanks) at the end
        "\ufeffmuscle,pressure_kPa,contraction_pct,force_N\r\nA,100,5,10\r\nB,200,6,20\r\n\r\n",
        "muscle,pressure_kPa,contraction_pct,force_N\nA,100,5,10\nB,200,6,20\n  \n\n",
        # blanks around names and text cells (the slow reader strips them)
        " muscle , pressure_kPa,contraction_pct ,force_N\n A ,100,5,10\nA,200,6,20\n B,1,2,3\n",
        "muscle,pressure_kPa,contraction_pct,force_N,note\nA,100,5,10, x \nA,200,6,20,x\n",
        # a covariate with blanks around its numbers
        "pressure_kPa,contraction_pct,force_N,humidity\n100,5,10, 0.5\n100,5,10,\t7\n",
        # semicolons, tabs, decimal commas (the fast reader reads these too)
        "muscle;pressure_kPa;contraction_pct;force_N\nA;100;5;10\n",
        "muscle;pressure_bar;contraction_pct;force_N;note\nA;1,005;5,5;10;a,b\nB;2;-1,5e-1;3,25;\n",
        "muscle\tpressure_kPa\tcontraction_pct\tforce_N\nA\t100.5\t5\t10\n",
    ],
)
def test_fast_reader_matches_slow_reader_small(tmp_path, monkeypatch, text):
    path = write(tmp_path, text)
    kwargs = {"l0_mm": 250.0} if "l0_mm" not in text and "length_mm" in text else {}
    load_fast_and_slow(monkeypatch, path, **kwargs)


def test_fast_reader_with_l0_argument(tmp_path, monkeypatch):
    text = csv_rows("pressure_kPa,length_mm,force_N", ["100,250,10", "100,225,20", "1,200,0"])
    fast, _ = load_fast_and_slow(monkeypatch, write(tmp_path, text), l0_mm=250)
    assert fast.l0_mm == {"muscle": 250.0}


@pytest.mark.parametrize(
    "text",
    [
        'muscle,pressure_kPa,contraction_pct,force_N\n"A",100,5,10\n',  # quotes
        "\nmuscle,pressure_kPa,contraction_pct,force_N\nA,100,5,10\n",  # blank first line
        "muscle,pressure_kPa,contraction_pct,force_N\nA,100,5,10\n\nA,200,5,10\n",  # blank line
        "muscle,pressure_kPa,contraction_pct,force_N\nA, 100,5,10\n",  # blank in a number
        "muscle,pressure_kPa,contraction_pct,force_N\nA,1_00,5,10\n",  # underscore
        "muscle,pressure_kPa,contraction_pct,force_N\nA,١٠٠,5,10\n",  # Arabic-Indic digits
        "muscle,pressure_kPa,contraction_pct,force_N,\nA,100,5,10,\n",  # trailing commas
        "muscle,pressure_kPa,contraction_pct,force_N\rA,100,5,10\rB,1,2,3\r",  # lone CR
        "muscle,pressure_kPa,contraction_pct,force_N\nA,100,5,10\nA,100,5\n",  # ragged
        "muscle,pressure_kPa,contraction_pct,force_N\nA,100,5,10\n,,,\nA,1,5,10\n",
    ],
)
def test_files_the_fast_reader_leaves_to_the_slow_reader(tmp_path, monkeypatch, text):
    path = write(tmp_path, text)
    assert _csv._read_csv_fast(path, str(path)) is None
    try:
        data = load_bench(path)
    except BenchDataError as err:
        slow = slow_error(monkeypatch, path)
        assert (str(err), err.row, err.line) == (str(slow), slow.row, slow.line)
    else:
        with monkeypatch.context() as patch:
            patch.setattr(_csv, "_FAST_CSV", False)
            assert_same_bench(data, load_bench(path))


def test_latin1_file_is_left_to_the_slow_reader(tmp_path, monkeypatch):
    path = tmp_path / "latin1.csv"
    path.write_bytes(
        "muscle,pressure_kPa,contraction_pct,force_N\nMüller,1,5,10\n".encode("latin-1")
    )
    assert _csv._read_csv_fast(path, str(path)) is None
    assert load_bench(path).muscles == ("Müller",)


def test_censored_rows_warning_points_at_the_caller(tmp_path):
    with pytest.warns(CensoredRowsWarning) as record:
        load_bench(write(tmp_path, CENSORED))
    assert record[0].filename == __file__


@pytest.mark.parametrize(
    ("rows", "kwargs"),
    [
        (["A,100,5,10", "A,-102,5,10"], {}),  # negative absolute pressure
        (["A,100,5,10", "A,100,60,10"], {}),  # contraction out of range
        (["A,100,5,10", "A,100,5,0", "A,100,5,0.0"], {}),  # fine, but...
        (["A,100,5,0", "B,100,5,-0"], {}),  # ...all censored
        (["A,100,5,10", "B,100,5,True"], {}),  # pandas would read True as 1
        (["A,100,5,10", "B,100,5,nan"], {}),
        (["A,100,5,10", ",100,5,10"], {}),  # empty muscle id
        (["A,100,5,10", " ,100,5,10"], {}),  # blank muscle id
    ],
)
def test_fast_reader_errors_match_slow_reader(tmp_path, monkeypatch, rows, kwargs):
    path = write(tmp_path, csv_rows("muscle,pressure_kPa,contraction_pct,force_N", rows))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", CensoredRowsWarning)
            load_bench(path, **kwargs)
    except BenchDataError as err:
        slow = slow_error(monkeypatch, path, **kwargs)
        assert (str(err), err.column, err.row, err.line) == (
            str(slow),
            slow.column,
            slow.row,
            slow.line,
        )
    else:
        load_fast_and_slow(monkeypatch, path, **kwargs)


def test_l0_and_time_checks_name_the_first_offending_row(tmp_path, monkeypatch):
    # Interleaved muscles: the vectorised checks must find the same rows as a loop would.
    rows = ["A,0,100,250,250,10", "B,0,100,90,100,10", "A,1,100,240,250,10", "B,1,100,80,100,1"]
    header = "muscle,time_s,pressure_kPa,length_mm,l0_mm,force_N"
    bad_l0 = [*rows, "B,2,100,80,101,1", "A,2,100,230,260,1"]
    err = raises(write(tmp_path, csv_rows(header, bad_l0)), "constant within a muscle")
    assert (err.column, err.row, err.line) == ("l0_mm", 5, 6)
    assert "101 here but 100 on row 2 for muscle 'B'" in str(err)
    bad_time = [*rows, "A,3,100,230,250,1", "B,1,100,80,100,1", "A,2,100,230,250,1"]
    err = raises(write(tmp_path, csv_rows(header, bad_time)), "not later than 1 s on row 4")
    assert (err.column, err.row, err.line) == ("time_s", 6, 7)
    assert "of muscle 'B'" in str(err)
    assert str(err) == str(slow_error(monkeypatch, tmp_path / "bench.csv"))


@pytest.mark.parametrize(
    ("column", "cell", "message"),
    [
        ("force_N", "abc", "'abc' is not a number"),  # the fast reader leaves the file
        (  # the fast reader reads the file, the check after it finds the problem
            "time_s",
            "0.5",
            "time_s 0.5 s is not later than 49.0 s on row 249999 of muscle 'M0833'; "
            "time must increase strictly within a muscle",
        ),
    ],
)
def test_bad_cell_deep_in_a_large_file(tmp_path, column, cell, message):
    n, bad = 250_200, 250_000  # rows; the bad one, 1-based
    frame = pd.DataFrame(
        {
            "muscle": np.repeat([f"M{i:04d}" for i in range(n // 300 + 1)], 300)[:n],
            "time_s": np.tile(np.arange(300) * 0.5, n // 300 + 1)[:n],
            "pressure_bar": np.tile([1.0, 2.505, 3.127], n // 3),
            "contraction_pct": np.tile(np.round(np.linspace(0.0, 30.0, 300), 2), n // 300 + 1)[:n],
            "force_N": np.tile(np.round(np.linspace(500.0, 10.0, 300), 3), n // 300 + 1)[:n],
        }
    )
    frame[column] = frame[column].astype(str)
    frame.loc[bad - 1, column] = cell
    path = tmp_path / "large.csv"
    frame.to_csv(path, index=False)
    err = raises(path, message)
    assert str(err) == f"{path}, column '{column}', row {bad} (line {bad + 1}): {message}"
    assert (err.column, err.row, err.line) == (column, bad, bad + 1)


def test_fast_pressure_conversion_is_the_exact_text_conversion(tmp_path, monkeypatch):
    rng = np.random.default_rng(7)
    kpa = np.round(rng.uniform(0, 700, 500), 3)
    for unit, factor in (("bar", 100), ("Pa", 1e-3), ("psi", KPA_PER_PSI)):
        cells = [f"{p / factor:.{rng.integers(1, 8)}g}" for p in kpa] + BAR
        rows = [f"{p},5,10" for p in cells]
        path = write(tmp_path, csv_rows(f"pressure_{unit},contraction_pct,force_N", rows))
        fast, _ = load_fast_and_slow(monkeypatch, path)
        got = fast.frame["pressure_kPa"].to_numpy()
        np.testing.assert_array_equal(got, pressure_text_to_kPa(cells, unit))
    rows = [f"{p},5,10" for p in BAR]
    path = write(tmp_path, csv_rows("pressure_bar,contraction_pct,force_N", rows))
    assert load_bench(path).frame["pressure_kPa"].tolist() == [float(p) for p in KPA]


def test_plain_numbers_read_as_python_reads_them():
    # Every cell the fast reader takes as a number is one Python's float() reads, to the same
    # float64: random strings over the characters it accepts, and some chosen ones.
    pa = pytest.importorskip("pyarrow")
    rng = np.random.default_rng(3)
    alphabet = np.array(list("0123456789+-.eE"))
    cells = ["".join(rng.choice(alphabet, size=rng.integers(1, 12))) for _ in range(6_000)]
    digits = np.array(list("0123456789"))
    for _ in range(3_000):  # well-formed numbers, long mantissas, extreme exponents
        mantissa = "".join(rng.choice(digits, size=rng.integers(1, 40)))
        point = int(rng.integers(0, len(mantissa) + 1))
        exponent = int(rng.integers(-340, 320))
        sign = str(rng.choice(["", "-", "+"]))
        cells.append(f"{sign}{mantissa[:point]}.{mantissa[point:]}e{exponent}")
    cells += ["1.", ".5", "+.5e-3", "-0", "0e0", "1e", "e1", ".", "+", "1e+", "--1", "1.2.3"]
    cells += ["0.1000000000000000055511151231257827021181583404541015625", "9007199254740993"]
    cells += ["2.4703282292062328e-324", "1.7976931348623158e308", "1.7976931348623159e308"]
    taken = 0
    for cell in cells:
        values = _csv._plain_numbers(pa.chunked_array([pa.array([cell], pa.string())]))
        if values is None:
            continue
        taken += 1
        expected = float(cell)
        assert "_" not in cell and np.isfinite(expected)
        assert values[0] == expected and np.signbit(values[0]) == np.signbit(expected), cell
    assert taken > 3_000
    # one column, several chunks
    column = pa.chunked_array([pa.array(["1", "2.5"]), pa.array(["-3e2"])])
    assert _csv._plain_numbers(column).tolist() == [1.0, 2.5, -300.0]
    assert _csv._plain_numbers(pa.chunked_array([pa.array(["1", " 2"])])) is None


# ----------------------------------------------------------------------------------------
# Atomic output writers
# ----------------------------------------------------------------------------------------


def test_write_text_atomic_creates_parents_and_replaces(tmp_path):
    path = tmp_path / "a" / "b" / "report.txt"
    write_text_atomic(path, "first\n")
    assert path.read_text() == "first\n"
    write_text_atomic(path, "second\n")
    assert path.read_text() == "second\n"
    assert os.listdir(path.parent) == ["report.txt"]


def test_write_bytes_atomic(tmp_path):
    path = write_bytes_atomic(tmp_path / "blob.bin", b"\x00\x01\x02")
    assert path.read_bytes() == b"\x00\x01\x02"


def test_failed_write_leaves_nothing_behind(tmp_path):
    def half_then_fail(tmp: str) -> None:
        with open(tmp, "w") as fh:
            fh.write("partial")
        raise RuntimeError("disk on fire")

    target = tmp_path / "out" / "result.csv"
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_atomic(target, half_then_fail)
    assert not target.exists()
    assert os.listdir(target.parent) == []

    target.write_text("old content")
    with pytest.raises(RuntimeError):
        write_atomic(target, half_then_fail)
    assert target.read_text() == "old content"
    assert os.listdir(target.parent) == ["result.csv"]


def test_new_file_permissions_follow_umask(tmp_path):
    old = os.umask(0o022)
    try:
        path = write_text_atomic(tmp_path / "p.txt", "x")
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o644


def test_write_frame_atomic_csv_and_parquet(tmp_path):
    frame = pd.DataFrame({"a": [1.0, 0.1 + 0.2], "b": ["x", "y"]})
    for name in ("f.csv", "f.parquet", "f.pq"):
        path = write_frame_atomic(tmp_path / name, frame)
        back = pd.read_csv(path) if name.endswith(".csv") else pd.read_parquet(path)
        assert back["a"].tolist() == frame["a"].tolist()
        assert back["b"].tolist() == ["x", "y"]


def test_save_figure_atomic(tmp_path):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 2))
    fig.add_subplot().plot([0, 1], [0, 1])
    path = save_figure_atomic(fig, tmp_path / "figs" / "fit.png", dpi=50)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    with pytest.raises(ValueError):
        save_figure_atomic(fig, tmp_path / "figs" / "bad.nosuchformat")
    assert os.listdir(tmp_path / "figs") == ["fit.png"]


def test_refuse_overwrite_input(tmp_path):
    inp = write(tmp_path, BASIC)
    with pytest.raises(ValueError, match="refusing to write .*input file"):
        refuse_overwrite_input(inp, [inp])
    with pytest.raises(ValueError, match="refusing"):
        refuse_overwrite_input(tmp_path / "sub" / ".." / "bench.csv", [str(inp)])
    link = tmp_path / "link.csv"
    link.symlink_to(inp)
    with pytest.raises(ValueError, match="refusing"):
        refuse_overwrite_input(link, [inp])
    hard = tmp_path / "hard.csv"
    os.link(inp, hard)
    with pytest.raises(ValueError, match="refusing"):
        refuse_overwrite_input(hard, [inp])
    refuse_overwrite_input(tmp_path / "out.csv", [inp, tmp_path / "missing.csv"])
