"""The emulated Pluto under the real clients: libiio-utils' iio_info, pyadi-iio, hil.Pluto.

The emulator serves iiod's network protocol on a loopback address (a fixture, free port);
libiio 0.24 (Debian libiio0) and pyadi-iio talk to it exactly as to a board.
"""

import errno
import shutil
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

adi = pytest.importorskip("adi", reason="pyadi-iio (and libiio0) are not installed")

from hil import (  # noqa: E402
    DEVICES,
    DeviceNotFoundError,
    EmulatedPluto,
    IiodServer,
    Pluto,
    RequestFailedError,
)

ADDRESS = "127.0.0.7"


def free_port(address: str = ADDRESS) -> int:
    with socket.socket() as s:
        s.bind((address, 0))
        return s.getsockname()[1]


@pytest.fixture
def server():
    board = EmulatedPluto.for_link(20.0, seed=1)
    with IiodServer(board, ADDRESS, free_port()).serve_in_background() as srv:
        yield srv


def test_pluto_is_in_the_one_device_table():
    kind = DEVICES["pluto"]
    assert kind.full_duplex and kind.emulator is not None and kind.id_name == "uri"
    assert not DEVICES["hackrf"].full_duplex


@pytest.mark.skipif(shutil.which("iio_info") is None, reason="libiio-utils is not installed")
def test_iio_info_lists_the_three_devices(server):
    out = subprocess.run(
        ["iio_info", "-u", server.uri], capture_output=True, text=True, timeout=60, check=True
    ).stdout
    assert "IIO context has 3 devices:" in out
    for dev in ("ad9361-phy", "cf-ad9361-lpc", "cf-ad9361-dds-core-lpc"):
        assert f": {dev}" in out
    assert "voltage0:  (input, index: 0, format: le:S12/16>>0)" in out
    assert "frequency_available value: [325000000 1 3800000000]" in out


def test_pyadi_reads_back_what_the_ad9361_makes_of_each_value(server):
    sdr = adi.Pluto(server.uri)
    # RF PLL: VCO = 4 x 2450000123 = 9800000492 Hz = 40 MHz x (245 + 103 / 8388593) -> the
    # VCO runs at 9800000491.14, the LO at a quarter of that, read back to the hertz below
    sdr.rx_lo = 2_450_000_123
    assert sdr.rx_lo == 2_450_000_122
    sdr.tx_lo = 2_400_000_000  # on the grid: 4 x 2.4 GHz = 240 x 40 MHz
    assert sdr.tx_lo == 2_400_000_000
    # 1 MS/s needs the FIR's decimation by 4 (pyadi-iio loads it); the clock chain
    # (BBPLL fractional-N, integer dividers) lands on an integer near the request
    sdr.sample_rate = 1_000_000
    assert abs(sdr.sample_rate - 1_000_000) <= 2 and sdr.sample_rate == int(sdr.sample_rate)
    assert list(sdr.filter) == [128, 4, 128, 4]  # the driver's summary: taps, decimation
    sdr.sample_rate = 3_000_001
    assert sdr.sample_rate != 3_000_001 and abs(sdr.sample_rate - 3_000_001) <= 10
    sdr.rx_rf_bandwidth = 3_000_000
    assert sdr.rx_rf_bandwidth == 3_000_000
    sdr.tx_hardwaregain_chan0 = -10.3  # 0.25 dB attenuation steps, truncated
    assert sdr.tx_hardwaregain_chan0 == -10.25
    sdr.gain_control_mode_chan0 = "manual"
    assert sdr.gain_control_mode_chan0 == "manual"
    sdr.rx_hardwaregain_chan0 = 40.7  # whole dB
    assert sdr.rx_hardwaregain_chan0 == 40
    for name, bad in [
        ("tx_hardwaregain_chan0", 3),  # attenuation only
        ("rx_hardwaregain_chan0", 72),  # -3..71 dB between 1.3 and 4 GHz
        ("rx_lo", 4_000_000_000),  # a stock Pluto's AD9363 stops at 3.8 GHz
        ("rx_rf_bandwidth", 25_000_000),
        ("gain_control_mode_chan0", "loud"),
    ]:
        with pytest.raises(OSError) as e:
            setattr(sdr, name, bad)
        assert e.value.errno == errno.EINVAL, name
    assert sdr.rx_hardwaregain_chan0 == 40 and sdr.rx_lo == 2_450_000_122  # unchanged


def test_cyclic_tone_comes_back_at_its_frequency_plus_the_lo_offset(server):
    sdr = adi.Pluto(server.uri)
    sdr.sample_rate = 4_000_000
    fs = sdr.sample_rate
    sdr.rx_lo = 2_450_000_000
    sdr.tx_lo = 2_450_050_000
    offset = sdr.tx_lo - sdr.rx_lo
    n = 4096
    k = 205  # whole cycles per buffer: a cyclic buffer repeats without a seam
    sdr.tx_cyclic_buffer = True
    sdr.tx(0.5 * 2**14 * np.exp(2j * np.pi * k * np.arange(n) / n))
    sdr.rx_buffer_size = 1 << 16
    x = sdr.rx()
    sdr.tx_destroy_buffer()
    spectrum = np.abs(np.fft.fft(x)) ** 2
    freqs = np.fft.fftfreq(len(x), 1 / fs)
    peak = freqs[np.argmax(spectrum)]
    assert abs(peak - (k * fs / n + offset)) <= fs / len(x)
    assert spectrum.max() > 1000 * np.median(spectrum)  # a tone, not noise


