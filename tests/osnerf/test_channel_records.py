"""Every result says which channel it ran over: the run report's link, eval-codec's config,
ber's config and each sweep point, with TDL/CDL's profile and pinned TR 38.901 spec_version;
a sweep varies the channel model (TS 38.101-4 conditions included) with all else fixed."""

import json

import pytest
from PIL import Image

from osnerf.cli import main
from osnerf.run.config import RunConfig
from osnerf.run.links import build_links
from osnerf.sweeps import read_results

SPEC_VERSION = "19.2"


@pytest.fixture(scope="module")
def image_dir(tmp_path_factory, shared_data):
    d = tmp_path_factory.mktemp("imgs")
    name = sorted((shared_data / "kodak").iterdir())[0]
    Image.open(name).convert("RGB").crop((100, 100, 164, 148)).save(d / "im0.png")
    return d


@pytest.mark.parametrize("channel", ["tdl", "cdl", "tdla30-10"])
def test_the_run_report_records_the_channel_and_its_spec_version(channel):
    links = build_links(RunConfig(channel=channel), None, [0, 1])
    rec = links.report.to_dict()["channel_params"]
    assert rec["channel"] == channel and rec["spec_version"] == SPEC_VERSION
    assert links.report.to_dict()["ofdm"] is True
    flat = build_links(RunConfig(channel="rayleigh"), None, [0])
    assert flat.report.to_dict()["channel_params"] == {"channel": "rayleigh"}


def test_eval_codec_records_the_condition_it_ran_over(image_dir, tmp_path):
    out = tmp_path / "eval.json"
    argv = ["eval-codec", "--images", str(image_dir), "--channel", "tdlb100-400"]
    argv += ["--snr-db", "10", "--cbr", "1/16", "--schemes", "digital", "--out", str(out)]
    assert main([*argv, "--no-lpips"]) == 0
    rec = json.loads(out.read_text())["config"]["channel_params"]
    assert rec["channel"] == "tdlb100-400" and rec["model"] == "TDL-B100"
    assert rec["spec_version"] == SPEC_VERSION and rec["max_doppler_hz"] == pytest.approx(400)
    assert rec["delay_spread_s"] == pytest.approx(100e-9)


def test_ber_records_its_channel(tmp_path):
    out = tmp_path / "ber.json"
    argv = ["ber", "--channel", "rayleigh", "--snr-db", "5", "--num-bits", "2000"]
    assert main([*argv, "--out", str(out)]) == 0
    assert json.loads(out.read_text())["config"]["channel_params"] == {"channel": "rayleigh_fast"}


def test_a_sweep_varies_the_channel_model_and_each_point_records_it(image_dir, tmp_path):
    spec = tmp_path / "channels.yaml"
    spec.write_text(
        f"command: eval-codec\n"
        f"fixed: {{images: {image_dir}, snr_db: '10', cbr: 1/16, schemes: digital, "
        f"no_lpips: true}}\n"
        f"axes: {{channel: [tdl, tdlc300-100, rayleigh]}}\n"
        f"seeds: [0]\n"
    )
    out = tmp_path / "channels.jsonl"
    argv = ["sweep", str(spec), "--out", str(out), "--executor", "serial", "--no-progress"]
    assert main(argv) == 0
    records = {r["point"]["channel"]: r for r in read_results(out)}
    assert sorted(records) == ["rayleigh", "tdl", "tdlc300-100"]
    assert records["tdl"]["channel"]["model"] == "TDL-A"
    assert records["tdlc300-100"]["channel"]["model"] == "TDL-C300"
    for name in ("tdl", "tdlc300-100"):
        assert records[name]["channel"]["spec_version"] == SPEC_VERSION
    assert records["rayleigh"]["channel"] == {"channel": "rayleigh"}


def test_a_sweep_refuses_an_unknown_channel_before_any_point(tmp_path, capsys):
    spec = tmp_path / "bad.yaml"
    spec.write_text(
        "command: run\nfixed: {snr_db: 0}\naxes: {channel: [tdl, tdla30-11]}\nseeds: [0]\n"
    )
    out = tmp_path / "bad.jsonl"
    assert main(["sweep", str(spec), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "axis 'channel' value 'tdla30-11': unknown channel" in err
    assert "tdla30-10" in err and "raytraced" in err and not out.exists()


def test_a_codec_trained_over_tdl_records_it_in_its_model_card(image_dir, tmp_path):
    from semcodec import load_codec

    out = tmp_path / "run"
    argv = ["train-codec", "--data", str(image_dir), "--out", str(out), "--model", "adjscc_s4_w64"]
    argv += ["--crop-px", "32", "--batch-size", "2", "--max-minutes", "0.02", "--threads", "1"]
    assert main([*argv, "--channel", "awgn,ofdm_tdl_ls"]) == 0
    channels = load_codec(out / "last.safetensors").card["training"]["channels"]
    assert channels["awgn"] == {"channel": "awgn"}
    assert channels["ofdm_tdl_ls"]["model"] == "TDL-A"
    assert channels["ofdm_tdl_ls"]["spec_version"] == SPEC_VERSION
