"""Random tables against the command line's contract (property-based, with hypothesis).

Whatever a bench or decay file holds, ``pamid fit``, ``pamid diagnose`` and ``pamid
damping`` end with exit code 0 (done), 1 (a fit that did not converge) or 2 (bad input);
3 (an internal error) is a defect. stderr never holds a traceback; on exit 2 it holds exactly
one line starting ``pamid: error:`` and stdout is empty; on exit 0 or 1 with ``--json``
stdout is exactly one JSON object (strict JSON: no NaN). The input file is never changed.

Bench tables are drawn valid first — one or two muscles (with names as labs write them)
of 0 to 20 rows each (diagnose: up to 60), the pressure in kPa, bar, psi or Pa, the
contraction in % or as a ratio or as lengths with l0, headers with their units as labs
write them, optional time, direction, trial and temperature columns — then, in most
examples, spoiled in one or two of the ways a real file goes wrong: a required column
missing, a non-numeric, blank, NaN, inf or out-of-range cell, an empty row, a duplicate
or synonym column, an unknown unit, a junk header, a ragged row, junk columns
(``SPOILS``; ``test_the_bench_tables_are_varied`` checks the mix by what ``load_bench``
says of them: the first version drew mostly files with a duplicate header or no rows, and
never two muscles). Decay tables: 0, 1 or 120 rows, spoiled the older way (names
renamed, columns added, dropped or repeated, cells replaced). Every table is written with
any of the delimiters and decimal marks pamid reads, quoted or not, with CRLF or a BOM.
Up to 64 rows per muscle and one or two muscles pack to few size classes
(``pamid._lanes._batch.padded_rows``), so JAX compiles each model a few times (the CLI is run
in this process). ``derandomize=True``: every run draws the same examples.
"""

from __future__ import annotations

import collections
import contextlib
import hashlib
import io
import json
import math
import os
import random
import re
import warnings

import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from pamid._cli import main

SETTINGS = settings(max_examples=30, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
#: Bench tables: more examples (their sizes share a few compiled programs).
BENCH_EXAMPLES = {"fit": 60, "diagnose": 25}

# Header spellings pamid maps to its names, names it rejects with a message, and junk.
PRESSURE = ["pressure_kPa", "Pressure [kPa]", "p / bar", "pressure_psi", "P (kPa)"]
FORCE = ["force_N", "Force (N)", "F_N", "force [N]"]
CONTRACTION = ["contraction_pct", "Contraction [%]", "κ [%]", "kappa_pct"]
OTHER_NAMES = ["muscle", "trial", "Test", "time_s", "Time [s]", "direction", "cycle",
               "temperature_C", "T_C", "velocity_mm_s", "length_mm", "l0_mm",
               "contraction_mm", "source_row", "force_kN", "pressure", "Time [ms]", "note",
               "", " ", "x", "ünïcödé", "a,b", 'q"uote', "pressure_kPa"]
JUNK_CELLS = ["", " ", "abc", "nan", "NaN", "inf", "-inf", "1e400", "-1e400", "1e300",
              "-1e300", "1e-320", "1_000", "٣", "３", "½", "Ω", "😀", '"', '""', "1,5",
              "1.5.5", "--1", "0x10", "1e", "  12  ", "\u00a0", ";", "\t", "-0", "+7",
              "NA", "null", "#N/A", "TRUE", "2026-11-24", "\\N", "\x00", "\r"]


#: The bench file's pressure unit: header spellings, and kPa to that unit.
PRESSURE_UNITS = {
    "kPa": (["pressure_kPa", "Pressure [kPa]", "P (kPa)", "p / kPa", "Pressure_kPa"], 1.0),
    "bar": (["pressure_bar", "Pressure [bar]", "p / bar", "p (bar)"], 0.01),
    "psi": (["pressure_psi", "Pressure [psi]"], 0.1450377),
    "Pa": (["pressure_Pa", "Pressure (Pa)"], 1000.0),
}
CONTRACTION_PCT = ["contraction_pct", "Contraction [%]", "κ [%]", "kappa_pct", "kappa (%)"]
MUSCLE_NAMES = ["M1", "left", "Festo DMSP-20 400", "A/B", "müskel", "3", "A B", "A_B"]
#: How a valid bench table is spoiled: in about two thirds of the tables, one or two of
#: these, about evenly.
SPOILS = ["cell", "missing_column", "non_numeric", "blank_cell", "empty_row", "duplicate",
          "unknown_unit", "junk_header", "ragged", "non_finite", "out_of_range",
          "junk_column"]


def numbers(lo: float, hi: float):
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False).map(lambda v: f"{v:.6g}")


def cells():
    return st.one_of(
        st.sampled_from(JUNK_CELLS),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.integers(-10**30, 10**30).map(str),
        st.text(max_size=6),
    )


