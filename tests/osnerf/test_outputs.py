"""Results are never lost: an existing output is refused without --overwrite, a path that is not
a regular file or folder is never replaced, outputs never land among the inputs, and a sweep
never touches a file that is not its own. Refusals exit 2 with one line and write nothing."""

from __future__ import annotations

import errno
import json
import os
import stat
import time

import numpy as np
import pytest
from PIL import Image

from osnerf.cli import main
from osnerf.link_report import LinkReport


def _ber(out, *extra) -> int:
    return main(["ber", "--snr-db", "0", "--num-bits", "10000", "--out", str(out), *extra])


def _image_dir(tmp_path, side: int):
    d = tmp_path / "img"
    d.mkdir()
    Image.fromarray(np.zeros((side, side, 3), np.uint8)).save(d / "a.png")
    return d


def _listing(folder) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


# ------------------------------------------------------------------------ not a regular file
@pytest.mark.parametrize("kind", ["fifo", "symlink"])
def test_out_on_a_fifo_or_symlink_is_refused_and_left_as_it_is(one_line, tmp_path, capsys, kind):
    target = tmp_path / "precious.txt"
    target.write_text("keep")
    x = tmp_path / "x"
    os.mkfifo(x) if kind == "fifo" else x.symlink_to(target)
    assert _ber(x) == 2
    err = one_line()
    assert "--out" in err and "not a regular file or folder" in err
    assert (x.is_fifo() if kind == "fifo" else x.is_symlink()) and target.read_text() == "keep"


def test_out_on_a_device_node_is_refused(one_line, tmp_path):
    """A device node of our own (never the machine's /dev/null: a regression would replace it)."""
    node = tmp_path / "null"
    try:
        os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("making a device node needs CAP_MKNOD")
    assert _ber(node) == 2
    assert "is a character device, not a regular file or folder" in one_line()
    assert stat.S_ISCHR(os.lstat(node).st_mode)


# ------------------------------------------------------------------------ existing results
def test_ber_refuses_to_overwrite_its_json_without_overwrite(one_line, tmp_path, capsys):
    out = tmp_path / "ber.json"
    out.write_text('{"old": true}')
    assert _ber(out) == 2
    assert "exists; give --overwrite" in one_line()
    assert out.read_text() == '{"old": true}'
    assert _ber(out, "--overwrite") == 0
    assert "ber" in json.loads(out.read_text())["results"][0] or "old" not in out.read_text()


def test_eval_codec_refuses_an_existing_json_and_a_plot_among_its_images(
    one_line, tmp_path, capsys
):
    images = _image_dir(tmp_path, 16)
    out = tmp_path / "r.json"
    out.write_text("old")
    base = ["eval-codec", "--images", str(images), "--snr-db", "10", "--schemes", "jscc"]
    assert main([*base, "--out", str(out)]) == 2
    assert "exists; give --overwrite" in one_line()
    assert main([*base, "--out", str(tmp_path / "n.json"), "--plot", str(images / "z.png")]) == 2
    assert "--plot" in one_line()
    assert sorted(p.name for p in images.iterdir()) == ["a.png"]
    assert out.read_text() == "old" and not (tmp_path / "n.json").exists()


def test_ota_refuses_an_existing_json_and_sigmf_folder(one_line, tmp_path, capsys):
    images = _image_dir(tmp_path, 64)
    out = tmp_path / "ota.json"
    out.write_text("old")
    argv = ["ota", "--schemes", "digital", "--snr-db", "10", "--images", str(images)]
    assert main([*argv, "--out", str(out)]) == 2
    assert "--out" in one_line() and out.read_text() == "old"
    sig = tmp_path / "n_sigmf"
    sig.mkdir()
    (sig / "old.sigmf-meta").write_text("{}")
    assert main([*argv, "--out", str(tmp_path / "n.json")]) == 2
    assert "--sigmf-dir" in one_line() and not (tmp_path / "n.json").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["train-nerf", "--data", "{data}"],
        ["render", "--run", "{model}"],
        ["plot", "{results}"],
        ["run", "--scene", "tiny"],
    ],
)
def test_folder_outputs_that_hold_files_are_refused(one_line, tmp_path, capsys, argv):
    data = tmp_path / "data"
    data.mkdir()
    model = tmp_path / "model.pt"
    model.write_bytes(b"x")
    results = tmp_path / "r.jsonl"
    results.write_text('{"spec_hash": "x", "point": {}, "metrics": {"ber": 0.1}}\n')
    out = tmp_path / "out"
    out.mkdir()
    (out / "001.png").write_bytes(b"old")
    (out / "report.json").write_text("{}")
    fill = {"{data}": str(data), "{model}": str(model), "{results}": str(results)}
    assert main([fill.get(a, a) for a in argv] + ["--out", str(out)]) == 2
    err = one_line()
    assert "--out" in err and "--overwrite" in err
    assert _listing(out) == {"001.png": b"old", "report.json": b"{}"}


