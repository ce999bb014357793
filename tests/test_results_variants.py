"""docs/results.md's demo-variant section: per-seed rows, means over seeds, and the tiny scene
over the air with and without digital's box, from the run reports' folders."""

import json

from benchmarks import results_variants


def _report(folder, name: str, seed: int, **psnr: float) -> None:
    (folder / name).mkdir()
    doc = {
        "git_commit": "0123456789abcdef",
        "seed": seed,
        "schemes": {k: {"psnr_object": v} for k, v in psnr.items()},
    }
    (folder / name / "report.json").write_text(json.dumps(doc))


def test_one_variant_alone_is_no_comparison(tmp_path):
    _report(tmp_path, "pipeline_demo", 0, jscc=21.0, digital=18.5)
    text = "\n".join(results_variants.section(tmp_path))
    assert "No demo variants (`python -m benchmarks pipeline`)." in text


def test_rows_per_seed_and_the_mean_of_each_variant(tmp_path):
    _report(tmp_path, "pipeline_demo", 0, jscc=21.0, digital=18.5, gt=22.0)
    _report(tmp_path, "pipeline_demo_exact_seed1", 1, jscc=20.0, digital=18.0, gt=22.0)
    _report(tmp_path, "pipeline_demo_err2_seed0", 0, jscc=20.5, digital=17.0, gt=22.0)
    _report(tmp_path, "pipeline_demo_box_seed0", 0, jscc=21.0, digital=20.0, gt=22.0)
    _report(tmp_path, "pipeline_demo_junk", 0, jscc=1.0)  # not a variant folder: not read
    text = "\n".join(results_variants.section(tmp_path))
    assert "| exact knowledge | 0 | 21.00 | 18.50 | – | 22.00 | +2.50 | 0123456 |" in text
    assert "| **exact knowledge, mean** |  | 20.50 | 18.25 | – | 22.00 | +2.25 |  |" in text
    assert (
        "| 2 dB estimate error (--snr-error-db 2) | 0 | 20.50 | 17.00 | – | 22.00 | +3.50 |" in text
    )
    assert (
        "| digital sends the box (--digital-box true) | 0 | 21.00 | 20.00 | – | 22.00 | +1.00 |"
        in text
    )
    assert text.index("exact knowledge |") < text.index("2 dB estimate") < text.index("box")
    assert "over the air" not in text  # no box runs over the air: no such table


def test_over_the_air_with_and_without_the_box(tmp_path):
    _report(tmp_path, "pipeline_demo", 0, jscc=21.0, digital=18.5)
    _report(tmp_path, "pipeline_demo_box_seed0", 0, jscc=21.0, digital=20.0)
    _report(tmp_path, "pipeline_tiny_ota_-5dB_seed1", 1, jscc=19.0, digital=15.0)
    _report(tmp_path, "pipeline_tiny_ota_box_-5dB_seed1", 1, jscc=19.0, digital=17.5)
    _report(tmp_path, "pipeline_tiny_ota_0dB_seed0", 0, jscc=20.0, digital=19.0)  # no box run
    text = "\n".join(results_variants.section(tmp_path))
    assert "| -5 dB | 1 | +4.00 | +1.50 |" in text
    assert "| 0 dB | 0 |" not in text
