"""Bench files as real labs write them: trials, blank cells, semicolons and decimal commas,
tabs, spreadsheets, headers with units in brackets, and column mappings (pamid._data._bench,
pamid._data._csv, pamid._data._names, pamid._data._spreadsheet, pamid._commands._reading)."""

from __future__ import annotations

import datetime as dt
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_bench_data import csv_rows, load_fast_and_slow, raises, slow_error, write

from pamid._data import _cells, _csv
from pamid._data._bench import MissingValuesWarning, load_bench
from pamid._errors import BenchDataError

AARL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / (
    "aarl_festo10mm_isometric.csv"
)


def quiet_load(path, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MissingValuesWarning)
        return load_bench(path, **kwargs)


# ----------------------------------------------------------------------------------------
# Trials
# ----------------------------------------------------------------------------------------

TRIALS = csv_rows(
    "muscle,trial,time_s,pressure_kPa,contraction_pct,force_N",
    [
        "A,Unkink_T8,0.0,100,0,10",
        "A,Unkink_T8,0.5,200,0,20",
        "A,kinked25_T9,0.0,100,5,8",
        "A,kinked25_T9,0.5,200,5,16",
        "B,Unkink_T8,0.0,100,0,11",
        "B,Unkink_T8,0.25,200,0,21",
        "B,kinked25_T9,0.0,100,5,9",
    ],
)


def test_trials_time_restarts_and_labels_repeat_across_muscles(tmp_path, monkeypatch):
    fast, _ = load_fast_and_slow(monkeypatch, write(tmp_path, TRIALS))
    frame = fast.frame
    assert list(frame.columns[:3]) == ["muscle", "trial", "pressure_kPa"]
    assert frame["trial"].tolist() == ["Unkink_T8", "Unkink_T8", "kinked25_T9", "kinked25_T9",
                                       "Unkink_T8", "Unkink_T8", "kinked25_T9"]
    assert frame["trial"].dtype == frame["muscle"].dtype
    assert frame["time_s"].tolist() == [0.0, 0.5, 0.0, 0.5, 0.0, 0.25, 0.0]
    assert fast.muscles == ("A", "B")


def test_numeric_trial_labels_stay_text(tmp_path, monkeypatch):
    text = csv_rows("trial,time_s,pressure_kPa,contraction_pct,force_N",
                    ["1,0,100,0,10", "1,1,200,0,20", "02,0,100,5,8", "2,0,100,5,8"])
    fast, _ = load_fast_and_slow(monkeypatch, write(tmp_path, text))
    assert fast.frame["trial"].tolist() == ["1", "1", "02", "2"]
    assert fast.covariates == ()


def test_time_going_backwards_inside_a_trial_names_the_trial(tmp_path, monkeypatch):
    rows = TRIALS.splitlines()
    rows.insert(5, "A,kinked25_T9,0.4,300,5,20")  # after 0.5 s of the same trial
    path = write(tmp_path, "\n".join(rows) + "\n")
    err = raises(path, r"time_s 0\.4 s is not later than 0\.5 s on row 4 of muscle 'A', "
                       r"trial 'kinked25_T9'; time must increase strictly within a trial")
    assert (err.column, err.row, err.line) == ("time_s", 5, 6)
    assert str(err) == str(slow_error(monkeypatch, path))


def test_time_going_backwards_without_a_muscle_column(tmp_path):
    text = csv_rows("run,time_s,pressure_kPa,contraction_pct,force_N",
                    ["r1,0,100,0,10", "r2,0,100,0,10", "r2,0,200,0,10"])
    err = raises(write(tmp_path, text), "on row 2 of trial 'r2'; time must increase")
    assert (err.column, err.row) == ("time_s", 3)


@pytest.mark.parametrize("header", ["trial", "Trial", "test", "TEST", "run", "Run"])
def test_trial_column_aliases(tmp_path, header):
    text = csv_rows(f"muscle,{header},time_s,pressure_kPa,contraction_pct,force_N",
                    ["A,a,0,100,0,10", "A,b,0,100,0,10"])
    data = load_bench(write(tmp_path, text))
    assert data.frame["trial"].tolist() == ["a", "b"]
    assert header.lower() == "trial" or header not in data.frame


def test_two_trial_columns_are_an_error(tmp_path):
    text = csv_rows("trial,run,pressure_kPa,contraction_pct,force_N", ["a,1,100,0,10"])
    err = raises(write(tmp_path, text), "columns 'trial' and 'run' both give trial")
    assert err.column == "run"


def test_empty_trial_label(tmp_path):
    text = csv_rows("trial,pressure_kPa,contraction_pct,force_N", ["a,100,0,10", ",100,0,10"])
    err = raises(write(tmp_path, text), "empty trial label")
    assert (err.column, err.row) == ("trial", 2)


@pytest.mark.skipif(not AARL.exists(), reason="the AARL measurements are not here")
def test_real_lab_file_with_trials():
    data = load_bench(AARL)
    frame = data.frame
    assert len(frame) == 61_515
    assert len(data.muscles) == 6
    per_muscle = frame.groupby("muscle", sort=False)["trial"].unique()
    assert [len(trials) for trials in per_muscle] == [12] * 6
    assert all(list(t) == list(per_muscle.iloc[0]) for t in per_muscle)  # same labels
    for _, rows in data.groups():  # time restarts in every trial, and only there
        restarts = np.flatnonzero(np.diff(rows["time_s"].to_numpy()) < 0) + 1
        changes = np.flatnonzero(rows["trial"].to_numpy()[1:] != rows["trial"].to_numpy()[:-1])
        np.testing.assert_array_equal(restarts, changes + 1)
        assert len(restarts) == 11