def test_output_dir_lets_a_command_continue_only_its_own_work(tmp_path, capsys):
    from osnerf.commands import args as checks

    out = tmp_path / "run"
    (out / "cache" / "key").mkdir(parents=True)

    def unfinished(d):
        return (d / "cache" / "key").is_dir() and not (d / "report.json").exists()

    assert checks.output_dir(out, resumable=unfinished) == out
    (out / "report.json").write_text("{}")
    with pytest.raises(checks.UsageError, match="--overwrite"):
        checks.output_dir(out, resumable=unfinished)
    assert checks.output_dir(out, overwrite=True, resumable=unfinished) == out


# ------------------------------------------------------------------------ sweeps
def _spec(tmp_path, text: str):
    p = tmp_path / "spec.yaml"
    p.write_text(text)
    return p


def test_sweep_never_repairs_a_file_that_is_not_its_own(one_line, tmp_path, capsys):
    spec = _spec(tmp_path, "command: ber\nfixed: {num_bits: 1000}\naxes: {snr_db: [0]}\n")
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes about the run\n")
    assert main(["sweep", str(spec), "--out", str(notes), "--no-progress"]) == 2
    assert "not the results file of a sweep" in one_line()
    assert notes.read_text() == "my notes about the run\n"
    assert not (tmp_path / "notes.txt.torn").exists()


def test_sweep_refused_for_another_spec_leaves_the_torn_tail_alone(one_line, tmp_path, capsys):
    spec = _spec(tmp_path, "command: ber\nfixed: {num_bits: 1000}\naxes: {snr_db: [0]}\n")
    out = tmp_path / "r.jsonl"
    text = '{"point": {}, "spec_hash": "other"}\n{"point": {"snr'
    out.write_text(text)
    assert main(["sweep", str(spec), "--out", str(out), "--no-progress"]) == 2
    assert "another sweep spec" in one_line()
    assert out.read_text() == text and not (tmp_path / "r.jsonl.torn").exists()


def test_sweep_refuses_an_output_option_every_point_would_share(one_line, tmp_path, capsys):
    spec = _spec(
        tmp_path, "command: ber\nfixed: {num_bits: 1000, plot: p.png}\naxes: {snr_db: [0, 5]}\n"
    )
    out = tmp_path / "r.jsonl"
    assert main(["sweep", str(spec), "--out", str(out), "--no-progress"]) == 2
    assert "names an output" in one_line()
    assert not out.exists() and not (tmp_path / "p.png").exists()


def test_sweep_counts_its_points_before_expanding_them(one_line, tmp_path, capsys):
    spec = _spec(tmp_path, "command: ber\naxes: {snr_db: [0, 5]}\nseeds: 1000000000\n")
    out = tmp_path / "r.jsonl"
    t0 = time.perf_counter()
    assert main(["sweep", str(spec), "--out", str(out)]) == 2
    assert time.perf_counter() - t0 < 10
    err = one_line()
    assert "2000000000 points, more than --max-points 10000" in err
    assert not out.exists()
    assert main(["sweep", str(spec), "--out", str(out), "--max-points", "1e12"]) == 2
    assert "argument --max-points" in one_line()


def test_sweep_max_points_raises_the_bound():
    from osnerf.sweeps import spec_from_dict

    d = {"command": "ber", "axes": {"snr_db": [0, 5]}, "seeds": 6}
    with pytest.raises(ValueError, match="12 points"):
        spec_from_dict(d, max_points=10)
    assert spec_from_dict(d, max_points=12).num_points == 12


def test_yaml_errors_carry_their_line(one_line, tmp_path, capsys):
    spec = _spec(tmp_path, "command: ber\naxes:\n  snr_db: [0, 5\nseeds: 1\n")
    assert main(["sweep", str(spec), "--out", str(tmp_path / "r.jsonl")]) == 2
    err = one_line()
    assert "line 4" in err or "line 3" in err, err


