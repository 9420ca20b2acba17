"""The public API is one list (``pamid._EXPORTS``): ``__all__``, ``dir(pamid)`` and the
type-checking imports agree with it, every name resolves, the namespaces (``pamid.sarosi``,
``cullinan``, ``io``, ``report`` and the low-level tier ``pamid.engine``) list exactly what
they define and it resolves, the names that moved still work with a DeprecationWarning,
and the scripts beside the package (experiments/, benchmarks/, notebooks/) import nothing
private, not even inside a function: no exceptions."""

from __future__ import annotations

import ast
import importlib
import json
import re
import sys
import warnings
from pathlib import Path

import pytest

import pamid

ROOT = Path(__file__).resolve().parents[1]
NAMESPACES = ("sarosi", "cullinan", "io", "report", "engine")


def _stub_imports() -> dict[str, tuple[str, str | None]]:
    """public name -> (module, attribute) of the ``if TYPE_CHECKING:`` imports of
    pamid/__init__.py, read from its source."""
    tree = ast.parse((ROOT / "pamid" / "__init__.py").read_text(encoding="utf-8"))
    blocks = [n for n in tree.body if isinstance(n, ast.If)
              and isinstance(n.test, ast.Name) and n.test.id == "TYPE_CHECKING"]
    assert len(blocks) == 1
    out = {}
    for node in blocks[0].body:
        assert isinstance(node, ast.ImportFrom) and node.level == 1, ast.dump(node)
        for alias in node.names:
            public = alias.asname or alias.name
            assert public not in out, f"{public} imported twice"
            if node.module is None:  # ``from . import sarosi as sarosi``: a namespace
                out[public] = (f".{alias.name}", None)
            else:
                out[public] = (f".{node.module}", alias.name)
    return out


def _expected_stubs() -> str:
    """The block the stubs should be, for the failure message."""
    lines = []
    for name, (module, attr) in sorted(pamid._EXPORTS.items()):
        lines.append(f"    from . import {module[1:]} as {name}" if attr is None
                     else f"    from {module} import {attr} as {name}")
    return "\n".join(lines)


def test_all_is_the_one_list():
    assert pamid.__all__ == sorted(pamid._EXPORTS)
    assert len(set(pamid.__all__)) == len(pamid.__all__)


def test_type_checking_imports_are_the_one_list():
    assert _stub_imports() == pamid._EXPORTS, (
        "the TYPE_CHECKING imports of pamid/__init__.py differ from _EXPORTS; they should "
        "read (ruff sorts them):\n" + _expected_stubs())


def test_dir_shows_exactly_the_curated_names():
    for name in ("fit_least_squares", "sarosi", "ForceModel"):
        getattr(pamid, name)  # loading modules must not add names to dir()
    shown = {n for n in dir(pamid) if not (n.startswith("__") and n.endswith("__"))}
    assert shown == set(pamid.__all__)


def test_no_public_name_is_private():
    assert [n for n in pamid.__all__ if n.startswith("_")] == []
    for ns in NAMESPACES:
        module = getattr(pamid, ns)
        assert [n for n in module.__all__ if n.startswith("_")] == [], ns


@pytest.mark.parametrize("name", sorted(pamid._EXPORTS))
def test_every_public_name_resolves(name):
    module, attr = pamid._EXPORTS[name]
    target = importlib.import_module(module, "pamid")
    if attr is not None:
        target = getattr(target, attr)
    assert getattr(pamid, name) is target


@pytest.mark.parametrize("ns", NAMESPACES)
def test_namespace_all_resolves(ns):
    module = importlib.import_module(f"pamid.{ns}")
    assert getattr(pamid, ns) is module
    assert len(module.__all__) == len(set(module.__all__))
    missing = [n for n in module.__all__ if not hasattr(module, n)]
    assert missing == []
    # Everything the namespace defines publicly is listed (an import left out of __all__
    # would be public by accident).
    public = {n for n, v in vars(module).items()
              if not n.startswith("_") and not isinstance(v, type(sys))}
    assert public == set(module.__all__)


def test_models_in_both_tiers_are_one_object():
    assert pamid.Sarosi is pamid.sarosi.Sarosi
    assert pamid.Cullinan is pamid.cullinan.Cullinan
    assert pamid.PamVolume is pamid.cullinan.PamVolume
    assert pamid.SlidingModeController is pamid.sarosi.SlidingModeController


def test_engine_lists_the_model_registry():
    names = pamid.engine.model_names()
    assert names[:2] == ("sarosi", "cullinan") and len(set(names)) == len(names)
    for name in names:
        assert pamid.engine.get_model(name).name == name


