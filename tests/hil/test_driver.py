"""The driver against the emulated board over pyusb: request order, quantisation, TX flush,
first-buffer discard, and faults (stall, timeout, unplug) reported as HilError subclasses."""

import errno
import warnings

import numpy as np
import pytest
import usb.core

from hil import (
    AirChannel,
    DeviceNotFoundError,
    DisconnectedError,
    Emulator,
    HackRF,
    RequestFailedError,
    StallError,
    StreamError,
    UsbTimeoutError,
    open_loopback,
    read_sigmf,
)
from hil.emulation import Faults
from hil.hackrf import protocol

CHUNK = 16384  # small transfers keep the tests fast; a multiple of 512


def ctrl(radio):
    return [e[1] for e in radio.events if e[0] == "ctrl"]


@pytest.fixture
def emu():
    return Emulator(AirChannel(snr_db=30), ppm=(0.0, 0.0), seed=1)


def test_enumerates_like_a_hackrf(emu):
    dev = usb.core.find(idVendor=0x1D50, idProduct=0x6089, backend=emu.backend)
    assert dev.serial_number == emu.serials[0] and len(dev.serial_number) == 32
    assert dev.manufacturer == "Great Scott Gadgets" and dev.product == "HackRF One"
    assert dev.bcdDevice == 0x0108
    intf = dev.get_active_configuration()[(0, 0)]
    assert intf.bInterfaceClass == 0xFF
    assert [(e.bEndpointAddress, e.wMaxPacketSize) for e in intf] == [(0x81, 512), (0x02, 512)]


def test_open_reads_identity_and_configures_in_hackrf_transfer_order(emu):
    with HackRF.open(backend=emu.backend) as sdr:
        assert sdr.board_id == 2 and sdr.firmware_version == "2024.02.1"
        assert sdr.serial_number == emu.serials[0] and sdr.part_id == (0xA000CB3C, 0x00574F61)
        sent = ctrl(emu.radios[0])
        assert [r.request for r in sent] == [14, 15, 18, 1, 6, 7, 29, 16, 17, 23]
        assert sent[4].data.hex() == "8096980001000000"  # 10 MS/s
        assert (sent[5].value | sent[5].index << 16) == 7_000_000  # automatic filter after the rate
        assert "sample_rate_hz=10000000.0" in repr(sdr)


def test_open_by_serial_tail_and_missing(emu):
    with HackRF.open(emu.serials[1][-4:], backend=emu.backend) as sdr:
        assert sdr.serial_number == emu.serials[1]
    with pytest.raises(DeviceNotFoundError, match="serial ending 'ffff'"):
        HackRF.open("ffff", backend=emu.backend)


def test_properties_quantise_and_read_back(emu):
    with HackRF.open(backend=emu.backend) as sdr:
        radio = emu.radios[0]
        sdr.sample_rate_hz = 2e6
        assert sdr.sample_rate_hz == 2e6 and sdr.baseband_filter_hz == 1_750_000
        assert ctrl(radio)[-2].data.hex() == "80841e0001000000"
        sdr.baseband_filter_hz = 5.2e6
        assert sdr.baseband_filter_hz == 5_000_000 and radio.baseband_filter_hz == 5_000_000
        sdr.center_freq_hz = 433.92e6
        assert ctrl(radio)[-1].data.hex() == "b1010000c0090e00" and radio.center_freq_hz == 433.92e6
        sdr.lna_gain_db, sdr.vga_gain_db, sdr.txvga_gain_db = 39, 33, 47
        assert (sdr.lna_gain_db, sdr.vga_gain_db, sdr.txvga_gain_db) == (32, 32, 47)
        assert (radio.lna_gain_db, radio.vga_gain_db, radio.txvga_gain_db) == (32, 32, 47)
        sdr.amp_enabled, sdr.bias_tee_enabled = True, True
        assert radio.amp_enabled and radio.bias_tee_enabled
        with pytest.raises(ValueError, match=r"lna_gain_db must be in \[0, 40\] dB"):
            sdr.lna_gain_db = 48
        with pytest.raises(ValueError, match=r"sample_rate_hz must be in"):
            sdr.sample_rate_hz = 30e6
        assert (
            sdr.lna_gain_db == 32 and sdr.sample_rate_hz == 2e6
        )  # unchanged after a refused value


