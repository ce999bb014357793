"""The README and docs/results.md say what bench-results/ holds, and the version is one."""

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import osnerf
from benchmarks import results

ROOT = Path(__file__).resolve().parent.parent


def test_results_tables_are_generated_from_bench_results():
    assert results.main(["--check"]) == 0, "run: python -m benchmarks.results"


def test_readme_table_rows_come_from_the_files():
    doc, table = results.render()
    readme = (ROOT / "README.md").read_text()
    assert "\n".join(table) in readme
    assert len(table) > 2, "bench-results/ holds no result the README could show"


def test_readme_is_short():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200


def test_docs_links_resolve():
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", page.read_text()):
            if "://" not in target:
                assert (page.parent / target).exists(), f"{page.name} links to {target}"


def test_version_is_declared_once_and_reported():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" in meta["project"]["dynamic"]
    assert meta["tool"]["setuptools"]["dynamic"]["version"] == {
        "attr": "osnerf.version.__version__"
    }
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from osnerf.cli import main; sys.exit(main(['--version']))",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=True,
    ).stdout
    assert out.strip() == f"osnerf {osnerf.__version__}"
    assert osnerf.result_header({}, 0)["versions"]["osnerf"] == osnerf.__version__
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert f"## [{osnerf.__version__}]" in changelog
    citation = (ROOT / "CITATION.cff").read_text()
    assert f"version: {osnerf.__version__}" in citation