@st.composite
def bench_tables(draw, max_muscles: int = 2, rows=(0, 1, 2, 3, 5, 8, 12, 20)):
    """A bench table as the bytes of a file: valid, then spoiled (module docstring). Its
    shape (muscles, rows, units, spoils) is chosen by a seeded ``random.Random``, evenly:
    hypothesis' own choices favour what it shrinks to (the first of ``sampled_from``, 0),
    which made most tables alike. Its seed is four draws: hypothesis varies an example by
    changing some of its draws, and a seed of one draw repeated (19 seeds in 100 tables)."""
    rng = random.Random(repr([draw(st.integers(0, 2**32 - 1)) for _ in range(4)]))
    n_muscles = rng.choice([1, 2][:max_muscles])
    rows = [rng.choice(rows) for _ in range(n_muscles)]
    if n_muscles > 1:  # a muscle of no rows is not in the table: two muscles have rows
        rows = [k or 5 for k in rows]
    names = draw(st.lists(st.sampled_from(MUSCLE_NAMES), min_size=n_muscles,
                          max_size=n_muscles, unique=True))
    muscle = [m for m, k in zip(names, rows) for _ in range(k)]
    step = [i for k in rows for i in range(k)]
    n = len(muscle)
    p_kpa = [100.0 + 100.0 * (i % 5) for i in step]
    kappa = [draw(st.floats(0.0, 25.0)) for _ in range(n)]
    force = [max(p * (2.8 - 0.09 * k) + draw(st.floats(-3.0, 3.0)), 1.0)
             for p, k in zip(p_kpa, kappa)]
    unit = rng.choice(list(PRESSURE_UNITS))
    spellings, scale = PRESSURE_UNITS[unit]
    header = [draw(st.sampled_from(spellings)), draw(st.sampled_from(FORCE))]
    columns = [[f"{p * scale:.6g}" for p in p_kpa], [f"{f:.6g}" for f in force]]
    how = rng.choice(["pct", "pct", "ratio", "length"])
    if how == "pct":
        header.append(draw(st.sampled_from(CONTRACTION_PCT)))
        columns.append([f"{k:.6g}" for k in kappa])
    elif how == "ratio":
        header.append("contraction_ratio")
        columns.append([f"{k / 100:.6g}" for k in kappa])
    else:
        header += [draw(st.sampled_from(["length_mm", "Length [mm]", "l (mm)"])), "l0_mm"]
        columns += [[f"{400 * (1 - k / 100):.6g}" for k in kappa], ["400"] * n]
    if n_muscles > 1 or draw(st.booleans()):
        header.insert(0, draw(st.sampled_from(["muscle", "Muscle"])))
        columns.insert(0, muscle)
    extras = draw(st.lists(st.sampled_from(["time", "direction", "trial", "temperature"]),
                           unique=True, max_size=3))
    for extra in extras:
        if extra == "time":
            header.append(draw(st.sampled_from(["time_s", "Time [s]", "t (s)"])))
            columns.append([f"{0.5 * i:.6g}" for i in step])
        elif extra == "direction":
            header.append("direction")
            columns.append(["1" if i % 10 < 5 else "-1" for i in step])
        elif extra == "trial":
            header.append(draw(st.sampled_from(["trial", "Test", "run"])))
            columns.append([str(i // 10 + 1) for i in step])
        else:
            header.append(draw(st.sampled_from(["temperature_C", "Temperature [°C]"])))
            columns.append([f"{draw(st.floats(15.0, 40.0)):.4g}" for _ in range(n)])
    required = [j for j, h in enumerate(header) if h not in ("muscle", "Muscle")][:3]
    spoils = [rng.choice(SPOILS) for _ in range(rng.choice([0, 1, 1, 2]))]
    event("spoils: " + (", ".join(sorted(set(spoils))) or "none"))
    for spoil in spoils:
        j = rng.choice(required)
        # A row of this column: an earlier spoil may have shortened it (ragged) or
        # lengthened it (an empty row), so the row is drawn from its length now.
        i = rng.randrange(len(columns[j])) if columns[j] else None
        if spoil == "missing_column":
            del header[j], columns[j]
            required = [k - (k > j) for k in required if k != j]
            if not required:
                break
        elif spoil in ("non_numeric", "blank_cell", "non_finite", "cell") and i is not None:
            pool = {"non_numeric": st.sampled_from(["abc", "1.5.5", "--1", "0x10", "½", "😀",
                                                    "TRUE", "2026-11-24", "#N/A", "1e"]),
                    "blank_cell": st.sampled_from(["", " "]),
                    "non_finite": st.sampled_from(["nan", "NaN", "inf", "-inf", "1e400"]),
                    "cell": cells()}[spoil]
            columns[j][i] = draw(pool)
        elif spoil == "empty_row" and i is not None:
            for col in columns:
                col.insert(i, "")
        elif spoil == "duplicate":
            header.append(draw(st.sampled_from([header[j], "pressure_bar", "force_N",
                                                "contraction_pct"])))
            columns.append(list(columns[j]))
        elif spoil == "unknown_unit":
            header[j] = draw(st.sampled_from(["force_kN", "pressure_mmHg", "Pressure [atm]",
                                              "Time [ms]", "contraction_permille"]))
        elif spoil == "junk_header":
            header[j] = draw(st.sampled_from(OTHER_NAMES) | st.text(max_size=8))
        elif spoil == "ragged" and i is not None:
            columns[j] = columns[j][:-1]
        elif spoil == "out_of_range" and i is not None:
            columns[j][i] = draw(st.sampled_from(["-500", "80", "-1e6", "1e300"]))
        elif spoil == "junk_column":
            header.append(draw(st.sampled_from(OTHER_NAMES)))
            columns.append([draw(cells()) for _ in range(len(columns[0]) if columns else n)])
    return _written(draw, header, columns)


@st.composite
def tables(draw, kind: str, sizes: tuple[int, ...]):
    """A decay table as the bytes of a file (see the module docstring)."""
    n = draw(st.sampled_from(sizes))
    if kind == "decay":
        angle = draw(st.sampled_from(["angle_rad", "angle_deg", "Angle [rad]"]))
        scale = 180 / math.pi if "deg" in angle else 1.0
        header = ["time_s", angle]
        # A free decay: 4 Hz, 25 samples a period (pamid's decay analysis resolves it).
        columns = [[f"{0.01 * i:.2f}" for i in range(n)],
                   [f"{scale * 0.1 * math.exp(-0.008 * i) * math.cos(0.08 * math.pi * i):.6f}"
                    for i in range(n)]]
        if draw(st.booleans()):
            header.insert(0, "trial")
            columns.insert(0, ["1"] * n)
    # Spoil it: rename, add, drop or repeat columns, replace cells, make rows ragged.
    for _ in range(draw(st.integers(0, 3))):
        action = draw(st.sampled_from(["rename", "add", "drop", "repeat", "cell", "cell",
                                       "ragged"]))
        j = draw(st.integers(0, len(header) - 1)) if header else 0
        if action == "rename" and header:
            header[j] = draw(st.sampled_from(OTHER_NAMES) | st.text(max_size=8))
        elif action == "add":
            header.append(draw(st.sampled_from(OTHER_NAMES)))
            columns.append([draw(cells()) for _ in range(n)])
        elif action == "drop" and len(header) > 1:
            del header[j], columns[j]
        elif action == "repeat" and header:
            header.append(header[j])
            columns.append(list(columns[j]))
        elif action == "cell" and n and header:
            columns[j][draw(st.integers(0, n - 1))] = draw(cells())
        elif action == "ragged" and n and header:
            columns[j] = columns[j][: n - 1]
    return _written(draw, header, columns)


def _written(draw, header: list[str], columns: list[list[str]]) -> bytes:
    """``header`` and ``columns`` as the bytes of a file: a delimiter and decimal mark
    pamid reads, quoted or not, CRLF or not, a BOM or not."""
    n = max((len(col) for col in columns), default=0)
    sep = draw(st.sampled_from([",", ";", "\t"]))
    decimal = draw(st.sampled_from([".", ","])) if sep != "," else "."
    quote = draw(st.sampled_from(["none", "all", "header"]))
    newline = draw(st.sampled_from(["\n", "\r\n"]))

    def cell(text: str, quoted: bool) -> str:
        if decimal == "," and text[:1].isdigit():
            text = text.replace(".", ",")
        return '"' + text.replace('"', '""') + '"' if quoted else text

    lines = [sep.join(cell(h, quote != "none") for h in header)]
    for i in range(n):
        lines.append(sep.join(cell(col[i], quote == "all") for col in columns if i < len(col)))
    text = newline.join(lines) + (newline if draw(st.booleans()) else "")
    bom = "\ufeff" if draw(st.booleans()) else ""
    return (bom + text).encode("utf-8")


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("property")


@pytest.fixture(scope="module", autouse=True)
def compile_cache(tmp_path_factory):
    old = os.environ.get("PAMID_CACHE_DIR")
    os.environ["PAMID_CACHE_DIR"] = str(tmp_path_factory.mktemp("jax-cache"))
    yield
    if old is None:
        os.environ.pop("PAMID_CACHE_DIR", None)
    else:
        os.environ["PAMID_CACHE_DIR"] = old


def _reject_constant(name):
    raise ValueError(f"{name} is not JSON")


def check_contract(path, args: list[str]) -> int:
    """Run ``pamid ARGS`` in this process on ``path`` and check the contract; the exit code."""
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(args)
    stdout, stderr = out.getvalue(), err.getvalue()
    shown = f"pamid {' '.join(args)} on {path.read_bytes()!r}: exit {code}\n{stderr}"
    event(f"{args[0]}: exit {code}")  # pytest --hypothesis-show-statistics
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before, "input changed: " + shown
    assert "Traceback" not in stderr, shown
    assert code in (0, 1, 2), shown
    if code == 2:
        errors = [line for line in stderr.splitlines() if line.startswith("pamid: error:")]
        assert len(errors) == 1, shown
        assert "\n" not in errors[0] and stdout == "", shown
    else:
        payload, end = json.JSONDecoder(parse_constant=_reject_constant).raw_decode(stdout)
        assert isinstance(payload, dict) and stdout[end:].strip() == "", shown
    return code


def write(workdir, data: bytes):
    path = workdir / "table.csv"
    path.write_bytes(data)
    return path


def _outcome(path, width: int | None = 48) -> str:
    """What ``load_bench`` says of a file: "valid" (or "valid, several muscles"), or its
    error without the file's name, numbers and quoted names (one kind of defect, one
    text), cut to ``width`` characters (None: whole)."""
    from pamid import load_bench

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bench = load_bench(path)
    except Exception as exc:  # noqa: BLE001 - every failure is a kind of its own here
        text = str(exc).replace(str(path), "")
        return re.sub(r"'[^']*'|\"[^\"]*\"|[-+]?\d[\d.e+-]*", "_", text)[:width]
    return "valid, several muscles" if len(bench.muscles) > 1 else "valid"


def test_the_bench_tables_are_varied(workdir):
    """The fuzz found that the first version drew mostly one defect (a duplicate header,
    or no rows): the bench tables are valid in a fair share and fail in many ways."""
    seen = collections.Counter()
    texts = set()

    # 300 tables (no JAX here: 3 s). Hypothesis' draws change with the test's source and
    # follow one another (mutations of earlier tables): over twelve seeds, 100 tables held
    # 24–44 % valid ones and 6–10 kinds of defect (a full run drew 15 % valid, 2026-11-29),
    # 300 held 24–38 % and 8–10 kinds, every share below within its bound.
    @settings(SETTINGS, max_examples=300)
    @given(data=bench_tables())
    def draw(data):
        path = write(workdir, data)
        seen[_outcome(path)] += 1
        texts.add(_outcome(path, width=None))

    draw()
    total = sum(seen.values())
    valid = ("valid", "valid, several muscles")
    assert seen["valid"] + seen["valid, several muscles"] >= 0.2 * total, seen
    # several muscles: the first strategy drew one such file in 100; a third of the tables
    # with two muscles drew 1 to 5 (1 in a full `make test` run, 2026-11-28: hypothesis'
    # draws are not the same there and alone); half of them, each muscle with rows, 8 alone
    assert seen["valid, several muscles"] >= 2, seen
    assert max(v for k, v in seen.items() if k not in valid) <= 0.25 * total, seen
    # the whole messages: a kind's 48 characters cut "is outside" off the contraction's
    # (6 kinds counted of 7 in a full run, 2026-11-29)
    said = " | ".join(texts)
    defects = ("is not a number", "missing required column", "empty cell", "appears twice",
               "unknown unit", "cells but the header", "no data rows", "is infinite",
               "is NaN", "is outside")
    assert sum(d in said for d in defects) >= 7, seen


@settings(SETTINGS, max_examples=BENCH_EXAMPLES["fit"])
@given(data=bench_tables())
def test_fit_keeps_its_contract_on_random_tables(workdir, data):
    path = write(workdir, data)
    check_contract(path, ["fit", str(path), "--json", "--intervals", "wald"])


@settings(SETTINGS, max_examples=BENCH_EXAMPLES["diagnose"])
# One muscle (each count of them compiles anew), mostly enough rows to be diagnosed.
@given(data=bench_tables(max_muscles=1, rows=(0, 3, 12, 20, 40, 60)))
# one and two rows ended in an internal error (IndexError in the lane fit) until
# diagnose checked that every muscle has more rows than the constants it compares
@example(data=b"pressure_kPa,force_N,contraction_pct\n100,200,5\n")
@example(data=b"pressure_kPa,force_N,contraction_pct\n100,5,1\n175,5,1")
def test_diagnose_keeps_its_contract_on_random_tables(workdir, data):
    path = write(workdir, data)
    check_contract(path, ["diagnose", str(path), "--json"])


@SETTINGS
@given(data=tables("decay", sizes=(0, 1, 120)))
def test_decay_commands_keep_their_contract_on_random_tables(workdir, data):
    path = write(workdir, data)
    check_contract(path, ["damping", str(path), "--inertia", "0.5", "--json"])
    check_contract(path, ["diagnose", str(path), "--inertia", "0.5", "--json"])
