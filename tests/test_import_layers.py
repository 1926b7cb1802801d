"""The package's imports run one way: no cycles among its modules, no library module importing a stage, and (one
known exception, named here) no harness module importing a method's package. Read from the source with `ast`;
imports under `if TYPE_CHECKING:` are type hints, not dependencies, and are left out."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

SRC = Path(__file__).resolve().parents[1] / "src"
ENTRY = (
    "stafpipe.stages",
    "stafpipe.cli",
    "stafpipe.launch",
    "stafpipe.pipeline",
    "stafpipe.compare",
    "stafpipe.__main__",
)
"""The command line and the stages: the only modules that may import a stage."""
KNOWN_METHOD_IMPORTS = {("stafpipe.learning.config", "stafpipe.methods.staf.subteaming")}
"""The training config holds `method=staf`'s rule settings as a field of its own (`train_ppo.subteaming`); it goes
when methods register their configs (the one-registry work of docs/architecture.md)."""


def _modules() -> dict[str, Path]:
    out = {}
    for path in (SRC / "stafpipe").rglob("*.py"):
        parts = path.relative_to(SRC).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _graph() -> set[tuple[str, str]]:
    modules = _modules()

    def known(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    edges = set()
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        hints = {
            id(n)
            for node in ast.walk(tree)
            if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING"
            for stmt in node.body
            for n in ast.walk(stmt)
        }
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(tree):
            if id(node) in hints:
                continue
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                targets = [base, *(f"{base}.{a.name}" for a in node.names)]
            else:
                continue
            for target in targets:
                found = known(target) if target.startswith("stafpipe") else None
                if found and found != name:
                    edges.add((name, found))
    return edges


def test_imports_have_no_cycles() -> None:
    edges = _graph()
    names = sorted({m for e in edges for m in e})
    index = {m: k for k, m in enumerate(names)}
    rows, cols = zip(*((index[a], index[b]) for a, b in edges), strict=True)
    matrix = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(names), len(names)))
    _, labels = connected_components(matrix, directed=True, connection="strong")
    cycles = [sorted(n for n, k in zip(names, labels, strict=True) if k == c) for c in set(labels)]
    assert [c for c in cycles if len(c) > 1] == []


def test_no_library_module_imports_a_stage() -> None:
    wrong = [(a, b) for a, b in _graph() if b.startswith("stafpipe.stages") and not a.startswith(ENTRY)]
    assert wrong == []


def test_the_harness_imports_no_method_package_but_the_one_named() -> None:
    wrong = {(a, b) for a, b in _graph() if b.startswith("stafpipe.methods") and not a.startswith("stafpipe.methods")}
    assert wrong == KNOWN_METHOD_IMPORTS


def test_the_graph_sees_imports_inside_functions() -> None:
    """An import inside a function (STAF's adapter loads the deep graph cut when it is built) is an edge too, and a
    type-only import under TYPE_CHECKING is not."""
    edges = _graph()
    assert ("stafpipe.methods.staf.adapter", "stafpipe.highlevel.checkpoint") in edges
    assert ("stafpipe.registry", "stafpipe.learning.adapters") not in edges
    assert len(edges) > 200
