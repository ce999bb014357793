"""The import boundaries of the developers' guide, enforced by walking every import with ast."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
OURS = {"common", "phy", "semcodec", "renderer", "hil", "osnerf"}
# common (the one writer, image loader and PSNR) is a leaf that every package may import.
ALLOWED = {
    "common": set(),
    "phy": {"common"},
    "semcodec": {"common", "phy"},
    "renderer": {"common"},
    "hil": {"common", "phy"},
    "osnerf": {"common", "phy", "semcodec", "renderer", "hil"},
}
PUBLIC_ONLY = ("tests", "benchmarks", "campaign")


def _imports(path: Path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module
            for alias in node.names:
                yield node.lineno, f"{node.module}.{alias.name}"


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_package_imports_only_what_it_may(package):
    bad = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for lineno, name in _imports(path):
            top = name.split(".")[0]
            if top in OURS and top != package and top not in ALLOWED[package]:
                bad.append(f"{path.relative_to(ROOT)}:{lineno} imports {name}")
    assert not bad, (
        f"{package} may import only {sorted(ALLOWED[package]) or 'nothing of ours'}:\n"
        + "\n".join(bad)
    )


def _bound_in_init(package: str) -> set[str]:
    """Names a package's ``__init__`` binds to something other than one of its own modules:
    ``from phy.theory import ber_theory`` binds ``ber_theory``; ``from hil import protocol``
    (the module itself) binds nothing here."""
    init = ROOT.joinpath(*package.split("."), "__init__.py")
    names = set()
    for node in ast.parse(init.read_text()).body:
        if isinstance(node, ast.ImportFrom) and node.module and node.module != package:
            names.update(a.asname or a.name for a in node.names)
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    return names


def _module_of_another_package(name: str) -> bool:
    """``name`` is a module file inside one of our packages (``hil.emulation.air``), not the package
    or one of its subpackages (``phy.digital``), whose ``__init__`` is the public surface."""
    parts = name.split(".")
    path = ROOT.joinpath(*parts)
    if len(parts) == 1 or (path / "__init__.py").is_file():
        return False
    if not path.with_suffix(".py").is_file():
        return False
    # ``from renderer import train``: the package's function, which shadows its module
    return parts[-1] not in _bound_in_init(".".join(parts[:-1]))


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_packages_use_each_others_public_surface(package):
    """Another package is imported through its ``__init__`` (``from hil import Pluto``), never
    through one of its modules (``from hil.pluto.driver import Pluto``): the rest is private."""
    bad = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for lineno, name in _imports(path):
            top = name.split(".")[0]
            if top in OURS and top != package and _module_of_another_package(name):
                bad.append(f"{path.relative_to(ROOT)}:{lineno} imports {name}")
    assert not bad, "import these from the package itself:\n" + "\n".join(sorted(set(bad)))


@pytest.mark.parametrize("folder", PUBLIC_ONLY)
def test_tests_and_benchmarks_use_public_names(folder):
    """tests/ and benchmarks/ import our packages' public names, never private modules."""
    bad = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for lineno, name in _imports(path):
            parts = name.split(".")
            if parts[0] in OURS and any(
                p.startswith("_") and not p.startswith("__") for p in parts[1:]
            ):
                bad.append(f"{path.relative_to(ROOT)}:{lineno} imports private {name}")
    assert not bad, "\n".join(bad)


def test_checker_catches_a_forbidden_edge(tmp_path):
    """The walker itself must see an import of osnerf from phy."""
    f = tmp_path / "x.py"
    f.write_text("import numpy\nfrom osnerf.cli import main\nimport semcodec.jscc.model as m\n")
    names = [n for _, n in _imports(f)]
    assert "osnerf.cli" in names and "semcodec.jscc.model" in names


