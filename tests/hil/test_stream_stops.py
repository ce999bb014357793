"""A stream that stops early: Ctrl-C stops the sending at once and writes the views decoded
so far, marked, with the capture; a board gone does the same, as a failure; the boards'
process ends without a traceback; a ring shorter than a frame is refused before any radio."""

import _thread
import json
import time

import pytest

import hil
from osnerf.cli import main


@pytest.fixture(scope="module")
def images(tmp_path_factory, shared_data):
    from PIL import Image

    folder = tmp_path_factory.mktemp("stream_images")
    Image.open(sorted((shared_data / "kodak").glob("*.png"))[0]).save(folder / "kodim01.png")
    return folder


def _argv(tmp_path, images, views: int, *extra) -> list[str]:
    argv = ["ota", "--stream", "--tx", "emulated", "--rx", "emulated", "--schemes", "jscc"]
    argv += ["--snr-db", "10", "--images", str(images), "--out", str(tmp_path / "s.json")]
    argv += ["--size", "48", "--max-images", "1", "--symbols-per-frame", "1024"]
    return [*argv, "--sample-rate-hz", "2e6", "--views", str(views), *extra]


def _stop_at_view(monkeypatch, n: int, stop) -> dict:
    """Run ``stop()`` on the decoder's thread once ``n`` views were decoded."""
    real, seen = hil.stream_over_the_air, {}

    def wrapped(tx, rx, views, cfg, on_view, **kw):
        def on(view):
            on_view(view)
            seen["decoded"] = seen.get("decoded", 0) + 1
            if seen["decoded"] == n:
                seen["at"] = time.monotonic()
                stop()

        return real(tx, rx, views, cfg, on, **kw)

    monkeypatch.setattr(hil, "stream_over_the_air", wrapped)
    return seen


def test_ctrl_c_stops_sending_and_writes_the_views_decoded_so_far(
    tmp_path, images, monkeypatch, capsys
):
    seen = _stop_at_view(monkeypatch, 3, _thread.interrupt_main)
    argv = _argv(tmp_path, images, 60, "--view-interval-s", "0.05")
    rc = main(argv)
    took = time.monotonic() - seen["at"]
    assert rc == 130
    assert took < 1.0, f"{took:.2f} s from Ctrl-C to the result"
    doc = json.loads((tmp_path / "s.json").read_text())
    stopped, stream = doc["stopped"], doc["stream"]
    assert stopped["by"] == "interrupt" and stopped["views_planned"] == 60
    assert stream["views_decoded"] == stopped["views_decoded"] >= 3
    assert stream["views_sent"] < 60  # sending stopped at the Ctrl-C
    assert len(doc["results"]) == stream["views_decoded"]
    assert stopped["capture"] and stopped["capture"] in doc["sigmf"]
    assert (tmp_path / "s_sigmf" / "ota_rx_partial.sigmf-meta").is_file()
    err = capsys.readouterr().err
    assert "Traceback" not in err and "interrupted" in err


def test_a_board_gone_mid_stream_writes_what_arrived_as_failed(
    tmp_path, images, monkeypatch, capsys
):
    def gone():
        raise hil.HilError("receiving board unplugged")

    _stop_at_view(monkeypatch, 2, gone)
    rc = main(_argv(tmp_path, images, 30, "--view-interval-s", "0.05"))
    assert rc == 1
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["stopped"]["by"] == "failure" and "unplugged" in doc["stopped"]["message"]
    assert doc["stream"]["views_decoded"] >= 1
    err = capsys.readouterr().err.strip().splitlines()
    assert any("failed: receiving board unplugged" in line for line in err)
    assert not any("Traceback" in line for line in err)


def test_a_ring_shorter_than_a_frame_is_refused_up_front(tmp_path, images, monkeypatch, capsys):
    def never(*a, **k):
        raise AssertionError("radios opened")

    monkeypatch.setattr("osnerf.commands.ota_stream._open_radios", never)
    assert main(_argv(tmp_path, images, 2, "--ring-s", "0.01")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--ring-s 0.01 holds less than one frame" in err[0]
    assert not (tmp_path / "s.json").exists()


def test_the_boards_process_ends_quietly_when_its_host_goes_away():
    """A call whose host hung up (SIGTERM, Ctrl-C) ends that connection's thread without
    an exception, so the child prints no thread traceback."""
    from hil.emulation.process import serve_connection

    class Gone:
        def __init__(self):
            self.calls = 0

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def recv(self):
            self.calls += 1
            if self.calls > 1:
                raise EOFError
            return ("overrun_samples", 0, ())

        def send(self, reply):
            raise BrokenPipeError(32, "Broken pipe")

    class Radio:
        overrun_samples = 0

    class Emu:
        radios = [Radio()]

    serve_connection(Gone(), Emu())  # returns; old code raised BrokenPipeError


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_the_command_exits_within_two_seconds_of_a_stop_with_its_result(tmp_path, images, sig):
    """``osnerf ota --stream`` as a user runs it: the signal mid-stream, then the process
    gone within 2 s, its result file holding the views decoded so far."""
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root), "OMP_NUM_THREADS": "1"}
    argv = _argv(tmp_path, images, 60, "--view-interval-s", "0.2")
    proc = subprocess.Popen(
        [sys.executable, "-m", "osnerf.cli", *argv], env=env, stderr=subprocess.PIPE, text=True
    )
    try:
        assert "streaming 60 view(s)" in proc.stderr.readline()
        time.sleep(5.0)  # the boards' process starts, then views go out and are decoded
        sent = time.monotonic()
        proc.send_signal(getattr(signal, sig))
        rc = proc.wait(timeout=30)
        took = time.monotonic() - sent
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert rc == 130, err
    assert took < 2.0, f"{took:.2f} s from {sig} to exit"
    assert "Traceback" not in err
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["stopped"]["by"] == "interrupt" and doc["stream"]["views_decoded"] >= 1
    assert doc["stream"]["views_sent"] < 60


def test_ctrl_c_stops_a_pluto_stream_as_fast(tmp_path, images, monkeypatch):
    """The same stop over an emulated Pluto (one full-duplex board, libiio's buffers)."""
    pytest.importorskip("adi", reason="pyadi-iio (and libiio0) are not installed")
    import socket

    from test_ota_stream import pluto_process

    with socket.socket() as s:
        s.bind(("127.0.0.9", 0))
        port = s.getsockname()[1]
    emu = pluto_process(port)
    try:
        seen = _stop_at_view(monkeypatch, 2, _thread.interrupt_main)
        argv = _argv(tmp_path, images, 40, "--view-interval-s", "0.1")
        i = argv.index("--tx")
        argv[i : i + 4] = ["--tx", "pluto", "--rx", "pluto", "--uri", f"ip:127.0.0.9:{port}"]
        argv[argv.index("--sample-rate-hz") + 1] = "4e6"
        rc = main(argv)
        took = time.monotonic() - seen["at"]
    finally:
        emu.terminate()
        emu.wait(10)
    assert rc == 130 and took < 1.0, f"rc {rc}, {took:.2f} s"
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["stopped"]["by"] == "interrupt" and doc["stream"]["views_sent"] < 40