# ----------------------------------------------------------------------------------------
# Blank optional cells
# ----------------------------------------------------------------------------------------

BLANKS = csv_rows(
    "muscle,time_s,pressure_kPa,contraction_pct,force_N,direction,temperature_C,cycle,flow",
    [
        "A,0,100,0,10,1,21.5,1,0.5",
        "A,1,200,1,20,1,,1,0.6",
        "A,,200,2,25,-1,21.7,,",
        "B,0,100,0,11,,22,1,0.5",
        "B,2,200,1,21,,22,1,0.7",
        "B,3,300,2,31,,22,2,0.8",
    ],
)


def test_blank_optional_cells_are_not_recorded(tmp_path, monkeypatch):
    path = write(tmp_path, BLANKS)
    fast, _ = load_fast_and_slow(monkeypatch, path)
    frame = fast.frame
    assert frame["direction"].dtype == np.float64
    np.testing.assert_array_equal(frame["direction"], [1, 1, -1, np.nan, np.nan, np.nan])
    np.testing.assert_array_equal(frame["time_s"], [0, 1, np.nan, 0, 2, 3])
    np.testing.assert_array_equal(frame["temperature_C"], [21.5, np.nan, 21.7, 22, 22, 22])
    np.testing.assert_array_equal(frame["cycle"], [1, 1, np.nan, 1, 1, 2])
    np.testing.assert_array_equal(frame["flow"], [0.5, 0.6, np.nan, 0.5, 0.7, 0.8])
    assert fast.covariates == ("flow",)
    with pytest.warns(MissingValuesWarning) as record:
        load_bench(path)
    assert len(record) == 1
    assert record[0].message.counts == {
        "time_s": 1, "direction": 3, "temperature_C": 1, "cycle": 1, "flow": 1
    }
    assert str(record[0].message) == (
        f"{path}: 1 blank cell in time_s (row 3, muscle 'A') and 3 in direction (rows 4-6, "
        "muscle 'B') and 1 in temperature_C (row 2, muscle 'A') and 1 in cycle (row 3, "
        "muscle 'A') and 1 in flow (row 3, muscle 'A'): treated as not recorded; direction "
        "is derived from the data there"
    )


def test_blank_direction_message_as_the_brief_words_it(tmp_path):
    rows = ["A,100,0,10,1"] * 2 + ["B,100,0,10,"] * 1200
    path = write(tmp_path, csv_rows("muscle,pressure_kPa,contraction_pct,force_N,direction",
                                    rows), name="file.csv")
    with pytest.warns(MissingValuesWarning) as record:
        data = load_bench(path)
    assert str(record[0].message) == (
        f"{path}: 1,200 blank cells in direction (rows 3-1202, muscle 'B'): treated as not "
        "recorded; direction is derived from the data there"
    )
    assert data.frame["direction"].isna().sum() == 1200
    assert issubclass(MissingValuesWarning, UserWarning)


