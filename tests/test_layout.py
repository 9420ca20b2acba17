"""The package layout (docs/architecture.md): the import graph of pamid's own modules, read
from their source, has no cycle, and no module imports a private name (one starting with an
underscore) from another package.

A package is ``pamid._x`` (a folder) or a top-level module such as ``pamid._io``. Every
``import`` counts, those inside functions too: a lazy import postpones the cost of a module,
not the dependency. ``pamid/__init__.py``, the public facade that imports every package
lazily, is left out of the graph (no package imports it at module level: see the last test).
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pamid"


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _package(module: str) -> str:
    """``pamid._fit._api`` → ``pamid._fit``; ``pamid._io`` → ``pamid._io``."""
    parts = module.split(".")
    return ".".join(parts[:2])


def _imports():
    """(importing module, imported module, name or None, line, at module level) for every
    import of a pamid module in pamid's source."""
    for module, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        base = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        top_level = set(map(id, tree.body))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    target = ".".join(base[: len(base) - node.level + 1]
                                      + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if target != "pamid" and not target.startswith("pamid."):
                    continue
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in MODULES:  # ``from pamid._data import _bench``: a module
                        yield module, sub, None, node.lineno, id(node) in top_level
                    else:
                        yield module, target, alias.name, node.lineno, id(node) in top_level
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name == "pamid" or alias.name.startswith("pamid."):
                        yield module, alias.name, None, node.lineno, id(node) in top_level


IMPORTS = list(_imports())


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def test_the_graph_is_read():
    # The parser finds what is known to be there (a guard against a test that sees nothing).
    assert "pamid._fit._api" in MODULES and "pamid._data._curves" in MODULES
    assert any(src == "pamid._fit._api" and dst.startswith("pamid._data")
               for src, dst, *_ in IMPORTS)
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]


def test_no_cycle_between_packages():
    edges = defaultdict(set)
    for src, dst, *_ in IMPORTS:
        if src != "pamid" and dst != "pamid" and _package(src) != _package(dst):
            edges[_package(src)].add(_package(dst))
    assert _cycles(edges) == []


def test_no_cycle_between_modules():
    edges = defaultdict(set)
    for src, dst, *_ in IMPORTS:
        if src != "pamid" and dst != "pamid" and src != dst and dst in MODULES:
            edges[src].add(dst)
    assert _cycles(edges) == []


def test_no_private_name_across_packages():
    bad = [f"{MODULES[src].relative_to(PACKAGE.parent)}:{line} imports {dst}.{name}"
           for src, dst, name, line, _ in IMPORTS
           if name is not None and name.startswith("_") and not name.startswith("__")
           and _package(src) != _package(dst)]
    assert bad == []


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m != "pamid"))
def test_no_module_imports_the_facade_at_import_time(module):
    # ``import pamid`` must stay cheap and acyclic: a private module reaches the public
    # facade only inside a function (the command line's use of public names).
    eager = [line for src, dst, _, line, top in IMPORTS if src == module and dst == "pamid" and top]
    assert eager == []


#: Runtime dependencies that pamid uses through another package, not by an import of its own.
USED_THROUGH = {
    "jaxlib": "jax's backend",
    "flatbuffers": "jax.export's serialization (the CLI's cache of traced programs)",
    "h5netcdf": "xarray's NetCDF-4 engine, found by name (pamid/_report/_mcmc.py)",
    "h5py": "h5netcdf's",
}


def test_every_runtime_dependency_is_used_by_the_package():
    """diffrax was a dependency of every installation, while only
    benchmarks/simulate_batch.py imported it (now the ``benchmarks`` extra)."""
    import re
    import tomllib

    project = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())["project"]
    imported = set()
    for path in MODULES.values():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                imported |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
                imported.add(node.module.split(".")[0])
    for requirement in project["dependencies"]:
        name = re.match(r"[A-Za-z0-9_.-]+", requirement).group().lower()
        assert name.replace("-", "_") in imported or name in USED_THROUGH, name
    assert any(r.startswith("diffrax") for r in project["optional-dependencies"]["benchmarks"])


def test_the_architecture_page_matches_the_tree():
    """docs/architecture.md names every private package of the tree in its table, and every
    file or folder of pamid it names exists (a moved module moves its line too)."""
    import re

    doc = (PACKAGE.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    folders = sorted(p.name for p in PACKAGE.iterdir()
                     if p.is_dir() and p.name.startswith("_") and (p / "__init__.py").exists())
    assert "_solvers" in folders
    rows = [line for line in doc.splitlines() if line.startswith("| `pamid/")]
    assert [f for f in folders if not any(f"`pamid/{f}/`" in r.split(" | ")[0] for r in rows)] == []
    named = set(re.findall(r"pamid/[A-Za-z0-9_/]+(?:\.py)?", doc))
    assert "pamid/_solvers/" in named
    assert [p for p in sorted(named) if not (PACKAGE.parent / p).exists()] == []
    # A module named bare in a package's row (`_sarosi.py`) is a file of that package (or a
    # top-level module the row also holds, `_cli.py`).
    for row in re.findall(r"^\| `pamid/(_[a-z]+)/`[^|]*\|(.*)$", doc, flags=re.M):
        folder, text = row
        missing = [m for m in re.findall(r"`(_[a-z_]+\.py)`", text)
                   if not (PACKAGE / folder / m).exists() and not (PACKAGE / m).exists()]
        assert missing == [], (folder, missing)
