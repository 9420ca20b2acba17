"""Result objects hold results; ``pamid.report`` writes them (text, files, figures).

The namespace's names resolve and are functions that take the result first; the result
classes carry no writing methods (only ``to_dict()``, their plain-data view); a figure
without a path is returned and nothing is written, with a path it is written atomically;
the fit's figures and JSON written through ``pamid.report`` are what ``pamid fit --out``
writes."""

from __future__ import annotations

import inspect
import json
from pathlib import Path

import pytest

import pamid
import pamid.report

ROOT = Path(__file__).resolve().parents[1]
RESULT_CLASSES = ("FitResult", "McmcResult", "Diagnosis", "Comparison")
WRITING = ("plot_", "save_", "write_")


def test_every_report_name_resolves_to_a_function_taking_the_result_first():
    names = pamid.report.__all__
    assert len(names) == len(set(names)) and names
    assert [n for n in names if n.startswith("_")] == []
    for name in names:
        fn = getattr(pamid.report, name)
        assert inspect.isfunction(fn), name
        first = next(iter(inspect.signature(fn).parameters))
        assert first in ("result", "d"), (name, first)
        assert fn.__doc__ and len(fn.__doc__) > 60, f"{name} needs a docstring"


def test_the_namespace_lists_everything_it_defines():
    public = {n for n, v in vars(pamid.report).items()
              if not n.startswith("_") and not inspect.ismodule(v)}
    assert public == set(pamid.report.__all__)


#: Results of the decay workflows: no writing methods either (a decay posterior's figure is
#: ``pamid.report.plot_decay_predictive``); not all of them have a ``to_dict()``.
DECAY_RESULT_CLASSES = ("DecayPosterior", "DecayPredictive", "DecayReport", "DecayModelFit",
                        "JointDecayFit", "TrajectoryFit")


def _writing_methods(klass) -> list[str]:
    return sorted(n for n in dir(klass) if n.startswith(WRITING) or n in ("to_json", "report"))


@pytest.mark.parametrize("cls", RESULT_CLASSES)
def test_result_classes_hold_results_only(cls):
    klass = getattr(pamid, cls)
    assert _writing_methods(klass) == []
    assert callable(klass.to_dict)
    assert "plain" in klass.to_dict.__doc__  # says it is the plain-data view


@pytest.mark.parametrize("cls", DECAY_RESULT_CLASSES)
def test_decay_result_classes_hold_results_only(cls):
    assert _writing_methods(getattr(pamid, cls)) == []


def test_importing_report_loads_no_plotting_library(fresh_python):
    assert fresh_python("import sys, json, pamid.report; "
                        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
                        "('matplotlib', 'arviz'))))") == []


@pytest.fixture(scope="module")
def fit(small_bench):
    return pamid.fit_least_squares(small_bench.bench)


def test_fit_figures_are_returned_without_a_path_and_written_with_one(fit, small_bench,
                                                                       tmp_path):
    from matplotlib.figure import Figure

    fig = pamid.report.plot_fit(fit, small_bench.bench, 1)
    assert isinstance(fig, Figure) and list(tmp_path.iterdir()) == []
    assert "fit —" in fig.get_suptitle()
    fig = pamid.report.plot_residuals(fit, small_bench.bench, 1, tmp_path / "res.png",
                                      title="residuals of muscle 1")
    assert fig.get_suptitle().startswith("residuals of muscle 1")
    assert (tmp_path / "res.png").stat().st_size > 10_000
    assert [p.name for p in tmp_path.iterdir()] == ["res.png"]  # no temporary file left


def test_write_fit_plots_and_fit_json_are_what_the_command_writes(fit, small_bench, tmp_path):
    names = pamid.report.write_fit_plots(fit, small_bench.bench, tmp_path, max_plots=1)
    muscle = small_bench.bench.muscles[0]
    assert names == [f"fit_{muscle}.png", f"residuals_{muscle}.png", "rmse_histogram.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)
    text = pamid.report.fit_json(fit, source="small_bench.csv", plots=names)
    assert text == json.dumps({**fit.to_dict(), "source": "small_bench.csv", "plots": names})