# ------------------------------------------------------------------------ caches
def test_osnerf_cache_naming_a_file_is_refused_before_anything_is_written(
    one_line, tmp_path, capsys, monkeypatch
):
    f = tmp_path / "cachefile"
    f.write_text("")
    monkeypatch.setenv("OSNERF_CACHE", str(f))
    out = tmp_path / "run"
    assert main(["run", "--scene", "tiny", "--out", str(out)]) == 2
    assert "$OSNERF_CACHE" in one_line()
    assert not out.exists()


# ------------------------------------------------------------------------ a full disk
def _fake_report(psnr: float, views: bool):
    """A small run report of two schemes (and its pictures) as the pipeline returns them;
    ``views=False`` has no per-view measurements, so no ``plot_views.png``."""
    from osnerf.report import Report, SchemeReport, ViewsSummary

    seconds = {"encode": 0.1, "air": 0.2, "decode": 0.1, "nerf": 1.0}
    schemes = {
        name: SchemeReport(psnr, 0.5, None, psnr, None, 100, 2, seconds, 1.2)
        for name in ("jscc", "digital")
    }
    ids = {3: 5.0, 4: 6.0} if views else {}
    report = Report(
        scene={"name": "tiny"},
        demand={"objects": ["crate"]},
        link=LinkReport("awgn"),
        snr_db=10.0,
        symbol_rate_hz=1e6,
        codec=None,
        views=ViewsSummary(
            measured_snr_db=ids,
            link_snr_db=ids,
            cbr=dict.fromkeys(ids, 0.1),
            sent_on_demand=[3],
        ),
        schemes=schemes,
        comparisons={},
        scu_decisions=[{"stage": "collector", "decision": "views 3, 4"}],
        metric_notes="",
        seconds_total=2.0,
        scene_seconds=0.5,
    )
    img = np.full((8, 8, 3), psnr / 40, np.float32)
    pictures = {
        "gt": [img, img],
        "renders": dict.fromkeys(schemes, [img, img]),
        "received": dict.fromkeys(schemes, [img]),
    }
    return report, pictures


@pytest.fixture
def fake_pipeline(monkeypatch):
    """``osnerf run``'s pipeline replaced by one that returns ``fake_pipeline.report`` (and
    keeps its stage cache, so the same command continues in its folder)."""
    import osnerf.run

    class Fake:
        report = _fake_report(10.0, views=True)

    def run_pipeline(cfg, out, cache_dir=None, prepared=None):
        (out / "cache" / cfg.key()).mkdir(parents=True, exist_ok=True)
        return Fake.report

    monkeypatch.setattr(osnerf.run, "run_pipeline", run_pipeline)
    return Fake


def _report_files(out) -> dict:
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.is_file()}


@pytest.mark.parametrize("full_at", ["grid.png", "plot_schemes.png", "report.html", "report.json"])
def test_run_on_a_full_disk_names_the_file_and_keeps_the_last_report_whole(
    one_line, tmp_path, capsys, monkeypatch, fake_pipeline, full_at
):
    """The disk fills while the report stage writes ``full_at``: exit 1 with one line naming
    that file; the previous report (json, html, pictures) is left whole and no temporary file
    stays, so report.json never describes pictures of another run."""
    import common.files

    out = tmp_path / "run"
    argv = ["run", "--scene", "tiny", "--out", str(out)]
    assert main(argv) == 0
    before = _report_files(out)
    assert {"report.json", "report.html", "grid.png", "plot_views.png"} <= set(before)
    capsys.readouterr()

    write = common.files._write_file

    def full_disk(path, data):
        if not path.name.startswith(f".{full_at}."):
            return write(path, data)
        with open(path, "wb") as f:
            f.write(data[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(common.files, "_write_file", full_disk)
    fake_pipeline.report = _fake_report(20.0, views=True)
    assert main(argv) == 1
    err = one_line()
    assert "No space left on device" in err and repr(str(out / full_at)) in err, err
    assert _report_files(out) == before  # the same files, byte for byte: nothing half-new


def test_a_report_without_view_plots_removes_the_last_ones(tmp_path, fake_pipeline):
    """A report is one set: a picture the new report has no data for is not left behind
    from the previous run in the same folder."""
    out = tmp_path / "run"
    argv = ["run", "--scene", "tiny", "--out", str(out)]
    assert main(argv) == 0 and (out / "plot_views.png").is_file()
    fake_pipeline.report = _fake_report(20.0, views=False)
    assert main(argv) == 0
    assert not (out / "plot_views.png").exists()
    assert json.loads((out / "report.json").read_text())["schemes"]["jscc"]["psnr"] == 20.0