def test_no_warning_and_whole_numbers_without_blanks(tmp_path):
    text = csv_rows("pressure_kPa,contraction_pct,force_N,direction,cycle", ["100,0,10,1,3"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data = load_bench(write(tmp_path, text))
    assert data.frame["direction"].dtype == np.int64
    assert data.frame["cycle"].dtype == np.int64


def test_time_check_skips_blank_times(tmp_path):
    ok = csv_rows("time_s,pressure_kPa,contraction_pct,force_N",
                  ["0,100,0,10", ",100,0,10", "1,100,0,10"])
    assert len(quiet_load(write(tmp_path, ok))) == 3
    bad = csv_rows("time_s,pressure_kPa,contraction_pct,force_N",
                   ["1,100,0,10", ",100,0,10", "0.5,100,0,10"])
    with pytest.raises(BenchDataError, match=r"0\.5 s is not later than 1 s on row 1") as info:
        quiet_load(write(tmp_path, bad))
    assert (info.value.column, info.value.row) == ("time_s", 3)


@pytest.mark.parametrize(
    ("column", "cells"),
    [("force_N", ["10", ""]), ("pressure_kPa", ["100", ""]), ("contraction_pct", ["", "1"]),
     ("muscle", ["A", ""])],
)
def test_blank_required_cells_stay_errors(tmp_path, monkeypatch, column, cells):
    frame = pd.DataFrame({"muscle": ["A", "A"], "pressure_kPa": ["100", "200"],
                          "contraction_pct": ["0", "1"], "force_N": ["10", "20"],
                          "direction": ["", "1"]})
    frame[column] = cells
    path = tmp_path / "bench.csv"
    frame.to_csv(path, index=False)
    row = cells.index("") + 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MissingValuesWarning)
        err = raises(path, "empty muscle id" if column == "muscle" else "empty cell")
    assert (err.column, err.row, err.line) == (column, row, row + 1)
    assert str(err) == str(slow_error(monkeypatch, path))


def test_nan_written_out_stays_an_error(tmp_path):
    text = csv_rows("pressure_kPa,contraction_pct,force_N,direction", ["100,0,10,", "1,1,1,nan"])
    err = raises(write(tmp_path, text), "'nan' is NaN")
    assert (err.column, err.row) == ("direction", 2)


def test_optional_column_blank_for_a_whole_muscle(tmp_path):
    text = csv_rows("muscle,time_s,pressure_kPa,contraction_pct,force_N,temperature_C",
                    ["A,0,100,0,10,20", "A,1,100,1,10,21", "B,,100,0,10,", "B,,100,1,10,"])
    with pytest.warns(MissingValuesWarning, match=r"2 blank cells in time_s \(rows 3-4, "
                                                  r"muscle 'B'\) and 2 in temperature_C"):
        data = load_bench(write(tmp_path, text))
    assert data.for_muscle("B")["time_s"].isna().all()


def test_parquet_nulls_in_optional_columns(tmp_path):
    frame = pd.DataFrame({"pressure_kPa": [100.0, 200.0], "contraction_pct": [0.0, 1.0],
                          "force_N": [10.0, 20.0], "direction": [1.0, None],
                          "temperature_C": [None, 20.0]})
    path = tmp_path / "bench.parquet"
    frame.to_parquet(path)
    with pytest.warns(MissingValuesWarning, match="1 blank cell in direction"):
        data = load_bench(path)
    np.testing.assert_array_equal(data.frame["direction"], [1.0, np.nan])
    frame["force_N"] = [10.0, None]
    frame.to_parquet(path)
    err = raises(path, "missing value")
    assert (err.column, err.row) == ("force_N", 2)


# ----------------------------------------------------------------------------------------
# Semicolons, decimal commas, tabs
# ----------------------------------------------------------------------------------------

EXCEL_DE = (
    "muscle;pressure_bar;contraction_pct;force_N;note\n"
    "A;2,505;5,5;499,911;Versuch 1, neu\n"
    "A;3;-1,5E-1;12;\n"
    "B;0,5;10;7,25;x.y\n"
)


def test_semicolon_and_decimal_comma_detected(tmp_path, monkeypatch):
    fast, _ = load_fast_and_slow(monkeypatch, write(tmp_path, EXCEL_DE))
    frame = fast.frame
    assert frame["pressure_kPa"].tolist() == [250.5, 300.0, 50.0]
    assert frame["contraction_pct"].tolist() == [5.5, -0.15, 10.0]
    assert frame["force_N"].tolist() == [499.911, 12.0, 7.25]
    assert frame["note"].tolist() == ["Versuch 1, neu", "", "x.y"]  # text as written


def test_sep_and_decimal_overrides(tmp_path):
    path = write(tmp_path, EXCEL_DE)
    same = load_bench(path, sep=";", decimal=",")
    pd.testing.assert_frame_equal(same.frame, load_bench(path).frame)
    pd.testing.assert_frame_equal(load_bench(path, decimal=",").frame, same.frame)
    err = raises(path, r"'2,505' is not a number", decimal=".")
    assert (err.column, err.row, err.line) == ("pressure_bar", 1, 2)
    # a semicolon file with decimal points, and one forced to read commas
    text = EXCEL_DE.replace(",", ".").replace("Versuch 1. neu", "v1")
    data = load_bench(write(tmp_path, text))
    assert data.frame["force_N"].tolist() == [499.911, 12.0, 7.25]
    err = raises(write(tmp_path, text), "not a number with the decimal mark ','", decimal=",")
    assert (err.column, err.row) == ("pressure_bar", 1)


def test_point_in_a_decimal_comma_file_is_an_error(tmp_path):
    text = EXCEL_DE.replace("7,25", "7.25")
    err = raises(write(tmp_path, text), r"'7\.25' is not a number with the decimal mark ','")
    assert (err.column, err.row, err.line) == ("force_N", 3, 4)


def test_tab_separated(tmp_path, monkeypatch):
    text = EXCEL_DE.replace(";", "\t")
    fast, _ = load_fast_and_slow(monkeypatch, write(tmp_path, text, "bench.tsv"))
    assert fast.frame["force_N"].tolist() == [499.911, 12.0, 7.25]
    again = load_bench(tmp_path / "bench.tsv", sep="tab", decimal=",")
    pd.testing.assert_frame_equal(again.frame, fast.frame)
    err = raises(write(tmp_path, text.replace("12", "zwölf"), "bad.tsv"), "'zwölf' is not")
    assert (err.column, err.row, err.line) == ("force_N", 2, 3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"sep": "ab"}, "sep must be one character"), ({"decimal": ";"}, "decimal must be"),
     ({"sep": ",", "decimal": ","}, "must differ"), ({"sheet": "Data"}, "spreadsheets")],
)
def test_bad_reading_options(tmp_path, kwargs, match):
    raises(write(tmp_path, EXCEL_DE), match, **kwargs)


