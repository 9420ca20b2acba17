"""No traceback, ever: what ``pamid`` says and returns when something other than its input
fails (out of memory, a defect, Ctrl-C, a closed stdout), and the memory diagnose needs.

Exit codes (pamid/_commands/failure.py): 2 bad input or a wrong option (one line, also for
argparse's own errors), 1 not converged, 3 internal failure, 130 interrupted, 141 stdout
closed early.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamid
from pamid._cli import main
from pamid._commands import failure
from pamid._diagnose import _static
from pamid._inference import numerical_rank

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench_csv(tmp_path_factory):
    """One muscle of 300 rows (the default protocol, repeats averaged)."""
    frame = pamid.simulate_sarosi_bench(jax.random.key(3), pamid.sarosi.table_3_1(),
                                        pamid.SarosiProtocol(min_force_N=10.0))
    path = tmp_path_factory.mktemp("failures") / "bench.csv"
    frame.to_csv(path, index=False)
    return path


def _one_line(err: str) -> str:
    lines = [s for s in err.splitlines() if s.strip() and not s.startswith("[")]
    lines = [s for s in lines if not s.startswith("pamid: warning:")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def _raise(exc):
    def boom(*args, **kwargs):
        raise exc

    return boom


# -- out of memory, deep in the diagnose path --------------------------------------------------


def test_memory_error_deep_in_diagnose_is_one_line_and_exit_3(bench_csv, monkeypatch, capsys):
    monkeypatch.delenv("PAMID_DEBUG", raising=False)
    monkeypatch.setattr(_static, "_run_lanes", _raise(
        MemoryError("Unable to allocate 47.0 GiB for an array with shape (64, 9596, 9596)")))
    assert main(["diagnose", str(bench_csv), "--json"]) == failure.EXIT_INTERNAL == 3
    captured = capsys.readouterr()
    line = _one_line(captured.err)
    assert line.startswith("pamid: error: out of memory (MemoryError: Unable to allocate 47.0")
    assert "try --max-rows N or a machine with more memory" in line
    assert captured.out == ""


def test_xla_resource_exhausted_is_out_of_memory(bench_csv, monkeypatch, capsys):
    monkeypatch.delenv("PAMID_DEBUG", raising=False)
    # what XLA raised for one muscle of 10,000 rows before the rank stopped using the SVD
    # of the tall Jacobian: several lines, the first one says it
    exc = jax.errors.JaxRuntimeError(
        "RESOURCE_EXHAUSTED: Out of memory allocating 51256399720 bytes.\n"
        "  while running replica 0 and partition 0 of a replicated computation")
    monkeypatch.setattr(_static, "_run_lanes", _raise(exc))
    assert main(["diagnose", str(bench_csv)]) == 3
    line = _one_line(capsys.readouterr().err)
    assert line == ("pamid: error: out of memory (JaxRuntimeError: RESOURCE_EXHAUSTED: Out of "
                    "memory allocating 51256399720 bytes.); try --max-rows N or a machine with "
                    "more memory")


def test_out_of_memory_in_fit_suggests_the_stream(bench_csv, monkeypatch, capsys):
    monkeypatch.delenv("PAMID_DEBUG", raising=False)
    import pamid._fit._api as fit_api

    monkeypatch.setattr(fit_api, "fit_least_squares", _raise(MemoryError()))
    assert main(["fit", str(bench_csv), "--json"]) == 3
    line = _one_line(capsys.readouterr().err)
    assert line == ("pamid: error: out of memory (MemoryError); a Parquet file bigger than "
                    "memory is fitted a chunk of muscles at a time with --stream (a CSV file: "
                    "convert it to Parquet first); or a machine with more memory")


def test_out_of_memory_elsewhere_suggests_a_smaller_file():
    assert failure.describe(MemoryError(), "compare") == (
        "out of memory (MemoryError); try a smaller file or a machine with more memory")


# -- any other failure ------------------------------------------------------------------------


def test_internal_error_is_one_line_naming_the_type(bench_csv, monkeypatch, capsys):
    monkeypatch.delenv("PAMID_DEBUG", raising=False)
    monkeypatch.setattr(_static.StaticProblem, "evaluate", _raise(KeyError("slots")))
    assert main(["diagnose", str(bench_csv)]) == 3
    line = _one_line(capsys.readouterr().err)
    assert line == ("pamid: error: internal error (KeyError: 'slots'); rerun with "
                    "PAMID_DEBUG=1 for the traceback and report it")


def test_pamid_debug_reraises(bench_csv, monkeypatch):
    monkeypatch.setenv("PAMID_DEBUG", "1")
    monkeypatch.setattr(_static.StaticProblem, "evaluate", _raise(RuntimeError("deep defect")))
    with pytest.raises(RuntimeError, match="deep defect"):
        main(["diagnose", str(bench_csv)])


def test_keyboard_interrupt_is_one_line_and_exit_130(bench_csv, monkeypatch, capsys):
    monkeypatch.delenv("PAMID_DEBUG", raising=False)
    monkeypatch.setattr(_static.StaticProblem, "evaluate", _raise(KeyboardInterrupt()))
    assert main(["diagnose", str(bench_csv)]) == 130
    assert _one_line(capsys.readouterr().err) == "pamid: interrupted"


def test_bad_input_keeps_exit_2(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    path.write_text("pressure_kPa,contraction_pct,force_N\n100,1,50\n100,x,40\n")
    assert main(["diagnose", str(path)]) == 2
    assert "row 2" in _one_line(capsys.readouterr().err)


def test_message_of_an_exception_without_text():
    assert failure.describe(RuntimeError(), "fit") == (
        "internal error (RuntimeError); rerun with PAMID_DEBUG=1 for the traceback and "
        "report it")
    long = failure.describe(ValueError("x" * 1000), "fit")
    assert len(long) < failure.MAX_QUOTE + 120


# -- a wrong option: argparse's error in one line ----------------------------------------------


@pytest.mark.parametrize(("argv", "line"), [
    (["fit", "x.csv", "--max-plots", "1.5"],
     "pamid fit: error: argument --max-plots: invalid int value: '1.5' "
     "(see pamid fit --help)"),
    (["fit", "x.csv", "--bogus", "1"],
     "pamid fit: error: unrecognized arguments: --bogus 1 (see pamid fit --help)"),
    (["fit"], "pamid fit: error: the following arguments are required: data "
              "(see pamid fit --help)"),
    (["diagnose", "x.csv", "--folds"],
     "pamid diagnose: error: argument --folds: expected one argument "
     "(see pamid diagnose --help)"),
    (["damping", "d.csv"], "pamid damping: error: the following arguments are required: "
                           "--inertia (see pamid damping --help)"),
    (["simulate", "lifting-mass", "--pressure-kPa", "400", "--mass-kg", "x", "--x0-mm", "5"],
     "pamid simulate lifting-mass: error: argument --mass-kg: invalid float value: 'x' "
     "(see pamid simulate lifting-mass --help)"),
    (["simulate", "positioning", "--target-mm", "5", "--zork"],
     "pamid simulate positioning: error: unrecognized arguments: --zork "
     "(see pamid simulate positioning --help)"),
    ([], "pamid: error: the following arguments are required: command (see pamid --help)"),
    # --max-plots -1 was accepted (fit plotted all muscles but the last)
    *[([*command, "--max-plots", "-1"],
       f"pamid {command[0]}: error: argument --max-plots: must be an integer ≥ 0, got -1 "
       f"(see pamid {command[0]} --help)")
      for command in (["fit", "x.csv"], ["compare", "x.csv"],
                      ["damping", "d.csv", "--inertia", "1"],
                      ["check-decays", "d.csv", "--model-json", "m.json", "--inertia", "1"])],
])
def test_a_wrong_option_is_one_line_and_exit_2(argv, line, monkeypatch, capsys):
    """argparse printed its usage (several lines) above the error."""
    monkeypatch.delenv("PAMID_DEBUG", raising=False)
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    captured = capsys.readouterr()
    assert captured.err == line + "\n" and captured.out == ""


def test_a_wrong_option_with_pamid_debug_shows_the_usage(monkeypatch, capsys):
    monkeypatch.setenv("PAMID_DEBUG", "1")
    with pytest.raises(SystemExit) as stop:
        main(["fit", "x.csv", "--max-plots", "1.5"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: pamid fit ") and "--max-plots MAX_PLOTS" in err
    assert err.endswith("pamid fit: error: argument --max-plots: invalid int value: '1.5' "
                        "(see pamid fit --help)\n")


def test_help_is_no_error(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["fit", "--help"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.startswith("usage: pamid fit ")


def _commands(parser, prefix=()):
    """Every command and nested subcommand of ``parser``, as argument lists."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield [*prefix, name]
                yield from _commands(sub, (*prefix, name))


