"""No import cycle between osnerf's modules: each module's module-level imports (those that
run when it is imported; not those inside functions or under ``if TYPE_CHECKING``), read
with ``ast``, form a graph without cycles."""

from __future__ import annotations

import ast
from pathlib import Path

import osnerf.run

PACKAGE = "osnerf"


def _modules(root: Path, package: str) -> dict[str, Path]:
    """Module name -> file, for every .py under ``root`` (packages as their __init__)."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = [package, *path.relative_to(root).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _module_level(body: list[ast.stmt]):
    """The import statements that run at import time (class bodies included, functions and
    ``if TYPE_CHECKING:`` blocks not)."""
    for node in body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, ast.If):
            test = ast.unparse(node.test)
            if test not in ("TYPE_CHECKING", "typing.TYPE_CHECKING"):
                yield from _module_level(node.body)
            yield from _module_level(node.orelse)
        elif isinstance(node, ast.Try):
            for block in (node.body, node.orelse, node.finalbody, *(h.body for h in node.handlers)):
                yield from _module_level(block)
        elif isinstance(node, (ast.With, ast.ClassDef)):
            yield from _module_level(node.body)


def _ancestors(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:k]) for k in range(1, len(parts))]


def import_graph(root: Path, package: str = PACKAGE) -> dict[str, set[str]]:
    """Module -> the package's modules its module-level imports execute. Importing
    ``a.b.c`` also runs the packages ``a`` and ``a.b`` (edges to them), except the
    importer's own packages, which are already being imported when it runs."""
    mods = _modules(root, package)
    graph = {}
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        targets = set()
        for node in _module_level(ast.parse(path.read_text()).body):
            if isinstance(node, ast.Import):
                targets.update(a.name for a in node.names)
                continue
            base = node.module or ""
            if node.level:  # relative: from the importer's package
                pkg = name.split(".") if is_pkg else name.split(".")[:-1]
                pkg = pkg[: len(pkg) - (node.level - 1)]
                base = ".".join(pkg + ([base] if base else []))
            for a in node.names:
                sub = f"{base}.{a.name}"
                targets.add(sub if sub in mods else base)
        own = set(_ancestors(name))
        edges = set()
        for t in targets:
            while t and t not in mods and "." in t:  # ``import a.b.attr``-like: its module
                t = t.rsplit(".", 1)[0]
            if t in mods:
                edges.add(t)
                edges.update(a for a in _ancestors(t) if a in mods and a not in own)
        graph[name] = edges - {name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as [m0, m1, ..., m0], or None."""
    state, stack = {}, []

    def visit(m):
        state[m] = "open"
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == "open":
                return stack[stack.index(t) :] + [t]
            if t not in state and (c := visit(t)):
                return c
        state[m] = "done"
        stack.pop()
        return None

    for m in sorted(graph):
        if m not in state and (c := visit(m)):
            return c
    return None


def test_find_cycle_finds_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_graph_counts_packages_run_on_import(tmp_path):
    """``from p.sub import x`` runs ``p/__init__``: a cycle through it is one."""
    (tmp_path / "p").mkdir()
    (tmp_path / "__init__.py").write_text("")
    (tmp_path / "p" / "__init__.py").write_text("from pkg.p.sub import x\n")
    (tmp_path / "p" / "sub.py").write_text("from pkg.q import y\nx = 1\n")
    (tmp_path / "q.py").write_text("from pkg.p.sub import x\ny = 2\n")
    graph = import_graph(tmp_path, "pkg")
    assert graph["pkg.q"] == {"pkg.p", "pkg.p.sub"}
    assert find_cycle(graph) is not None


def test_osnerf_has_no_import_cycle():
    assert "__getattr__" not in vars(osnerf.run)  # no lazy attribute hiding an import
    graph = import_graph(Path(osnerf.__file__).parent)
    assert "osnerf.run.jscc" in graph and "osnerf.schemes" not in graph["osnerf.run.jscc"]
    cycle = find_cycle(graph)
    assert cycle is None, " -> ".join(cycle)
