"""The package's shape (issue 35): its modules import each other without a cycle, lazy
imports inside functions counted (only ``TYPE_CHECKING`` blocks and the package
``__init__`` files, which gather the names, are left out), and no module of the package
or file of ``cpp/src/alignment`` outgrows the sizes a reader can take in one sitting."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "python" / "spectral_vs"
MAX_PYTHON_LINES = 400
MAX_ALIGNMENT_LINES = 350


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    return ".".join(("spectral_vs", *parts))


def imports_of(path: Path) -> set[str]:
    """The modules of the package that `path` imports anywhere, TYPE_CHECKING aside."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skipped.update(id(child) for child in ast.walk(node))
    found = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return found


def module_graph() -> dict[str, set[str]]:
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py") if p.name != "__init__.py"}
    return {name: imports_of(path) & set(modules) - {name} for name, path in modules.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph, as the modules along it, or None (depth-first search)."""
    state: dict[str, int] = {}  # 1: on the path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                return [*path[path.index(target) :], target]
            if target not in state and (cycle := visit(target)):
                return cycle
        state[node] = 2
        path.pop()
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_the_cycle_finder_finds_a_cycle_and_only_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_the_package_modules_import_each_other_without_a_cycle():
    graph = module_graph()
    assert "spectral_vs.clouds" in graph["spectral_vs.interop"]  # the graph sees imports
    assert find_cycle(graph) is None, " -> ".join(find_cycle(graph) or [])


def test_no_module_outgrows_its_size():
    long_python = {
        str(p.relative_to(ROOT)): n
        for p in PACKAGE.rglob("*.py")
        if (n := len(p.read_text(encoding="utf-8").splitlines())) >= MAX_PYTHON_LINES
    }
    assert not long_python, f"Python modules of {MAX_PYTHON_LINES} lines or more: {long_python}"
    alignment = ROOT / "cpp" / "src" / "alignment"
    long_cpp = {
        p.name: n
        for p in alignment.iterdir()
        if p.suffix in (".cpp", ".hpp")
        and (n := len(p.read_text(encoding="utf-8").splitlines())) >= MAX_ALIGNMENT_LINES
    }
    assert not long_cpp, (
        f"cpp/src/alignment files of {MAX_ALIGNMENT_LINES} lines or more: {long_cpp}"
    )