def test_every_help_text_is_shown(capsys):
    """`pamid --help` and every (sub)command's --help print and exit 0: argparse formats a
    help text with %, so a bare "95 % predictive" in one command's one-line help made the
    top-level `pamid --help` end in a traceback."""
    from pamid._cli import _parser

    commands = [[], *_commands(_parser())]
    assert ["predict"] in commands and ["simulate", "lifting-mass"] in commands
    for args in commands:
        with pytest.raises(SystemExit) as stop:
            main([*args, "--help"])
        assert stop.value.code == 0, args
        assert capsys.readouterr().out.startswith(" ".join(["usage: pamid", *args])), args


@pytest.mark.parametrize("command", ["fit", "diagnose", "compare"])
def test_the_help_of_a_model_option_says_a_model_file_is_code(command, capsys):
    """`--model file.py:Class` runs whatever the file does; the help did not say so."""
    with pytest.raises(SystemExit) as stop:
        main([command, "--help"])
    assert stop.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert ("A model file is Python code: pamid imports it, which runs whatever it does, "
            "with your permissions; give only files you trust") in text


# -- a closed stdout --------------------------------------------------------------------------


def test_broken_pipe_in_process_is_quiet(monkeypatch, capsys):
    import pamid._commands.dynamics as dynamics

    # register() binds the function when the parser is built, i.e. inside main()
    monkeypatch.setattr(dynamics, "cmd_lifting_mass", _raise(BrokenPipeError(32, "Broken pipe")))
    assert main(["simulate", "lifting-mass", "--pressure-kPa", "400", "--mass-kg", "50",
                 "--x0-mm", "50", "--json"]) == failure.EXIT_BROKEN_PIPE == 141
    assert capsys.readouterr().err == ""