CYCLE_ROOTS = tuple(sorted(OURS)) + ("campaign", "benchmarks")


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _runtime_nodes(tree: ast.AST):
    """Every node of a module that runs, at import or in a function: ``if TYPE_CHECKING:``
    blocks are left out (they never import at run time)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if (
                isinstance(child, ast.If)
                and isinstance(child.test, ast.Name | ast.Attribute)
                and ast.unparse(child.test).endswith("TYPE_CHECKING")
            ):
                stack.extend(child.orelse)
                continue
            stack.append(child)


def import_graph(root: Path, tops=CYCLE_ROOTS) -> dict[str, set[str]]:
    """Module -> the modules of ours it imports, at module level and inside functions.

    ``from a.b import c`` is an edge to ``a.b.c`` when that is a module, else to ``a.b``, and to
    the packages above it whose ``__init__`` the import runs (all but the importer's own).
    """
    paths = {_module_name(p, root): p for top in tops for p in (root / top).rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in paths}
    for mod, path in paths.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in _runtime_nodes(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                targets = [
                    f"{base}.{a.name}" if f"{base}.{a.name}" in paths else base for a in node.names
                ]
            else:
                continue
            for target in targets:
                # importing a.b.c runs a's and a.b's __init__ first, unless they are the
                # importer's own ancestors (already running)
                parts = target.split(".")
                for k in range(1, len(parts) + 1):
                    name = ".".join(parts[:k])
                    if name in paths and name != mod and not mod.startswith(name + "."):
                        graph[mod].add(name)
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))
    return cycles


def test_no_import_circles_also_through_imports_inside_functions():
    """No circle between our modules, counting imports inside functions (a deferred import
    hides a circle from Python, not from a reader)."""
    cycles = import_cycles(import_graph(ROOT))
    assert not cycles, "import circles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_cycle_walker_sees_a_circle_hidden_in_a_function(tmp_path):
    pkg = tmp_path / "osnerf"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from osnerf.b import g\n")
    (pkg / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from osnerf import c\n"
        "def g():\n    from osnerf import a\n"
    )
    (pkg / "c.py").write_text("import osnerf.b\n")
    graph = import_graph(tmp_path, tops=("osnerf",))
    assert graph["osnerf.b"] == {"osnerf.a"}  # the TYPE_CHECKING import is not an edge
    assert import_cycles(graph) == [["osnerf.a", "osnerf.b"]]


def test_cycle_walker_sees_a_circle_through_a_package_init(tmp_path):
    """``from osnerf.run.x import f`` runs ``osnerf/run/__init__``, which may lead back."""
    run = tmp_path / "osnerf" / "run"
    run.mkdir(parents=True)
    (tmp_path / "osnerf" / "__init__.py").write_text("")
    (tmp_path / "osnerf" / "schemes.py").write_text("def f():\n    from osnerf.run.x import g\n")
    (run / "__init__.py").write_text("from osnerf.run.config import C\n")
    (run / "config.py").write_text("from osnerf.schemes import f\n")
    (run / "x.py").write_text("from osnerf.run import config\n")
    graph = import_graph(tmp_path, tops=("osnerf",))
    assert "osnerf.run" not in graph["osnerf.run.x"]  # its own package is already running
    assert import_cycles(graph) == [
        ["osnerf.run", "osnerf.run.config", "osnerf.run.x", "osnerf.schemes"]
    ]


# ----------------------------------------------------------------- sizes a reader can hold
SIZED = ("common", "phy", "semcodec", "renderer", "hil", "osnerf", "campaign", "benchmarks")
MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 450


def oversized(root: Path, tops=SIZED) -> list[str]:
    """``path: N lines`` for each module over :data:`MAX_MODULE_LINES` and ``path:line name: N
    lines`` for each function or method (nested ones too, decorators not counted) over
    :data:`MAX_FUNCTION_LINES`, under the folders ``tops`` of ``root``."""
    out = []
    for top in tops:
        for path in sorted((root / top).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            text = path.read_text()
            if (n := len(text.splitlines())) > MAX_MODULE_LINES:
                out.append(f"{rel}: {n} lines")
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_FUNCTION_LINES:
                        out.append(f"{rel}:{node.lineno} {node.name}: {n} lines")
    return out


def test_no_function_over_80_lines_and_no_module_over_450():
    found = oversized(ROOT)
    assert not found, "split by concept:\n" + "\n".join(found)


def test_size_check_sees_a_long_function_and_a_long_module(tmp_path):
    pkg = tmp_path / "phy"
    pkg.mkdir()
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    (pkg / "long.py").write_text(f"def f():\n{body}")
    last = body.index(f"    x{MAX_FUNCTION_LINES - 1} ")
    (pkg / "short.py").write_text(f"def g():\n{body[:last]}")  # 80 lines: allowed
    (pkg / "big.py").write_text("x = 1\n" * (MAX_MODULE_LINES + 1))
    (pkg / "full.py").write_text("x = 1\n" * MAX_MODULE_LINES)  # 450 lines: allowed
    assert oversized(tmp_path, ("phy",)) == [
        f"phy/big.py: {MAX_MODULE_LINES + 1} lines",
        f"phy/long.py:1 f: {MAX_FUNCTION_LINES + 1} lines",
    ]
