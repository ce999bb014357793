"""SoapySDR devices through the real library: Debian's libSoapySDR and its remote module
reach the emulated device of ``osnerf hil emulate soapy`` over SoapyRemote's RPC and UDP
streams, as they would reach ``SoapySDRServer`` on another host."""

import json
import math
import struct
import time

import numpy as np
import pytest

SoapySDR = pytest.importorskip(
    "SoapySDR", reason="Debian's python3-soapysdr is not installed (make soapysdr)"
)
if not any("remoteSupport" in m for m in SoapySDR.listModules()):
    pytest.skip(
        "Debian's soapysdr-module-remote is not installed (make soapysdr)", allow_module_level=True
    )

from hil import DEVICES, OtaConfig, Radio, SoapyRadio, StreamError  # noqa: E402
from hil.emulation import EmulatedSoapyDevice, SoapyRemoteServer, soapy_rpc, soapy_streams  # noqa: E402
from hil.emulation.soapy_device import RX, TX  # noqa: E402
from hil.pluto import ad9361  # noqa: E402
from osnerf.cli import main  # noqa: E402
from osnerf.ota_link import DEFAULT_DELAY_S, DEFAULT_MULTIPATH  # noqa: E402

ADDRESS = "127.0.0.9"


def serve(snr_db: float = 10.0, **kwargs) -> SoapyRemoteServer:
    device = EmulatedSoapyDevice.for_link(
        snr_db, multipath=DEFAULT_MULTIPATH, delay_s=DEFAULT_DELAY_S, **kwargs
    )
    return SoapyRemoteServer(device, ADDRESS, 0).serve_in_background()


@pytest.fixture(scope="module")
def server():
    with serve() as srv:
        yield srv


@pytest.fixture(scope="module")
def images(tmp_path_factory, shared_data):
    """Three Kodak crops."""
    import shutil

    folder = tmp_path_factory.mktemp("soapy_images")
    for path in sorted((shared_data / "kodak").glob("*.png"))[:3]:
        shutil.copy(path, folder / path.name)
    return folder


def test_constants_are_the_librarys():
    assert (SoapySDR.SOAPY_SDR_TX, SoapySDR.SOAPY_SDR_RX) == (TX, RX) == (0, 1)
    codes = ("TIMEOUT", "STREAM_ERROR", "CORRUPTION", "OVERFLOW", "NOT_SUPPORTED")
    assert [getattr(SoapySDR, f"SOAPY_SDR_{c}") for c in codes] == [-1, -2, -3, -4, -5]
    assert (SoapySDR.SOAPY_SDR_TIME_ERROR, SoapySDR.SOAPY_SDR_UNDERFLOW) == (-6, -7)
    assert (soapy_streams.OVERFLOW, soapy_streams.UNDERFLOW) == (
        SoapySDR.SOAPY_SDR_OVERFLOW,
        SoapySDR.SOAPY_SDR_UNDERFLOW,
    )
    assert (
        (soapy_streams.END_BURST, soapy_streams.HAS_TIME)
        == (
            SoapySDR.SOAPY_SDR_END_BURST,
            SoapySDR.SOAPY_SDR_HAS_TIME,
        )
        == (1 << 1, 1 << 2)
    )
    assert "soapy" in DEVICES and DEVICES["soapy"].serve is not None


def test_rpc_bytes_follow_the_specification():
    msg = soapy_rpc.Packer().call(soapy_rpc.Call.GET_DRIVER_KEY).message()
    # header word, version 0.4.0, total length; CALL (15), INT32 (2) 100; trailer word
    assert msg == b"SRPC" + bytes([0, 0, 4, 0, 0, 0, 0, 22, 15, 2, 0, 0, 0, 100]) + b"CPRS"
    # a double is frexp's exponent (int32) and its mantissa scaled to 53 bits (int64)
    body = bytes(soapy_rpc.Packer().float64(4e6).body)
    exponent = 22  # 4e6 = 0.95367431640625 * 2**22
    mantissa = int(math.ldexp(4e6 / 2**exponent, 53))
    expected = bytes([4, 2]) + struct.pack(">i", exponent)
    assert body == expected + bytes([3]) + struct.pack(">q", mantissa)
    u = soapy_rpc.Unpacker(bytes(soapy_rpc.Packer().float64(-1234.5678).range((1, 2, 0.25)).body))
    assert u.float64() == -1234.5678 and u.range() == (1.0, 2.0, 0.25) and u.done
    # a stream datagram's header: bytes, sequence, elements (or an error), flags, time
    d = soapy_rpc.datagram(7, -4)
    assert d == struct.pack(">IIiiq", 24, 7, SoapySDR.SOAPY_SDR_OVERFLOW, 0, 0)
    assert soapy_rpc.elems_per_datagram(1500, 4) == (1500 - 48 - 24) // 4 == 357