def test_broken_pipe_of_a_real_process_exits_quietly():
    """``pamid simulate lifting-mass --json`` into a pipe whose reader has gone: no output
    on stderr at all (no traceback, no "Exception ignored"), exit 141."""
    env = {k: v for k, v in os.environ.items() if k != "PAMID_DEBUG"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "pamid._cli", "simulate", "lifting-mass", "--pressure-kPa",
         "400", "--mass-kg", "50", "--x0-mm", "50", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT, env=env)
    proc.stdout.close()  # the reader is gone before the command writes (it imports jax first)
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 141, err
    assert err == ""


def test_the_same_command_into_an_open_pipe_prints_its_json():
    """The control for the test above: the command does print, and exits 0."""
    out = subprocess.run(
        [sys.executable, "-m", "pamid._cli", "simulate", "lifting-mass", "--pressure-kPa",
         "400", "--mass-kg", "50", "--x0-mm", "50", "--json"],
        capture_output=True, cwd=ROOT, timeout=300, check=False)
    assert out.returncode == 0
    assert json.loads(out.stdout)["system"] == "lifting-mass"


# -- the memory of diagnose grows with the rows, not their square -----------------------------


def _svd_rank(a: np.ndarray) -> int:
    norms = np.linalg.norm(a, axis=0)
    sv = np.linalg.svd(a / np.where(norms > 0, norms, 1.0), compute_uv=False)
    return int(np.sum(sv > sv[0] * 1e-9))