# ----------------------------------------------------------------------------------------
# Headers as labs write them, and explicit mappings
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("headers", "canonical"),
    [
        ("Pressure [kPa],force (N),Contraction [%]", "pressure_kPa,force_N,contraction_pct"),
        ("p / bar,F [N],kappa [%]", "pressure_bar,force_N,contraction_pct"),
        ("P (psi),Force_N,κ (%)", "pressure_psi,force_N,contraction_pct"),
        ("p_kPa,F_N,Length [mm],L0 [mm]", "pressure_kPa,force_N,length_mm,l0_mm"),
        ("Pressure [Pa],Force [N],Contraction [mm]", "pressure_Pa,force_N,contraction_mm"),
        ("Muscle,Time [s],Temperature [°C],p [kPa],F [N],l [mm],l0_mm",
         "muscle,time_s,temperature_C,pressure_kPa,force_N,length_mm,l0_mm"),
        ("t [s],T [°C],p [kPa],F [N],κ [%],T_ambient",
         "time_s,temperature_C,pressure_kPa,force_N,contraction_pct,T_ambient"),
        ("t_s,T_C,p_kPa,F_N,contraction_pct,t_ambient,Velocity [mm/s]",
         "time_s,temperature_C,pressure_kPa,force_N,contraction_pct,t_ambient,velocity_mm_s"),
        ("p [kPa],F [N],κ [%],direction [-],Cycle (#),Test",
         "pressure_kPa,force_N,contraction_pct,direction,cycle,trial"),
    ],
)
def test_header_styles(tmp_path, headers, canonical):
    from pamid._data._names import canonical_names

    assert canonical_names(headers.split(","), _cells.QUANTITY_UNITS) == canonical.split(",")
    cells = {"muscle": "A", "length_mm": "240", "l0_mm": "250", "force_N": "12.5"}
    row = ",".join(cells.get(name, "1") for name in canonical.split(","))
    data = load_bench(write(tmp_path, f"{headers}\n{row}\n"))
    assert data.frame.loc[0, "force_N"] == 12.5
    assert "pressure_kPa" in data.frame
    assert ("contraction_pct" in data.frame) or ("contraction_mm" in data.frame)


def test_time_and_temperature_symbols_differ(tmp_path):
    data = load_bench(write(tmp_path, "t [s],T [°C],p [kPa],F [N],κ [%]\n2,21.5,100,10,5\n"))
    assert (data.frame.loc[0, "time_s"], data.frame.loc[0, "temperature_C"]) == (2.0, 21.5)


@pytest.mark.parametrize(
    ("header", "match"),
    [
        ("Force [kN]", "unknown unit 'kN' for force; accepted units: N"),
        ("Time [ms]", "unknown unit 'ms' for time; accepted units: s"),
        ("T [s]", "unknown unit 's' for temperature"),
        ("p / atm", "unknown unit 'atm' for pressure"),
        ("Pressure [kpa]", "units are case-sensitive: name the column pressure_kPa"),
    ],
)
def test_unknown_units_in_any_style_name_the_column(tmp_path, header, match):
    base = {"Force [kN]": "pressure_kPa,contraction_pct", "p / atm": "force_N,contraction_pct",
            "Pressure [kpa]": "force_N,contraction_pct"}.get(header,
                                                              "pressure_kPa,force_N,contraction_pct")
    n = len(base.split(",")) + 1
    err = raises(write(tmp_path, f"{base},{header}\n" + ",".join(["1"] * n) + "\n"), match)
    assert err.column == header
    assert f"column '{header}'" in str(err)


def test_two_headers_for_one_quantity(tmp_path):
    text = "pressure_kPa,Force [N],force_N,contraction_pct\n1,2,3,4\n"
    err = raises(write(tmp_path, text), "columns 'Force \\[N\\]' and 'force_N' both give force_N")
    assert err.column == "force_N"


def test_column_mapping(tmp_path, monkeypatch):
    text = "Zeit;Druck;Kraft;Kontraktion;Kommentar\n0;2,5;100,5;10;gut\n1;3;90;12;\n"
    path = write(tmp_path, text)
    mapping = {"Druck": "pressure_bar", "Kraft": "force_N", "Kontraktion": "Contraction [%]",
               "Zeit": "time_s"}
    fast, _ = load_fast_and_slow(monkeypatch, path, columns=mapping)
    assert fast.frame["pressure_kPa"].tolist() == [250.0, 300.0]
    assert fast.frame["force_N"].tolist() == [100.5, 90.0]
    assert fast.frame["Kommentar"].tolist() == ["gut", ""]
    err = raises(path, "the column mapping names 'Kraf', which the file does not have. "
                       "Columns found: Zeit, Druck", columns={**mapping, "Kraf": "force_N"})
    assert err.column == "Kraf"


def test_errors_name_the_column_as_the_file_writes_it(tmp_path, monkeypatch):
    text = "Pressure [kPa],Force (N),Contraction [%]\n100,10,5\n100,abc,5\n"
    path = write(tmp_path, text)
    err = raises(path, "'abc' is not a number")
    assert (err.column, err.row, err.line) == ("Force (N)", 2, 3)
    missing = raises(write(tmp_path, "Pressure [kPa],Contraction [%]\n1,2\n"),
                     r"missing required column: force_N\. Columns found: Pressure \[kPa\], "
                     r"Contraction \[%\]")
    assert missing.column == "force_N"


# ----------------------------------------------------------------------------------------
# Spreadsheets
# ----------------------------------------------------------------------------------------