def test_rx_request_order_and_first_buffer_discarded(emu):
    with HackRF.open(backend=emu.backend, rx_chunk_bytes=CHUNK) as sdr:
        radio = emu.radios[0]
        start = len(radio.events)
        x = sdr.rx(3 * CHUNK // 2)
        assert x.shape == (1, 3 * CHUNK // 2) and x.dtype == np.complex64
        sent = [r for r in ctrl(radio)[-7:]]
        after = [e for e in radio.events[start:]]
        kinds = [(e[0], e[1].request if e[0] == "ctrl" else e[1]) for e in after]
        assert kinds[:3] == [("ctrl", 20), ("ctrl", 19), ("ctrl", 1)]
        assert after[2][1].value == 1  # mode receive after VGA then LNA
        assert ("ctrl", 1) in kinds[3:] and sent[-1].request == 41  # mode off, then M0 state
        # the stale first buffer (every byte 100) is thrown away and not counted as signal
        assert sdr.last_stats.discarded_bytes == CHUNK
        assert not np.any(np.isclose(x.real, 100 / 128) & np.isclose(x.imag, 100 / 128))
        assert radio.rx_cursor >= 3 * CHUNK // 4  # the medium only advanced by the real buffers


def test_exactly_one_buffer_is_discarded():
    """With a stale first buffer the host gets the medium's samples from 0; without one,
    the driver still drops one buffer, so its output starts one transfer later."""
    outs = {}
    for stale in (True, False):
        emu = Emulator(AirChannel(snr_db=20), ppm=(0.0,), seed=3)
        emu.radios[0].faults.stale_first_buffer = stale
        with HackRF.open(backend=emu.backend, rx_chunk_bytes=CHUNK) as sdr:
            outs[stale] = sdr.rx(CHUNK)
            assert sdr.last_stats.discarded_bytes == CHUNK
    half = CHUNK // 2  # samples per transfer
    assert np.array_equal(outs[True][:, half:], outs[False][:, :half])
    assert not np.array_equal(outs[True][:, :half], outs[False][:, :half])


def test_tx_pads_flushes_and_waits_before_mode_off(emu):
    with HackRF.open(backend=emu.backend) as sdr:
        sdr.sample_rate_hz = 20e6
        radio = emu.radios[0]
        start = len(radio.events)
        n = 1000 + protocol.TRANSFER_BYTES // 2  # one full transfer + 2000 bytes
        rng = np.random.default_rng(0)
        x = (rng.uniform(-0.9, 0.9, n) + 1j * rng.uniform(-0.9, 0.9, n)).astype(np.complex64)
        sdr.tx(x)
        ev = radio.events[start:]
        assert [e[1].request for e in ev[:2]] == [21, 1] and ev[1][1].value == 2
        writes = [e[1] for e in ev if e[0] == "write"]
        assert [len(w) for w in writes] == [262144, 2048, 32768]
        sent = np.frombuffer(writes[0] + writes[1], np.int8)
        expected = np.clip(np.round(x.view(np.float32).astype(np.float64) * 128), -128, 127).astype(
            np.int8
        )
        assert np.array_equal(sent[: 2 * n], expected)
        assert not np.any(sent[2 * n :]) and not any(writes[2])  # zero padding and the zero flush
        i_flush = next(i for i, e in enumerate(ev) if e[0] == "write" and len(e[1]) == 32768)
        after = [e[1] for e in ev[i_flush + 1 :]]
        assert after[0].request == 1 and after[0].value == 0  # mode off only after the flush
        assert radio.mode == 0 and sdr.last_stats.num_samples == n


def test_tx_validates_full_scale(emu):
    with HackRF.open(backend=emu.backend) as sdr:
        with pytest.raises(ValueError, match="full scale"):
            sdr.tx(np.array([1.5 + 0j]))
        with pytest.raises(ValueError, match="samples must be"):
            sdr.tx(np.zeros((2, 3), np.complex64))


def test_stall_becomes_stall_error_from_usb_error(emu):
    with HackRF.open(backend=emu.backend) as sdr:
        emu.radios[0].faults.stall_requests = {16}
        with pytest.raises(StallError, match="set frequency") as ei:
            sdr.center_freq_hz = 915e6
        assert (
            isinstance(ei.value.__cause__, usb.core.USBError)
            and ei.value.__cause__.errno == errno.EPIPE
        )
        assert sdr.center_freq_hz == 2_450_000_000


def test_firmware_stalls_on_illegal_values(emu):
    dev = usb.core.find(idVendor=0x1D50, backend=emu.backend)
    import struct

    with pytest.raises(usb.core.USBError) as ei:
        dev.ctrl_transfer(0x40, 16, 0, 0, struct.pack("<II", 7300, 0))
    assert ei.value.errno == errno.EPIPE
    with pytest.raises(usb.core.USBError) as ei:
        dev.ctrl_transfer(0x40, 1, 3, 0, None)  # unknown transceiver mode
    assert ei.value.errno == errno.EPIPE
    assert bytes(dev.ctrl_transfer(0xC0, 19, 0, 48, 1)) == b"\x00"  # LNA 48 dB refused: reply 0
    assert bytes(dev.ctrl_transfer(0xC0, 19, 0, 24, 1)) == b"\x01"


def test_refused_gain_is_request_failed(emu):
    with HackRF.open(backend=emu.backend) as sdr:
        with pytest.raises(RequestFailedError, match="refused gain 48"):
            sdr._gain_request(protocol.ControlRequest(0xC0, 19, 0, 48, b"", 1), "set LNA gain")


def test_timeout_mid_stream_saves_capture_and_switches_off(emu, tmp_path):
    with HackRF.open(backend=emu.backend, rx_chunk_bytes=CHUNK) as sdr:
        radio = emu.radios[0]
        radio.faults.read_timeout_after_bytes = 3 * CHUNK  # stale + 2 good buffers, then silence
        with pytest.raises(UsbTimeoutError) as ei:
            sdr.rx(10 * CHUNK, save_to=tmp_path / "cap")
        err = ei.value
        assert err.capture.shape == (1, CHUNK) and err.sigmf_path is not None
        rec = read_sigmf(err.sigmf_path)
        assert rec.datatype == "ci8" and np.array_equal(rec.samples, err.capture[0])
        assert radio.mode == 0 and not sdr.receiving


def test_unplug_mid_stream_is_disconnected_error(emu, tmp_path):
    sdr = HackRF.open(backend=emu.backend, rx_chunk_bytes=CHUNK)
    emu.radios[0].faults.unplug_after_bytes = 2 * CHUNK
    with pytest.raises(DisconnectedError, match="gone") as ei:
        sdr.rx(10 * CHUNK, save_to=tmp_path / "cap")
    assert ei.value.capture.shape == (1, CHUNK // 2)
    assert read_sigmf(tmp_path / "cap").samples.shape == (CHUNK // 2,)
    sdr.close()  # closing a vanished board does not raise
    with pytest.raises(DeviceNotFoundError):
        HackRF.open(emu.serials[0], backend=emu.backend)


def test_overruns_from_m0_state(emu):
    with HackRF.open(backend=emu.backend, rx_chunk_bytes=CHUNK) as sdr:
        emu.radios[0].faults.shortfalls = 3
        with pytest.warns(UserWarning, match="overruns"):
            sdr.rx(CHUNK)
        assert sdr.last_stats.device_shortfalls == 3 and not sdr.last_stats.clean
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with pytest.raises(StreamError, match="3 overruns"):
                sdr.rx(CHUNK, max_shortfalls=0)


def test_old_firmware_without_m0_state():
    emu = Emulator(ppm=(0.0,), usb_api_version=0x0104)
    with HackRF.open(backend=emu.backend, rx_chunk_bytes=CHUNK) as sdr:
        sdr.rx(1000)
        assert sdr.m0_state() is None and sdr.last_stats.device_shortfalls == -1


def test_stream_iterator_is_continuous():
    emu = Emulator(AirChannel(snr_db=20), ppm=(0.0,), seed=5)
    with open_loopback(emu.radios[0], rx_chunk_bytes=CHUNK) as sdr:
        blocks = []
        for block in sdr.stream(chunk_samples=3000):
            blocks.append(block)
            if len(blocks) == 4:
                break
        assert not sdr.receiving and emu.radios[0].mode == 0
    emu2 = Emulator(AirChannel(snr_db=20), ppm=(0.0,), seed=5)
    with open_loopback(emu2.radios[0], rx_chunk_bytes=CHUNK) as sdr:
        whole = sdr.rx(12000)
    assert np.array_equal(np.concatenate(blocks, axis=1), whole)


def test_timeout_before_any_data_is_a_timeout_and_writes_nothing(emu, tmp_path):
    """A USB timeout inside the stale first buffer, before any sample arrived, raises a
    UsbTimeoutError saying no capture was saved, with an empty capture, and writes no SigMF
    file (no 0-byte .sigmf-data without its .sigmf-meta)."""
    emu.radios[0].faults.read_timeout_after_bytes = 100_000
    with HackRF.open(backend=emu.backend) as sdr:
        with pytest.raises(UsbTimeoutError, match="no capture was saved") as ei:
            sdr.rx(500_000, save_to=tmp_path / "cap")
    assert ei.value.capture.shape == (1, 0) and ei.value.sigmf_path is None
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "name, error", [("rx-timeout", UsbTimeoutError), ("unplug", DisconnectedError)]
)
def test_named_fault_stops_after_exactly_that_many_samples(emu, tmp_path, name, error):
    emu.radios[0].faults = Faults.named(name, after_samples=1000)
    sdr = HackRF.open(backend=emu.backend, rx_chunk_bytes=CHUNK)
    with pytest.raises(error) as ei:
        sdr.rx(10 * CHUNK, save_to=tmp_path / "cap")
    sdr.close()
    assert ei.value.capture.shape == (1, 1000)
    assert read_sigmf(ei.value.sigmf_path).samples.shape == (1000,)


def test_overrun_beyond_the_limit_keeps_the_capture(emu, tmp_path):
    emu.radios[0].faults = Faults.named("overrun")
    with HackRF.open(backend=emu.backend, rx_chunk_bytes=CHUNK) as sdr:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with pytest.raises(StreamError, match="3 overruns") as ei:
                sdr.rx(CHUNK, max_shortfalls=0, save_to=tmp_path / "cap")
    assert read_sigmf(ei.value.sigmf_path).samples.shape == (CHUNK,)


def test_unknown_fault_name_lists_the_known_ones():
    with pytest.raises(KeyError, match="rx-timeout"):
        Faults.named("meteor")