def _known_matrices():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 6))
    dup = a.copy()
    dup[:, 4] = dup[:, 1]  # a repeated column
    combo = a.copy()
    combo[:, 5] = 2.0 * a[:, 0] - 3.0 * a[:, 2]  # a linear combination
    zero = a.copy()
    zero[:, 3] = 0.0  # a masked constant
    scales = a * np.array([1e-8, 1.0, 1e6, 1.0, 1e3, 1.0])  # full rank, badly scaled
    near = a.copy()
    near[:, 2] = a[:, 1] + 1e-12 * a[:, 0]  # equal to rounding: rank 5
    wide = rng.normal(size=(4, 6))  # fewer rows than constants
    ones = np.ones((20, 3))
    return {"full": (a, 6), "duplicate": (dup, 5), "combination": (combo, 5),
            "zero column": (zero, 5), "scaled": (scales, 6), "nearly equal": (near, 5),
            "wide": (wide, 4), "rank one": (ones, 1)}


@pytest.mark.parametrize("name", list(_known_matrices()))
def test_numerical_rank_equals_the_svd_rank(name):
    a, rank = _known_matrices()[name]
    assert _svd_rank(a) == rank
    assert int(numerical_rank(jnp.asarray(a))) == rank
    assert int(numerical_rank(a)) == rank  # NumPy in: the same criterion, no compile


def test_numerical_rank_batched_like_the_lanes():
    mats = _known_matrices()
    stack = np.stack([mats[k][0] for k in ("full", "duplicate", "combination", "scaled")])
    ranks = jax.jit(jax.vmap(numerical_rank))(jnp.asarray(stack))
    np.testing.assert_array_equal(np.asarray(ranks), [6, 5, 5, 6])


def _problem(rows: int, tmp_path):
    from pamid._data._bench import load_bench
    from pamid._fit._spec import get_model

    points = rows // 100  # 5 pressures × 2 directions × 10 repeats
    proto = pamid.SarosiProtocol(points_per_curve=points, repeats=10, average_repeats=False,
                                 seconds_per_point=200.0 / points, min_force_N=10.0)
    frame = pamid.simulate_sarosi_bench(jax.random.key(0), pamid.sarosi.table_3_1(), proto)
    path = tmp_path / f"rows{rows}.csv"
    frame.to_csv(path, index=False)
    bench = load_bench(path)
    return _static.StaticProblem(bench, get_model("sarosi", bench.frame))


def test_lane_temporaries_grow_linearly_with_the_rows(tmp_path):
    """XLA's own accounting of the compiled lanes: 10× the rows, ~10× the temporaries (the
    SVD of the tall Jacobian made it ~100×: 6.4 GB for 8 lanes of 10,000 rows)."""
    temps = {}
    from pamid._effects._model import with_effects
    from pamid._fit._least_squares import _own_loop

    for rows in (2000, 20000):
        problem = _problem(rows, tmp_path)
        lanes = 8
        n_tr = len(_static.transforms())
        k = problem.spec.n_params
        p = k + n_tr + 4
        # the refits as the diagnosis runs them: four effect columns, the transforms free
        # (the implicit compliance), unbounded
        index = (np.zeros(lanes, int), np.arange(lanes) % 6, np.tile(np.arange(4), (lanes, 1)),
                 np.ones((lanes, 4)))
        theta0 = np.concatenate([np.tile(np.asarray(problem.theta0)[0], (lanes, 1)),
                                 np.zeros((lanes, n_tr + 4))], axis=1)
        bounds = (np.full((lanes, p), -np.inf), np.full((lanes, p), np.inf))
        compiled = _own_loop.lower(
            with_effects(problem.spec, True, 4), _static.REFIT_SOLVER, _static.lane_data,
            _static.MAX_ITER, ("prediction",), problem._shared_arrays(),
            theta0, np.ones((lanes, p)), bounds, index).compile()
        temps[rows] = compiled.memory_analysis().temp_size_in_bytes
        assert temps[rows] / (lanes * rows) <= _static.LANE_BYTES_PER_SAMPLE
        # the statistics of the fits to all data (QR of the Jacobian: n × p, never n × n)
        stats = _static._lane_statistics_jit.lower(
            problem.spec, True, problem._shared_arrays(), index[0], index[2], index[3],
            np.ones((lanes, p)), np.zeros((lanes, p))).compile()
        temps[rows, "statistics"] = stats.memory_analysis().temp_size_in_bytes
        assert temps[rows, "statistics"] / (lanes * rows) <= _static.LANE_BYTES_PER_SAMPLE
    assert 8.0 < temps[20000] / temps[2000] < 12.0
    assert 8.0 < temps[20000, "statistics"] / temps[2000, "statistics"] < 12.0