def test_the_library_reads_the_ranges_and_quantisation_of_the_part(server):
    found = SoapySDR.Device.enumerate(server.args)
    assert len(found) == 1 and found[0]["remote:driver"] == "osnerf"
    with SoapyRadio.open(server.args) as radio:
        assert isinstance(radio, Radio) and not isinstance(server.device, Radio)
        r = radio.ranges()
        assert r["center_freq_range_hz"] == ad9361.LO_RANGE_HZ
        assert r["sample_rate_range_hz"] == ad9361.SAMPLE_RATE_RANGE_HZ
        assert r["rx_gain_range_db"] == (-3, 71) and r["tx_gain_range_db"] == (-89.75, 0)
        radio.rx_gain_db = 30.7  # the AD9361 keeps whole dB
        radio.tx_gain_db = -10.3  # and 0.25 dB steps of attenuation
        assert (radio.rx_gain_db, radio.tx_gain_db) == (30.0, -10.25)
        radio.center_freq_hz = 2.45e9
        assert radio.center_freq_hz == ad9361.lo_frequency_hz(2_450_000_000)
        with pytest.raises(ValueError, match=r"center_freq_hz must be in \[3.25e\+08"):
            radio.center_freq_hz = 6e9
        radio.rx_gain_db = 30  # the air's calibration gain again
        radio.tx_gain_db = -10


def test_a_tone_comes_back_through_the_emulated_air(server):
    import threading

    from osnerf.ota_link import air_channel

    with SoapyRadio.open(server.args) as radio:
        cfg = OtaConfig()
        radio.apply_ota_config(cfg)
        assert radio.air_settable
        radio.set_air(air_channel("soapy", 30.0, cfg, 0.0, ()), ppm=0.0, seed=1)  # flat, 30 dB
        fs = radio.sample_rate_hz
        k = np.arange(200_000)
        tone = (0.5 * np.exp(2j * np.pi * 100e3 / fs * k)).astype(np.complex64)
        got = {}
        t = threading.Thread(target=lambda: got.setdefault("y", radio.rx(600_000)))
        t.start()
        deadline = time.monotonic() + 10
        while not radio.receiving and time.monotonic() < deadline:
            time.sleep(0.001)
        stats = radio.tx(tone)
        t.join(30)
    y = got["y"][0]
    assert stats.num_samples == len(tone) and radio.last_counts["rx"].overflows == 0
    assert radio.last_counts["tx"].underflows == 0
    spectrum = np.abs(np.fft.fft(y))
    peak_hz = np.fft.fftfreq(len(spectrum), 1 / fs)[np.argmax(spectrum)]
    assert abs(peak_hz - 100e3) < 2 * fs / len(spectrum)


def ota(tmp_path, images, server_args, *extra):
    out = tmp_path / "ota.json"
    argv = ["ota", "--tx", "soapy", "--rx", "soapy", "--tx-args", server_args]
    argv += ["--schemes", "jscc,digital", "--images", str(images), "--out", str(out)]
    argv += ["--max-images", "3", *extra]
    return main(argv), out


def test_jscc_and_digital_cross_at_10_db_with_no_frame_lost(tmp_path, images, server):
    semcodec = pytest.importorskip("semcodec")
    if not semcodec.DEFAULT_CHECKPOINT.is_file():
        pytest.skip("semcodec's shipped default checkpoint is not in this checkout")
    rc, out = ota(tmp_path, images, server.args, "--snr-db", "10")
    assert rc == 0
    d = json.loads(out.read_text())
    s = d["summary"]
    assert s["frames_sent"] == 12 and s["frames_lost"] == 0
    # the receiver measures Es/N0 per symbol; the emulated air's SNR is over the whole band,
    # of which the frames use 52 of 64 carriers: at most that much above the air's
    assert 10.0 - 0.5 < s["snr_db_measured"] < 10.0 + 10 * math.log10(64 / 52)
    assert {r["scheme"] for r in d["results"]} == {"jscc", "digital"}
    assert "SoapySDR device (emulated)" in open(d["sigmf"][1][: -len("data")] + "meta").read()


