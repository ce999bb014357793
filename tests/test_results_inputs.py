"""python -m benchmarks.results: a missing or broken input is an error that names the file and
writes nothing; only the shipped checkpoint's jscc results are read."""

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks import results

ROOT = Path(__file__).resolve().parents[1]
README = "# x\n<!-- results:begin -->\nold table\n<!-- results:end -->\ntail\n"


@pytest.fixture
def pages(tmp_path, monkeypatch):
    """The pages' inputs and outputs under ``tmp_path``: a copy of bench-results/ and the
    checkpoints' cards, a README with its markers, docs/results.md."""
    res = tmp_path / "bench-results"
    shutil.copytree(ROOT / "bench-results", res)
    cards = tmp_path / "checkpoints"
    cards.mkdir()
    for p in (ROOT / "semcodec" / "checkpoints").glob("*.card.json"):
        shutil.copy(p, cards / p.name)
    (tmp_path / "README.md").write_text(README)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "results.md").write_text("old page\n")
    for name, value in [
        ("RESULTS", res),
        ("CARDS", cards),
        ("README", tmp_path / "README.md"),
        ("DOC", tmp_path / "docs" / "results.md"),
    ]:
        monkeypatch.setattr(results, name, value)
    return tmp_path


def _files(folder: Path) -> dict[str, str]:
    return {
        str(p): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_missing_bench_results_is_an_error_that_changes_nothing(pages, capsys):
    shutil.rmtree(pages / "bench-results")
    before = _files(pages)
    assert results.main([]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bench-results not found" in err[0]
    assert _files(pages) == before
    assert results.main(["--check"]) == 1


def test_python_m_benchmarks_results_without_bench_results(tmp_path):
    """The command itself, in a copy of the repository's page sources without bench-results/."""
    repo = tmp_path / "repo"
    for sub in ("benchmarks", "common", "semcodec/checkpoints", "docs"):
        shutil.copytree(ROOT / sub, repo / sub, ignore=shutil.ignore_patterns("*.safetensors"))
    shutil.copy(ROOT / "README.md", repo / "README.md")
    before = _files(repo)
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks.results"],
        cwd=repo,
        env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(repo), "PYTHONDONTWRITEBYTECODE": "1"},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode != 0, proc.stderr
    assert "Traceback" not in proc.stderr and "bench-results" in proc.stderr
    assert _files(repo) == before


@pytest.mark.parametrize("content", ["", '{"results": [', "[1, 2]"])
def test_a_broken_results_file_is_named(pages, content, capsys):
    bad = pages / "bench-results" / "doppler.json"
    bad.write_text(content)
    before = _files(pages)
    assert results.main([]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(bad) in err[0]
    assert _files(pages) == before


def test_a_readme_without_its_markers_is_named(pages, capsys):
    (pages / "README.md").write_text("# x\nno table here\n")
    before = _files(pages)
    assert results.main([]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "README.md" in err[0] and "results:begin" in err[0]
    assert _files(pages) == before


def test_only_the_shipped_checkpoints_jscc_results_are_read(pages):
    shipped = json.loads((pages / "checkpoints" / "default.card.json").read_text())["sha256"]
    res = pages / "bench-results"
    src = res / f"codec_awgn_jscc_{shipped[:12]}.json"
    other = json.loads(src.read_text())
    for r in other["results"]:
        r["psnr"] = 99.0
    (res / f"codec_awgn_jscc_{'f' * 12}.json").write_text(json.dumps(other))
    codec = results.codec_results(res, shipped)
    assert all(r["psnr"] != 99.0 for r in codec["awgn"]["rows"].values())
    assert [n for n, _ in codec["awgn"]["docs"]] == [
        "codec_awgn_separate.json",
        f"codec_awgn_jscc_{shipped[:12]}.json",
    ] or [n for n, _ in codec["awgn"]["docs"]] == [
        f"codec_awgn_jscc_{shipped[:12]}.json",
        "codec_awgn_separate.json",
    ]
    assert results.main([]) == 0
    assert results.main(["--check"]) == 0  # the other checkpoint's file changes no page
    assert "99.00" not in (pages / "docs" / "results.md").read_text()