@pytest.mark.slow
def test_evaluate_on_a_muscle_of_20000_rows(tmp_path):
    """The first step of the selection on one muscle of 20,000 rows: every candidate, all
    data and five folds (before: an n × n array per lane, 205 GB for 64 lanes)."""
    problem = _problem(20000, tmp_path)
    assert problem.features.shape[2] == pamid.engine.padded_rows(20000)  # its size class
    sets = [(), *[(c,) for c in problem.candidate_names]]
    fits = problem.evaluate(sets)
    base = fits[0]
    assert base.n[0] == 20000 and base.k[0] == 6
    assert all(np.all(f.converged) for f in fits)
    # no effect hidden: the baseline's RMSE is the reading noise (2 N, rounded to 0.1 N)
    assert 1.9 < base.rmse < 2.1
    assert base.cv_n == 20000  # every row held out once
    assert base.extra["residual"].shape == (1, pamid.engine.padded_rows(20000))


def test_start_subsample_of_a_long_muscle_is_a_gather_with_the_same_samples(monkeypatch):
    """One muscle of many samples: the start's subsample is gathered (a program of fixed
    size; one strided slice per stride made it grow with n) and equals the sliced one."""
    from pamid._solvers import _sarosi as gn

    n, n_sub = 3000, 64
    rng = np.random.default_rng(1)
    values = jnp.asarray(rng.normal(size=(3, n)))
    w = np.zeros((3, n))
    w[0], w[1, :2000], w[2, :100] = 1.0, 1.0, 1.0
    w = jnp.asarray(w)
    assert -(-n // n_sub) > gn.SUBSAMPLE_MAX_STRIDES  # the gather path
    (gathered,), w_gathered = gn._subsample((values,), w, n_sub)
    monkeypatch.setattr(gn, "SUBSAMPLE_MAX_STRIDES", 10**6)
    (sliced,), w_sliced = gn._subsample((values,), w, n_sub)
    np.testing.assert_array_equal(gathered, sliced)
    np.testing.assert_array_equal(w_gathered, w_sliced)
    np.testing.assert_array_equal(gathered[0], values[0, ::47][:n_sub])  # stride ⌈3000/64⌉
    np.testing.assert_array_equal(gathered[2], values[2, ::2][:n_sub])
    assert float(jnp.sum(w_gathered[2])) == 50.0  # 100 samples at stride 2


# -- --max-rows: a representative subsample of whole curves -----------------------------------


def _sweeps(tmp_path, points, repeats, effects=(), name="sweeps.csv"):
    proto = pamid.SarosiProtocol(points_per_curve=points, repeats=repeats,
                                 average_repeats=False, min_force_N=10.0, effects=effects)
    frame = pamid.simulate_sarosi_bench(jax.random.key(5), pamid.sarosi.table_3_1(), proto)
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


def test_subsample_keeps_whole_curves_of_every_setting(tmp_path):
    from pamid._data._bench import load_bench
    from pamid._diagnose._api import subsample_curves

    bench = load_bench(_sweeps(tmp_path, 40, 10))  # 100 curves of 40 rows
    assert len(bench.frame) == 4000
    same, note = subsample_curves(bench, 4000)
    assert same is bench and note is None
    sub, note = subsample_curves(bench, 1000)
    frame = sub.frame
    assert len(frame) == 1000 and note.startswith("25 of 100 whole curves")
    key = ["pressure_kPa", "direction", "cycle"]
    sizes = frame.groupby(key).size()
    assert (sizes == 40).all()  # every kept curve is whole
    # every setting (pressure × direction) keeps curves, from early and late cycles
    per_setting = frame.groupby(["pressure_kPa", "direction"])["cycle"].agg(["nunique", "min",
                                                                              "max"])
    assert len(per_setting) == 10 and (per_setting["nunique"] >= 2).all()
    assert per_setting["min"].max() <= 5 and per_setting["max"].min() >= 6
    # the kept rows in file order, as they were
    rows = frame["source_row"].to_numpy()
    assert np.all(np.diff(rows) > 0)


def test_subsample_thins_rows_when_one_curve_is_too_many(tmp_path):
    from pamid._data._bench import load_bench
    from pamid._diagnose._api import subsample_curves

    bench = load_bench(_sweeps(tmp_path, 200, 1))  # 10 curves of 200 rows
    sub, note = subsample_curves(bench, 50)
    assert len(sub.frame) <= 50
    # every setting (here every curve) kept, each thinned alike
    assert note == "one row in 40 of 10 of 10 curves, evenly spread over settings and time"


def test_cli_max_rows_says_so_in_json_and_report(tmp_path, capsys):
    from pamid import InjectedHysteresis

    path = _sweeps(tmp_path, 40, 10, effects=(InjectedHysteresis(N_at_3_bar=9.0),))
    out = tmp_path / "diag"
    assert main(["diagnose", str(path), "--max-rows", "1200", "--json", "--out",
                 str(out)]) == 0
    captured = capsys.readouterr()
    obj = json.loads(captured.out)
    assert obj["rows_total"] == 4000
    assert obj["rows_used"] == obj["n"] <= 1200
    assert obj["subsample"].startswith("30 of 100 whole curves")
    assert obj["selected"][0] == "hysteresis"
    assert "diagnosing 1200 of 4000 rows" in captured.err
    report = (out / "report.txt").read_text()
    assert "subsample (--max-rows): 1200 of the file's 4000 rows diagnosed" in report


def test_cli_max_rows_must_be_positive(tmp_path, capsys):
    path = _sweeps(tmp_path, 10, 1)
    assert main(["diagnose", str(path), "--max-rows", "0"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line == "pamid: error: --max-rows must be at least 1, not 0"


# -- a model file that ends the program ------------------------------------------------------

_MODEL = '''
import sys
import pamid

CALLS = []


class Quadratic(pamid.ForceModel):
    c0: float = 0.0
    c1: float = 1.0
    units = {"c0": "N", "c1": "N/kPa"}
    inputs = ("pressure_kPa", "contraction_pct")

    def __call__(self, pressure_kPa, contraction_pct):
        CALLS.append(1)
        if len(CALLS) > EXIT_AFTER:
            sys.exit(0)
        return self.c0 + self.c1 * pressure_kPa
'''


@pytest.mark.parametrize(("tail", "says"), [
    ("EXIT_AFTER = 0\nsys.exit(0)", "the model file failed to run: it ended the program"),
    ("EXIT_AFTER = 0", "Quadratic.__call__ failed on test inputs (SystemExit: 0)"),
    ("EXIT_AFTER = 1", "user code ended the program (SystemExit: 0) while pamid ran it"),
])
def test_a_model_file_that_exits_is_a_failure_of_that_file(bench_csv, tmp_path, capsys, tail,
                                                           says):
    """A --model file that called sys.exit(0) at import (or in its model, at the first call
    or a later one) ended pamid with exit 0 and nothing on stdout or stderr, even with
    --json."""
    path = tmp_path / "exits.py"
    text = _MODEL + tail + "\n"
    path.write_text(text)
    at = [k + 1 for k, line in enumerate(text.splitlines()) if "sys.exit(0)" in line]
    code = main(["fit", str(bench_csv), "--model", f"{path}:Quadratic", "--json",
                 "--intervals", "wald"])
    captured = capsys.readouterr()
    assert code == 2 and captured.out == ""
    line = _one_line(captured.err)
    lineno = at[-1] if "sys.exit" in tail else at[0]
    assert line.startswith(f"pamid: error: {path}, line {lineno}: ") and says in line, line


# -- forces at the edge of float64 -------------------------------------------------------------


def test_diagnose_of_forces_near_1e302_says_no_finite_fit_as_fit_does(bench_csv, tmp_path,
                                                                     capsys):
    """`pamid diagnose` ended in exit 3 (OverflowError, choosing an effect's grid value on
    the baseline's residual) where `pamid fit` says "no finite fit" (exit 1): the baseline
    is checked before anything is built on it."""
    import pandas as pd

    frame = pd.read_csv(bench_csv)
    frame["force_N"] *= 1e300
    path = tmp_path / "huge.csv"
    frame.to_csv(path, index=False)
    assert main(["fit", str(path), "--intervals", "wald", "--json"]) == 1
    fitted = json.loads(capsys.readouterr().out)["muscles"][0]["message"]
    assert fitted.startswith("no finite fit")
    assert main(["diagnose", str(path), "--json"]) == 1
    captured = capsys.readouterr()
    line = _one_line(captured.err)
    assert "is not trustworthy (no finite fit" in line and str(path) in line
    assert json.loads(captured.out)["status"] == "not_trustworthy"


def test_diagnose_of_a_model_with_nan_derivatives_names_the_model(bench_csv, tmp_path, capsys):
    """A model whose value is finite but whose derivatives are NaN (0·sqrt(|x|) at 0) ended
    `pamid diagnose` with "SVD did not converge in Linear Least Squares" (exit 2), naming
    neither the model nor its file."""
    path = tmp_path / "nan_grad.py"
    path.write_text('''
import jax.numpy as jnp
import pamid


class NanGrad(pamid.ForceModel):
    c0: float = 0.0
    c1: float = 1.0
    c2: float = -10.0
    units = {"c0": "N", "c1": "N/kPa", "c2": "N/%"}
    inputs = ("pressure_kPa", "contraction_pct")

    def __call__(self, pressure_kPa, contraction_pct):
        f = self.c0 + self.c1 * pressure_kPa + self.c2 * contraction_pct
        return f + 0.0 * jnp.sqrt(jnp.abs(self.c0 - self.c0))
''')
    assert main(["diagnose", str(bench_csv), "--model", f"{path}:NanGrad"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "SVD" not in line and str(bench_csv) in line
    assert "no finite fit: NanGrad (user model) has NaN or ±inf derivatives" in line


# -- the command line names its options, not the library's parameters ---------------------------


@pytest.mark.parametrize(("censored", "options", "says"), [
    (6, ["--intervals", "wald", "--json"],
     "pamid: warning: {path}: dropped 6 censored rows (force_N exactly 0) out of 300; pass "
     "--keep-censored to keep them"),
    (300, [], "pass --keep-censored to keep them"),
    (0, ["--bootstrap", "1"], "pamid: error: --bootstrap must be at least 2"),
    (0, ["--method", "mcmc", "--walkers", "3"], "pamid: error: --walkers must be even"),
])
def test_messages_name_the_commands_options(bench_csv, tmp_path, capsys, censored, options,
                                            says):
    """The command line said "pass keep_censored=True to keep them" and "n_boot must be at
    least 2": the library's parameters, not the options that set them."""
    import pandas as pd

    frame = pd.read_csv(bench_csv)
    frame.loc[frame.index < censored, "force_N"] = 0.0
    path = tmp_path / "bench.csv"
    frame.to_csv(path, index=False)
    main(["fit", str(path), *options])
    err = capsys.readouterr().err
    assert says.format(path=path).lower() in err.lower(), err
    assert "keep_censored" not in err and "n_boot" not in err and "n_walkers" not in err


# -- a compilation cache that cannot be written -------------------------------------------------


@pytest.fixture
def unwritable_folder(tmp_path):
    """A folder in which no file can be made, for this user."""
    if os.geteuid() == 0:  # root writes into a folder of mode 0500
        yield "/proc/self"  # it exists, and no file can be made in it
        return
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o500)
    yield folder
    folder.chmod(0o700)


def test_a_cache_that_cannot_be_written_is_said_once(unwritable_folder):
    """A read-only PAMID_CACHE_DIR gave one JAX warning ("Error writing persistent
    compilation cache entry for 'jit_add'") per program compiled: 40 for
    `simulate lifting-mass`."""
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "PAMID_CACHE_DIR": str(unwritable_folder)}
    res = subprocess.run([sys.executable, "-m", "pamid._cli", "simulate", "lifting-mass",
                          "--pressure-kPa", "400", "--mass-kg", "50", "--x0-mm", "50", "--json"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["x0_mm"] == 50
    assert res.stderr.splitlines() == [
        f"pamid: warning: the compilation cache PAMID_CACHE_DIR {unwritable_folder} cannot be "
        f"written ({'No such file or directory' if os.geteuid() == 0 else 'Permission denied'}"
        "): every program is compiled anew and none is kept for the next run"]