@pytest.mark.parametrize("name", sorted(pamid._MOVED))
def test_moved_names_warn_and_resolve(name):
    place = pamid._MOVED[name]
    assert name not in pamid.__all__ and name not in dir(pamid)
    with pytest.warns(DeprecationWarning, match=rf"pamid\.{name} is deprecated"):
        value = getattr(pamid, name)
    assert value is getattr(importlib.import_module(place), name)
    if not place.startswith("pamid._"):
        assert name in importlib.import_module(place).__all__


def test_moved_warning_names_the_new_place():
    with pytest.warns(DeprecationWarning, match=r"use pamid\.sarosi\.TABLE_3_1"):
        table = pamid.TABLE_3_1
    assert table is pamid.sarosi.TABLE_3_1
    with pytest.warns(DeprecationWarning, match=r"use pamid\.cullinan\.joint_torque_eq6_Nm"):
        pamid.joint_torque_eq6_Nm  # noqa: B018


def test_unknown_name_is_an_attribute_error():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(AttributeError, match="no attribute 'fit_least_square'"):
            pamid.fit_least_square  # noqa: B018
        assert not hasattr(pamid, "_not_there")


def test_import_is_lazy_and_float64(fresh_python):
    # `import pamid` imports neither its packages nor JAX (the command line reads its file
    # while JAX starts on another thread); JAX imported after it, or before, has float64.
    modules, jax_loaded, x64, dtype = fresh_python(
        "import sys, json, pamid; j = 'jax' in sys.modules; import jax, jax.numpy as jnp; "
        "print(json.dumps([sorted(m for m in sys.modules if m.startswith('pamid')), j, "
        "jax.config.jax_enable_x64, str(jnp.asarray(1.0).dtype)]))")
    assert modules == ["pamid"]
    assert jax_loaded is False
    assert x64 is True and dtype == "float64"
    assert fresh_python("import json, jax, pamid, jax.numpy as jnp; "
                        "print(json.dumps(str(jnp.asarray(1.0).dtype)))") == "float64"


def test_the_reader_does_not_import_pandas_and_the_frame_does(fresh_python, tmp_path):
    # `pamid fit` reads its file into NumPy columns (pamid._data._columns) and converts
    # pyarrow's arrays by their buffers (pamid._arrow: pyarrow's own conversions import
    # pandas): importing pandas is 0.2 s of a warm one-muscle fit. The frame, asked for,
    # is pandas' and holds what the file says.
    path = tmp_path / "b.csv"
    path.write_text("muscle,trial,pressure_kPa,contraction_pct,force_N,temperature_C,who\n"
                    "A,t1,300,1.0,100.5,,ann\nA,t1,300,2.0,90.25,21,bob\n"
                    "B,t1,400,1.0,150.0,22,ann\n")
    before, after, rows, frame_pandas, muscles, who, codes = fresh_python(
        "import sys, json, warnings; from pamid._data._bench import load_bench; "
        "warnings.simplefilter('ignore'); "
        "b = 'pandas' in sys.modules; "
        f"bench = load_bench(r'{path}'); a = 'pandas' in sys.modules; n = len(bench); "
        "f = bench.frame; "
        "print(json.dumps([b, a, n, 'pandas' in sys.modules, f['muscle'].tolist(), "
        "f['who'].tolist(), bench.muscle_codes.tolist()]))")
    assert (before, after, rows, frame_pandas) == (False, False, 3, True)
    assert muscles == ["A", "A", "B"] and who == ["ann", "bob", "ann"] and codes == [0, 0, 1]


PRIVATE_IMPORT = re.compile(r"^\s*(from\s+pamid\._|import\s+pamid\._|from\s+pamid\s+import\s+_)",
                            re.MULTILINE)


def _sources():
    for folder in ("experiments", "benchmarks", "notebooks"):
        for path in sorted((ROOT / folder).glob("*")):
            if path.suffix == ".py":
                yield path, path.read_text(encoding="utf-8")
            elif path.suffix == ".ipynb":
                cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
                yield path, "\n".join("".join(c["source"]) for c in cells
                                      if c["cell_type"] == "code")


def test_private_import_pattern():
    assert PRIVATE_IMPORT.search("import numpy\n    from pamid._fit import _spec\n")
    assert PRIVATE_IMPORT.search("import pamid._data._bench as bench")
    assert PRIVATE_IMPORT.search("from pamid import _io")
    assert not PRIVATE_IMPORT.search("import pamid\nfrom pamid import sarosi\n# pamid._fit\n")


def test_scripts_beside_the_package_import_nothing_private():
    sources = dict(_sources())
    assert len(sources) > 10  # the scan sees the scripts
    found = sorted(f"{p.relative_to(ROOT)}: {text[m.start():].splitlines()[0].strip()}"
                   for p, text in sources.items() for m in PRIVATE_IMPORT.finditer(text))
    # Their public counterparts: the flat API, pamid.io, pamid.report, and pamid.engine for
    # the registry, the solver, starts, intervals and sampler pieces.
    assert found == []
