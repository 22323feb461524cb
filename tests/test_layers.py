"""The package's architecture holds: no import cycle (imports inside functions included; those
for type checkers only, under ``TYPE_CHECKING``, are not imports at run time), the layers of
pyproject.toml's import-linter contract, each importing only those below it; no two public
classes or functions of one name; no module over 600 lines, the public API module at most
400."""

from __future__ import annotations

import ast
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parents[1]
#: Imports of the package itself are its version and its compiled core (``vo3d_opt._core``,
#: an extension module the graph cannot see, so it names the package instead): no edge.
ROOT_PACKAGE = "vo3d_opt"


def cycles(graph: grimp.ImportGraph) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.find_modules_directly_imported_by(v) - {ROOT_PACKAGE}:
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

    for module in sorted(graph.modules):
        if module not in index:
            visit(module)
    return found


def test_no_import_cycle() -> None:
    # imports for type checkers only (under TYPE_CHECKING) never run
    graph = grimp.build_graph(
        "vo3d_opt", include_external_packages=False, exclude_type_checking_imports=True
    )
    assert len(graph.modules) > 40
    assert cycles(graph) == []


def test_cycles_are_found() -> None:
    """The check itself: a graph with a cycle through an import inside a function."""
    graph = grimp.ImportGraph()
    for a, b in (("p.a", "p.b"), ("p.b", "p.c"), ("p.c", "p.a"), ("p.c", "p.d")):
        graph.add_import(importer=a, imported=b)
    assert cycles(graph) == [["p.a", "p.b", "p.c"]]


def test_the_layers_contract_is_kept() -> None:
    lint = Path(sys.executable).with_name("lint-imports")
    res = subprocess.run([str(lint)], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout[-2000:]
    assert "1 kept, 0 broken" in res.stdout


def public_definitions(package: Path) -> dict[str, list[str]]:
    """Each public top-level class and function name of ``package``: the modules defining it."""
    found: dict[str, list[str]] = defaultdict(list)
    for path in sorted(package.rglob("*.py")):
        module = ".".join(path.relative_to(package.parent).with_suffix("").parts)
        for node in ast.parse(path.read_text()).body:
            kinds = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)
            if isinstance(node, kinds) and not node.name.startswith("_"):
                found[node.name].append(module)
    return found


def test_no_two_public_classes_or_functions_share_a_name() -> None:
    shared = {k: v for k, v in public_definitions(ROOT / "vo3d_opt").items() if len(v) > 1}
    assert shared == {}


def test_the_check_finds_a_shared_name(tmp_path: Path) -> None:
    (tmp_path / "p" / "q").mkdir(parents=True)
    (tmp_path / "p" / "a.py").write_text("def select():\n    pass\n\n\ndef _helper():\n    pass\n")
    (tmp_path / "p" / "q" / "b.py").write_text("class select:\n    pass\n\n\ndef _helper():\n    pass\n")
    found = public_definitions(tmp_path / "p")
    assert found == {"select": ["p.a", "p.q.b"]}


def test_no_module_is_over_600_lines_and_the_api_module_over_400() -> None:
    lines = {p: len(p.read_text().splitlines()) for p in (ROOT / "vo3d_opt").rglob("*.py")}
    assert {str(p.relative_to(ROOT)): n for p, n in lines.items() if n > 600} == {}
    assert lines[ROOT / "vo3d_opt" / "selector.py"] <= 400
