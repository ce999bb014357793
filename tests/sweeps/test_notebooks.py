"""The four notebooks: stored without outputs, and each executed (small settings) making its
figures.

Each notebook reads OSNERF_NOTEBOOK_SMALL=1 (a few points) and OSNERF_NOTEBOOK_OUT (where its
results and figures go). A notebook whose package or command is not in the checkout yet is
skipped with the reason.
"""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path

import nbformat
import pytest

NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"

# notebook -> (modules, or "module:attribute", it needs; figures it must make; marks)
CASES = {
    "01_ber_vs_snr.ipynb": (("osnerf.commands.ber", "phy.theory:ber_theory"), ("ber_vs_snr",), ()),
    "02_psnr_vs_snr_kodak.ipynb": (
        ("osnerf.commands.eval_codec", "semcodec:load_codec"),
        ("psnr_vs_snr", "ssim_vs_snr", "digital_cliff"),
        (),
    ),
    "03_nerf_vs_snr_pipeline.ipynb": (
        ("osnerf.commands.run", "semcodec:load_codec", "renderer:train"),
        ("nerf_psnr_vs_snr",),
        (),
    ),
    "04_raytraced_channels.ipynb": (
        ("phy.raytrace:RayTracer",),
        ("raytraced_stats", "raytraced_cfr"),
        (pytest.mark.raytracing,),
    ),
}
READS_SHARED_DATA = {"02_psnr_vs_snr_kodak.ipynb"}
"""Notebooks that read ../shared/data (skipped like every other test of it when it is absent)."""


def _missing(needs) -> str | None:
    for need in needs:
        module, _, attr = need.partition(":")
        if importlib.util.find_spec(module) is None:
            return f"{module} is not in this checkout yet"
        if attr and not hasattr(importlib.import_module(module), attr):
            return f"{module}.{attr} is not in this checkout yet"
    return None


def test_notebooks_are_stored_without_outputs():
    found = sorted(p.name for p in NOTEBOOKS.glob("*.ipynb"))
    assert found == sorted(CASES)
    for name in found:
        nb = nbformat.read(NOTEBOOKS / name, as_version=4)
        nbformat.validate(nb)
        for cell in nb.cells:
            if cell.cell_type == "code":
                assert cell.outputs == [] and cell.execution_count is None, f"{name} has outputs"
        params = [c for c in nb.cells if "parameters" in c.metadata.get("tags", [])]
        assert len(params) == 1 and "OSNERF_NOTEBOOK_SMALL" in params[0].source


@pytest.mark.timeout(600)
@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=marks) for n, (_, _, marks) in CASES.items()]
)
def test_notebook_runs_small_and_makes_its_figures(name, tmp_path, monkeypatch, request):
    needs, figures, _ = CASES[name]
    reason = _missing(needs)
    if reason:
        pytest.skip(reason)
    if name in READS_SHARED_DATA:
        request.getfixturevalue("shared_data")
    from nbclient import NotebookClient

    out = tmp_path / "out"
    monkeypatch.setenv("OSNERF_NOTEBOOK_SMALL", "1")
    monkeypatch.setenv("OSNERF_NOTEBOOK_OUT", str(out))
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    client = NotebookClient(
        nb, timeout=540, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOKS)}}
    )
    client.execute()
    images = [
        o
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.outputs
        if "image/png" in o.get("data", {})
    ]
    assert len(images) >= len(figures)
    for fig in figures:
        for ext in ("png", "pdf"):
            path = out / f"{fig}.{ext}"
            assert path.is_file() and path.stat().st_size > 5000, f"{name} did not make {path.name}"
    errors = [
        o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"
    ]
    assert not errors
