"""A codec from another package, end to end: ``--codec NAME`` in eval-codec (AWGN and block
Rayleigh), osnerf ota between emulated HackRFs and osnerf run on the tiny scene; the
knowledge-base check stays on (another codec's identity is refused, both hashes named)."""

import json

from osnerf.cli import main


def test_plugin_in_eval_codec_on_awgn_and_block_rayleigh(plugin, kodak1, tmp_path):
    """The block transform keeps 3 of its 16 real coefficients per 4x4x3 block at CBR 1/16:
    at 20 dB on AWGN the picture is a coarse one, well above a blank image, and block
    Rayleigh over 4 draws (deep fades included) costs it PSNR."""
    psnr = {}
    for ch in ("awgn", "rayleigh"):
        out = tmp_path / f"{ch}.json"
        argv = ["eval-codec", "--images", str(kodak1), "--codec", "demo", "--schemes", "jscc"]
        argv += ["--channel", ch, "--snr-db", "20", "--draws", "4", "--no-lpips"]
        assert main([*argv, "--out", str(out)]) == 0
        doc = json.loads(out.read_text())
        assert doc["checkpoint"]["sha256"] == "d" * 64
        psnr[ch] = doc["results"][0]["psnr"]
    assert psnr["awgn"] > 17.0 and psnr["rayleigh"] < psnr["awgn"], psnr


def test_plugin_over_the_air_between_emulated_hackrfs(plugin, kodak1, tmp_path):
    out = tmp_path / "ota.json"
    argv = ["ota", "--tx", "emulated", "--rx", "emulated", "--schemes", "jscc", "--codec", "demo"]
    argv += ["--snr-db", "15", "--images", str(kodak1), "--size", "48", "--max-images", "1"]
    argv += ["--symbols-per-frame", "1024", "--out", str(out)]
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    rows = doc.get("images") or doc.get("results")
    assert rows and all(r["psnr"] > 15.0 for r in rows), rows


def test_plugin_in_osnerf_run_and_the_knowledge_base_check(plugin, tmp_path, capsys):
    """The plugin cannot focus: the pipeline sends the objects' box at the view's budget."""
    base = ["run", "--scene", "tiny", "--resolution", "32", "--views", "4", "--test-views", "2"]
    base += ["--nerf-steps", "60", "--renderer-steps", "0", "--schemes", "jscc,gt"]
    base += ["--cache-dir", str(tmp_path / "cache")]
    out = tmp_path / "run"
    assert main([*base, "--codec", "demo", "--out", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["codec"]["sha256"] == "d" * 64
    assert rep["schemes"]["jscc"]["symbols_sent"] > 0
    assert rep["schemes"]["jscc"]["psnr_received_object"] > 10.0
    bad = tmp_path / "bad"
    other = tmp_path / "other.ckpt"  # the demo codec's "checkpoint": any file
    other.write_bytes(b"demo")
    rc = main([*base, "--codec", "demo", "--receiver-codec", f"demo:{other}", "--out", str(bad)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert rc == 2 and "knowledge-base mismatch" in err and "dddddddddddd" in err
    assert "eeeeeeeeeeee" in err and not (bad / "report.json").exists()


def test_unknown_codec_is_refused_with_the_known_names(tmp_path, kodak1, capsys):
    argv = ["eval-codec", "--images", str(kodak1), "--codec", "nope", "--schemes", "jscc"]
    assert main([*argv, "--snr-db", "5", "--out", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "unknown codec 'nope'" in err and "jscc" in err and "deepjscc" in err
    assert not (tmp_path / "x.json").exists()