def write_xlsx(path: Path, sheets: dict[str, list[list]]) -> Path:
    from openpyxl import Workbook

    workbook = Workbook()
    workbook.remove(workbook.active)
    for name, rows in sheets.items():
        sheet = workbook.create_sheet(name)
        for row in rows:
            sheet.append(row)
    workbook.save(path)
    return path


SHEET = [
    ["Muscle", "Run", "Time [s]", "Pressure [bar]", "Force (N)", "Contraction [%]",
     "direction", "note"],
    ["A", 1, 0.0, 2.505, 100.5, 5, 1, "first"],
    ["A", 1, 0.5, 3, 90, 6, None, None],
    ["B", 2, 0.0, 0.5, 10.25, 7.5, -1, dt.datetime(2026, 11, 24, 9, 30)],
]


def test_xlsx_numbers_text_and_blanks(tmp_path):
    path = write_xlsx(tmp_path / "bench.xlsx", {"Data": SHEET})
    with pytest.warns(MissingValuesWarning, match=r"1 blank cell in direction \(row 2, muscle"):
        data = load_bench(path)
    frame = data.frame
    assert data.muscles == ("A", "B")
    assert frame["trial"].tolist() == ["1", "1", "2"]
    assert frame["pressure_kPa"].tolist() == [250.5, 300.0, 50.0]  # as exact as from text
    assert frame["force_N"].tolist() == [100.5, 90.0, 10.25]
    np.testing.assert_array_equal(frame["direction"], [1.0, np.nan, -1.0])
    assert frame["note"].tolist() == ["first", "", "2026-11-24 09:30:00"]
    # the same table as CSV gives the same frame
    csv = write(tmp_path, "\n".join(",".join("" if c is None else str(c) for c in row)
                                     for row in SHEET[:3]) + "\n")
    pd.testing.assert_frame_equal(quiet_load(csv).frame.drop(columns="note"),
                                  frame.iloc[:2].drop(columns="note"), check_dtype=False)


def test_xlsx_first_sheet_by_default_and_sheet_by_name(tmp_path):
    path = write_xlsx(tmp_path / "two.xlsx",
                      {"Data": SHEET[:2], "Other": [["pressure_kPa", "force_N",
                                                     "contraction_pct"], [1, 2, 3]]})
    assert load_bench(path).muscles == ("A",)
    assert load_bench(path, sheet="Other").frame["force_N"].tolist() == [2.0]
    err = raises(path, "no sheet named 'Nope'; the sheets are 'Data', 'Other'", sheet="Nope")
    assert err.sheet is None
    raises(path, "sep=';' .* applies to CSV files only", sep=";")


def test_xlsx_errors_name_sheet_and_cell(tmp_path):
    rows = [list(row) for row in SHEET]
    rows[3][4] = "n/a"
    path = write_xlsx(tmp_path / "bad.xlsx", {"Data": rows})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MissingValuesWarning)
        err = raises(path, "'n/a' is not a number")
    assert str(err) == (f"{path}, column 'Force (N)', row 3 (sheet 'Data', cell E4): "
                        "'n/a' is not a number")
    assert (err.sheet, err.cell, err.row) == ("Data", "E4", 3)


def test_xlsx_table_away_from_a1_and_blank_rows(tmp_path):
    from openpyxl import Workbook

    workbook = Workbook()
    sheet = workbook.active
    sheet.title = "Messung"
    for j, name in enumerate(["pressure_kPa", "force_N", "contraction_pct"]):
        sheet.cell(row=3, column=2 + j, value=name)
    sheet.cell(row=4, column=2, value=100)
    sheet.cell(row=4, column=3, value=10)
    sheet.cell(row=4, column=4, value=5)
    sheet.cell(row=6, column=2, value=100)  # row 5 is blank
    sheet.cell(row=6, column=3, value=10)
    sheet.cell(row=6, column=4, value=70)
    path = tmp_path / "away.xlsx"
    workbook.save(path)
    err = raises(path, "outside the physical range")
    assert (err.column, err.row, err.cell, err.sheet) == ("contraction_pct", 2, "D6", "Messung")


def test_xlsx_date_in_a_numeric_column(tmp_path):
    rows = [list(row) for row in SHEET[:3]]
    rows[2][2] = dt.time(0, 0, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MissingValuesWarning)
        err = raises(write_xlsx(tmp_path / "dates.xlsx", {"Data": rows}),
                     r"a date/time cell \(00:00:01\), not a number; write the time as seconds")
    assert (err.column, err.cell) == ("Time [s]", "C3")


def test_not_a_spreadsheet(tmp_path):
    path = tmp_path / "fake.xlsx"
    path.write_text("pressure_kPa,force_N\n1,2\n")
    raises(path, "cannot read it as a spreadsheet")


