"""docs/results.md's mismatch section and README rows: each part names the commit that made
its eval-codec files, not the commit that last ran the benchmark (parts are reused)."""

import json

from benchmarks import results_mismatch


def _write(folder, name: str, commit: str, results: dict | None = None) -> None:
    doc = {"git_commit": commit, "results": results or {}}
    (folder / name).write_text(json.dumps(doc))


def _panel_row(scheme: str, snr: float, psnr: float) -> dict:
    return {"scheme": scheme, "snr_db": snr, "psnr": psnr, "num_images": 24, "lost_images": 0}


def test_each_part_names_the_commit_of_its_own_files(tmp_path):
    panel = [_panel_row(s, snr, 20.0 + snr) for s in ("jscc", "digital") for snr in (0.0, 4.0)]
    estimate = [{**_panel_row("jscc", 0.0, 25.0), "channel": "awgn", "snr_error_db": 2.0}]
    results = {"plan_snr_db": 4.0, "panel": panel, "estimate": estimate}
    _write(tmp_path, "mismatch.json", "c" * 40, results)
    _write(tmp_path, "mismatch_panel.json", "a" * 40)
    _write(tmp_path, "mismatch_estimate_awgn_err2.json", "b" * 40)
    _write(tmp_path, "mismatch_estimate_awgn_err0.json", "d" * 40 + "-dirty")
    doc = results_mismatch.load(tmp_path)
    rows = results_mismatch.headline_rows(doc)
    assert [r[-1] for r in rows] == ["aaaaaaa", "aaaaaaa"]
    assert [r[1] for r in rows] == ["AWGN 0 dB", "AWGN 4 dB"]
    header = results_mismatch.section(doc, tmp_path)[2]
    assert "panel 24 (aaaaaaa), estimate 24 (bbbbbbb, ddddddd-dirty);" in header


def test_without_its_part_files_a_part_names_the_benchmark_s_commit(tmp_path):
    panel = [_panel_row(s, 0.0, 20.0) for s in ("jscc", "digital")]
    _write(tmp_path, "mismatch.json", "c" * 40, {"plan_snr_db": 4.0, "panel": panel})
    rows = results_mismatch.headline_rows(results_mismatch.load(tmp_path))
    assert [r[-1] for r in rows] == ["ccccccc"]