def test_front_end_interface(server):
    with Pluto.open(server.uri) as sdr:
        sdr.sample_rate_hz = 4e6
        sdr.center_freq_hz = 915e6
        assert sdr.rx_lo_hz == sdr.tx_lo_hz == 915_000_000
        sdr.rx_gain_db = 40.7
        assert sdr.rx_gain_db == 40
        assert sdr.rf_bandwidth_hz == 4_000_000  # the rate sets the analog filter to match
        assert "sample_rate_hz=4000000" in repr(sdr) and "rx_gain_db=40.0" in repr(sdr)
        with pytest.raises(ValueError, match="tx_gain_db must be in"):
            sdr.tx_gain_db = 1
        with pytest.raises(RequestFailedError, match="set RX LO: the driver refused"):
            sdr.rx_lo_hz = 5e9
        iq = sdr.rx(10_000)
        assert iq.shape == (1, 10_000) and iq.dtype == np.complex64
        assert np.abs(iq.view(np.float32)).max() <= 1.0
        # the noise at the ADC: 20 dB below -9 dBFS at the reference gain (30 dB); 40 dB: +10 dB
        noise_dbfs = 10 * np.log10(np.mean(np.abs(iq) ** 2))
        assert noise_dbfs == pytest.approx(-9 - 20 + 10, abs=0.5)
        with pytest.raises(ValueError, match="full scale"):
            sdr.tx(np.full(10, 1.5))
    assert "closed" in repr(sdr)


def test_unreachable_address_names_it():
    uri = f"ip:127.0.0.2:{free_port('127.0.0.2')}"
    with pytest.raises(DeviceNotFoundError, match=f"no Pluto at {uri}"):
        Pluto.open(uri)


_CYCLE = """
import gc, sys
from hil.pluto.iio_access import import_iio
iio = import_iio()
gc.disable()
ctx = iio.Context(sys.argv[1])
dev = ctx.find_device("cf-ad9361-lpc")
dev.channels[0].enabled = True
held = {"context": ctx, "buffer": iio.Buffer(dev, 1024)}
held["cycle"] = held
del ctx, dev, held
gc.collect()
print("collected")
"""


def test_a_buffer_and_its_context_in_one_cycle_are_collected_safely(server):
    """The collector finalises a cycle in any order; pylibiio alone may destroy the context
    first and then the buffer through it (a crash: run the same with ``__import__("iio")``);
    through ``import_iio`` the context destroys its buffers first."""
    run = subprocess.run(
        [sys.executable, "-c", _CYCLE, server.uri], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0 and run.stdout.strip() == "collected", run.stderr


def test_server_refuses_a_non_loopback_address():
    with pytest.raises(ValueError, match="127.0.0.0/8"):
        IiodServer(EmulatedPluto(), "10.0.0.1", 0)


def test_a_tx_buffer_fed_late_underruns_instead_of_stalling_the_receiver(server):
    """An open, streamed TX buffer whose data stops: the board sends silence (an underrun,
    counted) and the receiver goes on; what is written later is received later."""

    sdr = adi.Pluto(server.uri)
    sdr.sample_rate = 4_000_000
    sdr.rx_lo = sdr.tx_lo = 2_450_000_000  # (the board starts with them 50 MHz apart)
    sdr.tx_cyclic_buffer = False
    sdr.rx_buffer_size = 1 << 14
    sdr.rx()  # the RX stream is live
    tone = np.full(1 << 14, 8000 + 0j)  # -12 dBFS: about 17 dB above the noise here
    sdr.tx(tone)  # TX open and streaming, then nothing
    t0 = time.monotonic()
    first = np.concatenate([sdr.rx() for _ in range(8)])
    assert time.monotonic() - t0 < 10 and server.board.tx_underruns == 1
    sdr.tx(tone)  # fed again, late
    later = np.concatenate([sdr.rx() for _ in range(24)])
    sdr.tx_destroy_buffer()
    noise = np.median(np.abs(np.concatenate([first, later])) ** 2)  # mostly silence
    heard = [int(np.sum(np.abs(x) ** 2 > 15 * noise)) for x in (first, later)]
    # the first burst once and whole, then silence, wherever it falls across the buffers;
    # the late one arrives later (the emulator may cut the part that lands in receive
    # buffers it had already rendered), never twice
    assert heard[0] == pytest.approx(tone.size, rel=0.05)
    assert 50 < heard[1] <= 1.05 * tone.size


def test_a_transmission_starting_during_a_receive_read_is_heard_whole():
    """The TX buffer opens while a receive read is being rendered (the two run on separate
    connections): the burst starts after the samples of that read, none of it is lost."""
    board = EmulatedPluto.for_link(20.0, seed=1)
    board.tx_lo_hz = board.rx_lo_hz  # (the board starts with them 50 MHz apart)
    board.open_rx()
    render = board.medium.render_iq
    burst = np.zeros(2 * 4096, np.int16)
    burst[0::2] = 16000  # a 4096-sample tone at DC, about -6 dBFS
    started = []

    def render_then_start_tx(*args, **kwargs):
        y = render(*args, **kwargs)  # this read's samples are decided ...
        if not started:  # ... and then the transmitter starts, before the read returns
            started.append(True)
            board.open_tx(cyclic=False)
            board.write_tx(burst)
            board.close_tx()
        return y

    board.medium.render_iq = render_then_start_tx
    iq = np.concatenate([board.read_rx(8192) for _ in range(4)]).astype(np.float32)
    power = iq[0::2] ** 2 + iq[1::2] ** 2
    loud = power > 30 * np.median(power)
    assert not loud[:8192].any()  # the read in flight is noise alone
    assert abs(int(loud.sum()) - 4096) <= 64  # the whole burst (filter edges aside)