# ----------------------------------------------------------------------------------------
# Errors name file, column and row in every format
# ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["csv", "semicolon", "tab", "parquet", "xlsx"])
def test_each_format_names_file_column_and_row(tmp_path, fmt):
    frame = pd.DataFrame({"pressure_kPa": [100.0, 200.0, 300.0],
                          "contraction_pct": [1.0, 2.0, 60.0], "force_N": [1.0, 2.0, 3.0]})
    if fmt == "parquet":
        path = tmp_path / "bench.parquet"
        frame.to_parquet(path)
    elif fmt == "xlsx":
        path = write_xlsx(tmp_path / "bench.xlsx",
                          {"Bench": [list(frame.columns), *frame.values.tolist()]})
    else:
        sep = {"csv": ",", "semicolon": ";", "tab": "\t"}[fmt]
        path = tmp_path / "bench.csv"
        frame.to_csv(path, sep=sep, index=False, decimal="," if fmt == "semicolon" else ".")
    err = raises(path, "contraction 60([.,]0)? % is outside the physical range")
    assert (err.path, err.column, err.row) == (str(path), "contraction_pct", 3)
    assert str(err).startswith(f"{path}, column 'contraction_pct', row 3")
    if fmt == "xlsx":
        assert "(sheet 'Bench', cell B4)" in str(err)
    elif fmt != "parquet":
        assert err.line == 4


# ----------------------------------------------------------------------------------------
# Command line
# ----------------------------------------------------------------------------------------


def test_cli_fit_reads_a_german_excel_csv(tmp_path, pamid_cli):
    import jax

    import pamid

    frame = pamid.simulate_sarosi_bench(
        jax.random.key(3), pamid.sarosi.table_3_1(),
        pamid.SarosiProtocol(min_force_N=10.0, pressures_kPa=(200.0, 400.0, 600.0)),
    )
    german = pd.DataFrame({"Druck": frame["pressure_kPa"] / 100.0,
                           "Kraft": frame["force_N"],
                           "Kontraktion": frame["contraction_pct"]})
    path = tmp_path / "messung.csv"
    german.to_csv(path, sep=";", decimal=",", index=False)
    assert "," in path.read_text().splitlines()[1]
    args = ["fit", str(path), "--json", "--intervals", "wald",
            "--columns", "Druck=pressure_bar,Kraft=force_N,Kontraktion=contraction_pct"]
    res = pamid_cli(args + ["--sep", ";", "--decimal", ","])
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["muscles"][0]["n"] == len(frame)
    assert out["muscles"][0]["converged"]

    res = pamid_cli(["fit", str(path), "--json", "--columns", "Druck=pressure_bar,Kraf=force_N"])
    assert res.returncode == 2
    assert "Traceback" not in res.stderr
    assert f"{path}, column 'Kraf': the column mapping names 'Kraf'" in res.stderr
    res = pamid_cli(["fit", str(path), "--columns", "Druck"])
    assert res.returncode == 2 and "HEADER=NAME" in res.stderr


def test_cli_reading_options_for_fit_and_diagnose():
    from pamid._cli import _parser
    from pamid._commands._reading import reading_options

    for command in ("fit", "diagnose"):
        args = _parser().parse_args([command, "bench.xlsx", "--sheet", "Data", "--sep", "tab",
                                     "--decimal", ",", "--columns", "Druck=pressure_bar",
                                     "--l0-mm", "250", "--keep-censored", "--header-row", "4"])
        assert reading_options(args) == {
            "l0_mm": 250.0, "keep_censored": True, "sep": "tab", "decimal": ",",
            "sheet": "Data", "header_row": 4, "columns": {"Druck": "pressure_bar"},
        }


def test_cli_diagnose_passes_the_reading_options(tmp_path, pamid_cli):
    path = write(tmp_path, "Druck,Kraft,contraction_pct\n1,10,5\n")
    res = pamid_cli(["diagnose", str(path), "--json", "--columns",
                     "Druck=pressure_bar,Kraf=force_N"])
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    assert "the column mapping names 'Kraf'" in res.stderr


def test_fast_reader_reads_semicolon_files(tmp_path):
    path = write(tmp_path, EXCEL_DE)
    table = _csv._read_csv_fast(path, str(path))
    assert table is not None and table.n_rows == 3
    assert _csv._read_csv_fast(write(tmp_path, EXCEL_DE.replace("A;", '"A";')), "q") is None


# ----------------------------------------------------------------------------------------
# A lab's workbook as labs keep it: one sheet per muscle, notes and the resting length
# above the header, "Inflated length | strain | Pressure | Force | P/DP"
# ----------------------------------------------------------------------------------------

def raises_text(path, text, **kwargs) -> BenchDataError:
    """:func:`raises` for a message given as plain text (no pattern)."""
    return raises(path, re.escape(text), **kwargs)


LAB_COLUMNS = {"Inflated length": "length_mm", "Pressure": "pressure_kPa", "Force": "force_N",
               "resting length": "l0_mm"}
LAB_MAP = "Inflated length=length_mm,Pressure=pressure_kPa,Force=force_N,resting length=l0_mm"


def _lab_rows(rng, l0_mm: float) -> list[list]:
    """A hand-logged isometric map of one muscle: three lengths, the pressure stepped up
    (P/DP = 1) and down (P/DP = 0) at each, logged with noise; forces from Sárosi's eq. 2.1
    with Table 3-1's constants."""
    from pamid.sarosi import TABLE_3_1

    a1, a2, a3, a4, a5, a6 = (TABLE_3_1[f"a{k}"]["value"] for k in range(1, 7))
    up = np.arange(150.0, 601.0, 50.0)
    rows = []
    for kappa in (4.0, 9.0, 14.0):
        for flag, pressures in ((1, up), (0, up[::-1])):
            for p_set in pressures:
                p = p_set + rng.normal(0.0, 3.0)
                k = kappa + rng.normal(0.0, 0.15)
                bar = p / 100.0
                force = ((a1 * bar + a2) * np.exp(a3 * k) + a4 * k * bar + a5 * bar + a6
                         + rng.normal(0.0, 4.0))
                rows.append([round(l0_mm * (1 - k / 100), 1), round(k / 100, 4), round(p, 1),
                             round(float(force), 1), flag])
    return rows


