"""`osnerf ota --tx pluto --rx pluto` through one emulated Pluto looping to itself, and the
network faults (a board killed mid-capture, an unreachable address)."""

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import phy
from osnerf.cli import main

adi = pytest.importorskip("adi", reason="pyadi-iio (and libiio0) are not installed")
pytestmark = [
    pytest.mark.skipif(
        not all(
            hasattr(phy, n) for n in ("FrameConfig", "build_frame", "find_frames", "receive_frame")
        ),
        reason="phy's frame API is not in this checkout",
    ),
]

from hil import EmulatedPluto, IiodServer  # noqa: E402
from osnerf.ota_link import DEFAULT_DELAY_S, DEFAULT_MULTIPATH  # noqa: E402

ADDRESS = "127.0.0.8"
ROOT = Path(__file__).resolve().parents[2]


def emulator_process(*args: str) -> subprocess.Popen:
    """``osnerf hil emulate pluto ARGS`` in its own process (this checkout's code)."""
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONPATH": path}
    code = "import sys; from osnerf.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.Popen(
        [sys.executable, "-c", code, "hil", "emulate", "pluto", "--address", ADDRESS, *args],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def free_port(address: str = ADDRESS) -> int:
    with socket.socket() as s:
        s.bind((address, 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def images(tmp_path_factory, shared_data):
    from PIL import Image

    folder = tmp_path_factory.mktemp("ota_images")
    Image.open(sorted((shared_data / "kodak").glob("*.png"))[0]).save(folder / "kodim01.png")
    return folder


def serve(snr_db: float, **kwargs) -> IiodServer:
    board = EmulatedPluto.for_link(
        snr_db, seed=0, multipath=DEFAULT_MULTIPATH, delay_s=DEFAULT_DELAY_S, **kwargs
    )
    return IiodServer(board, ADDRESS, free_port()).serve_in_background()


def ota(tmp_path, images, uri, scheme, snr_db, *extra):
    out = tmp_path / "ota.json"
    argv = ["ota", "--tx", "pluto", "--rx", "pluto", "--uri", uri, "--schemes", scheme]
    argv += ["--snr-db", str(snr_db), "--images", str(images), "--out", str(out)]
    argv += ["--size", "48", "--max-images", "1", "--symbols-per-frame", "1024", *extra]
    return main(argv), out


@pytest.mark.parametrize(
    "snr_db, tolerance_db",
    [
        (0, 1.5),
        pytest.param(-5, 2.0, marks=pytest.mark.slow),
        pytest.param(-10, 3.0, marks=pytest.mark.slow),
    ],
)
def test_jscc_matches_the_simulated_link(tmp_path, images, snr_db, tolerance_db):
    semcodec = pytest.importorskip("semcodec")
    if not semcodec.DEFAULT_CHECKPOINT.is_file():
        pytest.skip("semcodec's shipped default checkpoint is not in this checkout")
    import torch

    with serve(float(snr_db)) as srv:
        rc, out = ota(tmp_path, images, srv.uri, "jscc", snr_db)
    assert rc == 0
    d = json.loads(out.read_text())
    r = d["results"][0]
    assert r["frames_sent"] >= 1 and r["frames_lost"] == 0
    # pilots: the air's SNR + 10 log10(64 / 52) on a flat channel; this multipath reads about
    # 1 dB off
    assert snr_db - 1.0 <= r["snr_db_measured"] <= snr_db + 10 * np.log10(64 / 52) + 1.5
    # one board: TX and RX LOs from one crystal, no carrier offset
    assert all(abs(f["cfo_hz"]) < 1500 for f in d["frames"])
    from common import load_square_images as load_images
    from renderer import psnr

    _, imgs = load_images(str(images), 48, 1)
    codec = semcodec.load_codec()
    enc = codec.encode(torch.from_numpy(imgs), r["snr_db_measured"], phy.parse_cbr("1/16"))
    g = torch.Generator().manual_seed(0)
    rx = phy.FlatLink(phy.make_channel("awgn"))(enc.symbols, r["snr_db_measured"], generator=g)
    ref = psnr(
        codec.decode(rx.x_hat, enc.meta, r["snr_db_measured"], noise_var=rx.noise_var)[0].numpy(),
        imgs[0],
    )
    assert r["psnr"] == pytest.approx(ref, abs=tolerance_db)
    assert (
        d["config"]["uri"] == srv.uri
        and "ADALM-Pluto" in open(d["sigmf"][1][: -len("data")] + "meta").read()
    )


def test_digital_at_0_db_reports_its_lost_codewords(tmp_path, images):
    with serve(0.0) as srv:
        rc, out = ota(tmp_path, images, srv.uri, "digital", 0, "--mcs", "16qam-3/4")
    assert rc == 0
    r = json.loads(out.read_text())["results"][0]
    assert r["frames_crc_failed"] > 0 and not r["decoded"]
    assert r["frames_lost"] + r["frames_crc_failed"] <= r["frames_sent"]


def test_unreachable_address_is_one_line_naming_it(tmp_path, images, capsys):
    uri = f"ip:127.0.0.3:{free_port('127.0.0.3')}"
    rc, out = ota(tmp_path, images, uri, "digital", 15)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and not out.exists()
    assert err[-1].startswith("osnerf ota: failed: DeviceNotFoundError: no Pluto at " + uri)


def _partial_capture(tmp_path, capsys, rc, out) -> int:
    """The run failed in one line naming the lost board and saved what arrived as valid
    SigMF; returns how many samples that holds."""
    import sigmf

    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and not out.exists()
    assert err[-1].startswith("osnerf ota: failed: DisconnectedError: receive: the board is gone")
    partial = tmp_path / "ota_sigmf" / "ota_rx_partial.sigmf-meta"
    assert f"capture so far saved to {partial}" in err[-1]
    rec = sigmf.fromfile(str(partial))
    rec.validate()
    return len(rec.read_samples())


def test_board_dropping_mid_capture_exits_1_and_keeps_the_capture(tmp_path, images, capsys):
    """The emulator runs as its own process and drops every connection (--fault drop) 200000
    samples into the capture, as a board that is switched off: the run says so in one line
    and keeps what arrived as valid SigMF."""

    port = free_port()
    emu = emulator_process(
        "--port", str(port), "--snr-db", "15", "--fault", "drop", "--fault-after-samples", "200000"
    )
    try:
        assert "osnerf hil emulate: pluto at" in emu.stderr.readline()
        rc, out = ota(tmp_path, images, f"ip:{ADDRESS}:{port}", "digital", 15)
        assert emu.wait(timeout=30) == 1  # the emulator says it died
    finally:
        emu.kill()
    n = _partial_capture(tmp_path, capsys, rc, out)
    assert 0 < n <= 200_000 and n % (1 << 14) == 0  # whole buffers, none after the drop


def test_emulator_killed_mid_capture_exits_1_and_keeps_the_capture(tmp_path, images, capsys):
    """SIGKILL to the emulator's process while the run is receiving: the emulator stalls its
    receive stream 150000 samples in (--fault slow) and says so, and is killed then."""
    import signal
    import threading

    port = free_port()
    emu = emulator_process(
        "--port", str(port), "--snr-db", "15", "--fault", "slow", "--fault-after-samples", "150000"
    )
    result = {}
    try:
        assert "osnerf hil emulate: pluto at" in emu.stderr.readline()
        run = threading.Thread(
            target=lambda: result.update(
                rc=ota(tmp_path, images, f"ip:{ADDRESS}:{port}", "digital", 15)
            )
        )
        run.start()
        assert "receive stalls after 150000 samples" in emu.stderr.readline()
        emu.send_signal(signal.SIGKILL)
        assert emu.wait(timeout=30) == -signal.SIGKILL
        run.join(timeout=120)
    finally:
        emu.kill()
    rc, out = result["rc"]
    assert 0 < _partial_capture(tmp_path, capsys, rc, out) <= 150_000


def test_emulate_refuses_a_non_loopback_address(capsys):
    t0 = time.monotonic()
    assert main(["hil", "emulate", "pluto", "--address", "10.1.2.3", "--port", "0"]) == 2
    assert "127.0.0.0/8" in capsys.readouterr().err and time.monotonic() - t0 < 10


def test_slow_server_mid_capture_times_out_in_one_line(tmp_path, images, capsys):
    """The board stops answering in time 200000 samples in: libiio's 5 s timeout ends the
    capture; the run exits 1 in one line and keeps what arrived."""
    with serve(15.0, fault="slow", after_samples=200_000) as srv:
        t0 = time.monotonic()
        rc, out = ota(tmp_path, images, srv.uri, "digital", 15)
        took = time.monotonic() - t0
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and not out.exists() and took < 60
    assert err[-1].startswith(
        "osnerf ota: failed: TimedOutError: receive: the board did not answer"
    )
    partial = tmp_path / "ota_sigmf" / "ota_rx_partial.sigmf-meta"
    assert f"capture so far saved to {partial}" in err[-1]
    import sigmf

    assert 0 < len(sigmf.fromfile(str(partial)).read_samples()) <= 200_000


def test_hil_info_lists_the_pluto_at_iiod_remote(monkeypatch, capsys):
    with serve(15.0) as srv:
        monkeypatch.setenv("IIOD_REMOTE", f"{srv.address}:{srv.port}")
        assert main(["hil", "info"]) == 0
    out = capsys.readouterr().out
    assert f"Found Pluto\nURI: {srv.uri}\n" in out and "PlutoSDR" in out


def test_the_pipeline_link_crosses_one_pluto(monkeypatch):
    """``osnerf run --channel ota --ota-device pluto``'s link: the first Pluto found
    (IIOD_REMOTE), both ends on one board; unit-power QPSK comes back at the air's SNR."""
    import torch

    from hil import OtaConfig
    from osnerf.ota_link import OtaLink, open_radios

    with serve(10.0) as srv:
        monkeypatch.setenv("IIOD_REMOTE", f"{srv.address}:{srv.port}")
        cfg = OtaConfig(symbols_per_frame=1024)
        tx, rx, emu = open_radios("pluto", 10.0, cfg)
        assert tx is rx and emu is None and tx.uri == srv.uri
        link = OtaLink(tx, rx, 10.0, cfg)
        g = torch.Generator().manual_seed(0)
        bits = torch.randint(0, 4, (2, 1500), generator=g)
        x = torch.exp(1j * (torch.pi / 4 + torch.pi / 2 * bits)).to(torch.complex64)
        try:
            out = link(x, 10.0)
        finally:
            link.close()
    assert link.frames_lost == 0 and link.frames_sent == 4
    err = (out.x_hat - x).abs().pow(2).mean().item()
    # zero-forced symbols: the error is the reported noise variance, near 10 dB below the signal
    assert err == pytest.approx(out.noise_var.mean().item(), rel=0.3)
    assert 7.0 <= -10 * np.log10(err) <= 13.0


def test_emulate_serves_until_sigterm_then_exits_0():
    import signal

    port = free_port()
    emu = emulator_process("--port", str(port))
    try:
        assert f"pluto at ip:{ADDRESS}:{port}" in emu.stderr.readline()
        with socket.create_connection((ADDRESS, port), timeout=10) as conn:
            conn.sendall(b"VERSION\r\n")
            assert conn.recv(64).startswith(b"0.24.")
        emu.send_signal(signal.SIGTERM)
        assert emu.wait(timeout=30) == 0
    finally:
        emu.kill()
