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
    """``name`` is a module file inside one of our packages (``hil.emulation.air``), not the package or
    one of its subpackages (``phy.digital``), whose ``__init__`` is the public surface."""
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