def write_lab_workbook(path: Path, lengths=(300, 250), notes_sheet: bool = False) -> Path:
    """Sheets named like ``300mm``: a note in row 1, "resting length | 300 | mm" in row 2,
    a blank row, the header in row 4 and the data from row 5."""
    rng = np.random.default_rng(7)
    sheets = {}
    for l0 in lengths:
        sheets[f"{l0}mm"] = [
            [f"Festo tube cut to {l0} mm, logged by hand on 2024-03-01", None, None],
            ["resting length", l0, "mm"],
            [None],
            ["Inflated length", "strain", "Pressure", "Force", "P/DP"],
            *_lab_rows(rng, float(l0)),
        ]
    if notes_sheet:
        sheets["Notes"] = [["Pressure sensor: SPTE, zeroed daily"], ["Operator: A. B."]]
    return write_xlsx(path, sheets)


def test_lab_workbook_header_found_below_notes(tmp_path):
    """Was: "the header has no name in cell B1" (the note in row 1 taken as the header)."""
    path = write_lab_workbook(tmp_path / "lab.xlsx")
    data = load_bench(path, sheet="300mm", columns=LAB_COLUMNS)
    frame = data.frame
    assert len(frame) == 60 and data.l0_mm == {"muscle": 300.0}
    assert frame["source_row"].iloc[0] == 1
    np.testing.assert_allclose(frame["contraction_pct"],
                               100 * (300 - frame["length_mm"]) / 300)
    assert frame["strain"].iloc[0] == pytest.approx(frame["contraction_pct"].iloc[0] / 100,
                                                    abs=2e-3)
    # errors name the cell below the header (row 4), not row 1
    err = raises_text(write_lab_workbook(tmp_path / "unmapped.xlsx"), "no unit in the column name",
                 sheet="300mm")
    assert (err.sheet, err.column) == ("300mm", "Pressure")
    assert "--columns 'Pressure=pressure_kPa'" in str(err)


def test_lab_workbook_header_row_option(tmp_path):
    path = write_lab_workbook(tmp_path / "lab.xlsx")
    auto = load_bench(path, sheet="250mm", columns=LAB_COLUMNS)
    given = load_bench(path, sheet="250mm", columns=LAB_COLUMNS, header_row=4)
    pd.testing.assert_frame_equal(auto.frame, given.frame)
    # a wrong row: a clear error naming the file, the sheet, the row and where the header is
    err = raises_text(path, "--header-row 5 (header_row=5): row 5 holds numbers (cell A5 is",
                 sheet="250mm", columns=LAB_COLUMNS, header_row=5)
    assert err.sheet == "250mm"
    assert str(err).startswith(f"{path}, sheet '250mm': ")
    assert "row 4 names pamid's columns (--header-row 4" in str(err)
    raises_text(path, "row 1 ('Festo tube cut to 250 mm, logged by hand on 2024-03-01') names "
                 "none of pamid's columns; row 4 names", sheet="250mm", header_row=1)
    raises_text(path, "row 3 of the sheet is empty", sheet="250mm", header_row=3)
    raises_text(path, "row 999 of the sheet is below the last filled row 64", sheet="250mm",
           header_row=999)
    raises_text(path, "header_row (--header-row) must be a row number, 1 or more", header_row=0)
    raises_text(write(tmp_path, "pressure_kPa,force_N,contraction_pct\n1,2,3\n"),
           "header_row=4 (--header-row) applies to spreadsheets", header_row=4)


def test_lab_workbook_every_sheet_a_muscle(tmp_path):
    path = write_lab_workbook(tmp_path / "lab.xlsx", lengths=(300, 250, 200), notes_sheet=True)
    with pytest.warns(UserWarning, match=r"sheet 'Notes' left out: no row there names"):
        data = load_bench(path, sheet="all", columns=LAB_COLUMNS)
    assert data.muscles == ("300mm", "250mm", "200mm") and data.has_muscle_column
    assert data.l0_mm == {"300mm": 300.0, "250mm": 250.0, "200mm": 200.0}
    assert data.frame.groupby("muscle", sort=False).size().tolist() == [60, 60, 60]
    assert data.covariates == ("strain",)
    # the resting length is each sheet's own
    for muscle, l0 in data.l0_mm.items():
        rows = data.for_muscle(muscle)
        np.testing.assert_allclose(rows["contraction_pct"], 100 * (l0 - rows["length_mm"]) / l0)
    # errors name the sheet and the cell
    err = raises_text(path, "row 61 holds numbers", sheet="all", columns=LAB_COLUMNS,
                 header_row=61)
    assert err.sheet == "300mm"