def test_an_injected_overflow_is_reported_and_exits_1(tmp_path, images, capsys):
    with serve(fault="overflow", after_samples=50_000) as srv:
        rc, out = ota(tmp_path, images, srv.args, "--snr-db", "10", "--schemes", "digital")
        assert srv.device.overflows == 1
    err = capsys.readouterr().err
    assert rc == 1 and not out.exists()
    assert "1 overflows (SOAPY_SDR_OVERFLOW: samples lost) after 50000 samples, allowed 0" in err
    assert "capture so far saved" in err


def test_an_overflow_reaches_the_counters_when_allowed():
    with serve(fault="overflow", after_samples=10_000) as srv, SoapyRadio.open(srv.args) as r:
        with pytest.warns(UserWarning, match="1 overflows"):
            y = r.rx(100_000, max_shortfalls=1)
        assert r.last_counts["rx"].overflows == 1 and y.shape == (1, 100_000)
    with serve(fault="overflow", after_samples=10_000) as srv, SoapyRadio.open(srv.args) as r:
        with pytest.raises(StreamError, match="1 overflows") as err:
            r.rx(100_000, max_shortfalls=0)
        assert err.value.capture.shape == (1, 10_000)  # what came before the lost samples


def test_a_reader_that_stops_reading_overflows(server):
    """The host stops reading: the flow-control window fills, the device's buffer (half a
    second of blocks) runs over, and the next samples come after SOAPY_SDR_OVERFLOW."""
    import time

    before = server.device.overflows
    dev = SoapySDR.Device(server.args)
    dev.setSampleRate(RX, 0, 4e6)
    stream = dev.setupStream(RX, SoapySDR.SOAPY_SDR_CF32, [0], {"remote:window": str(1 << 20)})
    dev.activateStream(stream)
    buff = np.zeros(1 << 14, np.complex64)
    codes, got = [], 0
    try:
        dev.readStream(stream, [buff], len(buff), timeoutUs=1_000_000)
        time.sleep(1.2)  # a host busy elsewhere
        while got < 4_000_000 and SoapySDR.SOAPY_SDR_OVERFLOW not in codes:
            r = dev.readStream(stream, [buff], len(buff), timeoutUs=1_000_000)
            codes.append(min(r.ret, 0))
            got += max(r.ret, 0)
    finally:
        dev.deactivateStream(stream)
        dev.closeStream(stream)
        dev.close()
    assert SoapySDR.SOAPY_SDR_OVERFLOW in codes and server.device.overflows == before + 1


def test_hil_info_lists_what_enumerate_finds(server, capsys):
    assert main(["hil", "info", "--soapy-args", server.args]) == 0
    out = capsys.readouterr().out
    assert "Found SoapySDR device" in out and "Driver: osnerf" in out
    assert "Frequency range: 3.25e+08-3.8e+09 Hz" in out


def test_a_frequency_outside_the_devices_range_is_a_usage_error(tmp_path, images, server, capsys):
    rc, _ = ota(tmp_path, images, server.args, "--center-freq-hz", "5e9")
    assert rc == 2
    assert "outside the SoapySDR device's range [3.25e+08, 3.8e+09] Hz" in capsys.readouterr().err
    rc, _ = ota(tmp_path, images, server.args, "--rx-gain-db", "75")
    assert rc == 2
    assert "--rx-gain-db 75 dB is outside the device's range [-3, 71] dB" in capsys.readouterr().err


def test_emulate_soapy_serves_until_sigterm_then_exits_0():
    import os
    import signal
    import socket
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    with socket.socket() as s:
        s.bind((ADDRESS, 0))
        port = s.getsockname()[1]
    path = os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONPATH": path}
    code = "import sys; from osnerf.cli import main; sys.exit(main(sys.argv[1:]))"
    argv = ["hil", "emulate", "soapy", "--address", ADDRESS, "--port", str(port)]
    emu = subprocess.Popen(
        [sys.executable, "-c", code, *argv], stderr=subprocess.PIPE, text=True, env=env
    )
    try:
        line = emu.stderr.readline()
        assert f"soapy at driver=remote,remote=tcp://{ADDRESS}:{port}" in line
        found = SoapySDR.Device.enumerate(f"driver=remote,remote=tcp://{ADDRESS}:{port}")
        assert [k["remote:driver"] for k in found] == ["osnerf"]
        emu.send_signal(signal.SIGTERM)
        assert emu.wait(timeout=30) == 0
    finally:
        emu.kill()