def test_lab_workbook_pressurizing_flag_is_the_direction(tmp_path):
    path = write_lab_workbook(tmp_path / "lab.xlsx")
    data = load_bench(path, sheet="300mm", columns=LAB_COLUMNS)
    assert "pressurizing" not in data.frame and "P/DP" not in data.frame
    assert data.frame["direction"].tolist() == ([1] * 10 + [-1] * 10) * 3
    # the same column in a CSV file, and under a name the user maps
    csv = write(tmp_path, "pressure_kPa,force_N,contraction_pct,P/DP\n100,50,5,1\n200,90,5,1\n"
                          "100,45,5,0\n")
    assert quiet_load(csv).frame["direction"].tolist() == [1, 1, -1]
    mapped = write(tmp_path, "pressure_kPa,force_N,contraction_pct,Ventil\n100,50,5,1\n"
                             "200,90,5,0\n", "mapped.csv")
    assert quiet_load(mapped, columns={"Ventil": "pressurizing"}).frame["direction"].tolist() \
        == [1, -1]
    # anything but 0 and 1 is an error naming the file, sheet, column, row and cell
    from openpyxl import load_workbook

    book = load_workbook(path)
    book["300mm"]["E7"] = 2
    book.save(path)
    err = raises_text(path, "a pressurizing flag must be 1 (pressurizing) or 0 (depressurizing), "
                       "got 2", sheet="300mm", columns=LAB_COLUMNS)
    assert (err.column, err.row, err.sheet, err.cell) == ("P/DP", 3, "300mm", "E7")
    both = write(tmp_path, "pressure_kPa,force_N,contraction_pct,P/DP,direction\n"
                           "100,50,5,1,1\n", "both.csv")
    raises_text(both, "both a direction column ('direction') and a pressurizing flag")


def test_values_above_the_header_only_when_mapped(tmp_path):
    path = write_lab_workbook(tmp_path / "lab.xlsx")
    unmapped = {k: v for k, v in LAB_COLUMNS.items() if k != "resting length"}
    # never guessed: without the mapping the resting length is not read
    raises_text(path, "length_mm is given without contraction_pct", sheet="300mm",
           columns=unmapped)
    assert load_bench(path, sheet="300mm", columns=unmapped, l0_mm=300).l0_mm == {
        "muscle": 300.0}
    # a label with a colon; its value not a number: the error names the cell
    from openpyxl import load_workbook

    book = load_workbook(path)
    book["300mm"]["A2"] = "resting length:"
    book["300mm"]["B2"] = "three hundred"
    book.save(path)
    err = raises_text(path, "'three hundred' is not a number (the value in sheet '300mm', cell B2)",
                 sheet="300mm", columns=LAB_COLUMNS)
    assert err.column == "resting length"
    book["300mm"]["B2"] = None
    book["300mm"]["C2"] = None
    book.save(path)
    raises_text(path, "the label 'resting length' (cell A2) has no value in a cell to its right",
           sheet="300mm", columns=LAB_COLUMNS)
    raises_text(path, "the column mapping names 'rest length', which the file does not have",
           sheet="300mm", columns={**unmapped, "rest length": "l0_mm"})


def test_every_sheet_a_muscle_refuses_a_muscle_column(tmp_path):
    path = write_xlsx(tmp_path / "b.xlsx", {"A": SHEET, "B": SHEET})
    raises_text(path, "with sheet='all' (--sheet all) each sheet is one muscle", sheet="all")


def test_cli_fits_the_lab_workbook(tmp_path, pamid_cli):
    """``pamid fit FILE.xlsx --sheet 300mm`` was: "the header has no name in cell B1"."""
    path = write_lab_workbook(tmp_path / "lab.xlsx")
    res = pamid_cli(["fit", path, "--sheet", "all", "--columns", LAB_MAP, "--json",
                     "--intervals", "wald"])
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert [m["muscle"] for m in out["muscles"]] == ["300mm", "250mm"]
    assert all(m["converged"] and m["rmse_N"] < 6.0 for m in out["muscles"])
    res = pamid_cli(["fit", path, "--sheet", "300mm", "--columns", LAB_MAP, "--header-row",
                     "5", "--json"])
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert f"{path}, sheet '300mm': --header-row 5" in res.stderr
    res = pamid_cli(["fit", path, "--header-row", "0"])
    assert res.returncode == 2 and "expected a row number, 1 or more" in res.stderr


def test_strain_as_a_ratio_is_the_contraction(tmp_path):
    path = write_lab_workbook(tmp_path / "lab.xlsx")
    data = load_bench(path, sheet="300mm", columns={"strain": "contraction_ratio",
                                                    "Pressure": "pressure_kPa",
                                                    "Force": "force_N"})
    strain = load_bench(path, sheet="300mm", columns=LAB_COLUMNS).frame["strain"]
    np.testing.assert_allclose(data.frame["contraction_pct"], 100.0 * strain)
    assert "contraction_ratio" not in data.frame and data.covariates == ("Inflated length",)
    # a strain written in percent is out of range as a ratio: said, with the fix
    csv = write(tmp_path, "pressure_kPa,force_N,strain\n100,50,0.05\n200,90,12\n")
    err = raises_text(csv, "contraction ratio 12 is 1200 % of the nominal length, outside the "
                           "physical range", columns={"strain": "contraction_ratio"})
    assert (err.column, err.row) == ("strain", 2)
    both = write(tmp_path, "pressure_kPa,force_N,contraction_pct,e\n100,50,5,0.05\n", "b.csv")
    raises_text(both, "the contraction is given twice", columns={"e": "contraction_ratio"})
