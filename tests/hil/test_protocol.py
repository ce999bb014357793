"""Every control request the driver builds, byte for byte against the protocol reference."""

import pytest

from hil.hackrf import M0State, protocol


@pytest.mark.parametrize(
    "rate_hz, payload_hex, filter_hz",
    [
        (2e6, "80841e0001000000", 1_750_000),
        (10e6, "8096980001000000", 7_000_000),
        (20e6, "002d310101000000", 15_000_000),
    ],
)
def test_sample_rate_payload_and_auto_filter(rate_hz, payload_hex, filter_hz):
    req = protocol.set_sample_rate(rate_hz)
    assert (req.request_type, req.request, req.value, req.index) == (0x40, 6, 0, 0)
    assert req.data.hex() == payload_hex
    assert protocol.auto_baseband_filter_hz(rate_hz) == filter_hz
    f = protocol.set_baseband_filter(filter_hz)
    assert (f.request_type, f.request, f.data) == (0x40, 7, b"")
    assert f.value == filter_hz & 0xFFFF and f.index == filter_hz >> 16
    assert f.value | (f.index << 16) == filter_hz


def test_sample_rate_fractional_divider():
    # 10/3 MS/s needs divider 3 to be integral: 10 MHz / 3
    assert protocol.sample_rate_params(10e6 / 3) == (10_000_000, 3)
    assert protocol.set_sample_rate(10e6 / 3).data.hex() == "8096980003000000"


@pytest.mark.parametrize("bad", [1.9e6, 20.5e6, float("nan")])
def test_sample_rate_range_named(bad):
    with pytest.raises(ValueError, match=r"sample_rate_hz must be in \[2e\+06, 2e\+07\]"):
        protocol.set_sample_rate(bad)


@pytest.mark.parametrize(
    "freq_hz, payload_hex",
    [(2.4e9, "6009000000000000"), (915e6, "9303000000000000"), (433.92e6, "b1010000c0090e00")],
)
def test_frequency_payload(freq_hz, payload_hex):
    req = protocol.set_frequency(freq_hz)
    assert (req.request_type, req.request, req.value, req.index) == (0x40, 16, 0, 0)
    assert req.data.hex() == payload_hex


def test_frequency_range_named():
    with pytest.raises(ValueError, match="center_freq_hz must be in"):
        protocol.set_frequency(6.5e9)


@pytest.mark.parametrize(
    "builder, asked, sent, number",
    [
        (protocol.set_lna_gain, 17, 16, 19),
        (protocol.set_lna_gain, 40, 40, 19),
        (protocol.set_lna_gain, 7.9, 0, 19),
        (protocol.set_vga_gain, 33, 32, 20),
        (protocol.set_vga_gain, 62, 62, 20),
        (protocol.set_txvga_gain, 47, 47, 21),
        (protocol.set_txvga_gain, 12.7, 12, 21),
    ],
)
def test_gain_requests_quantised(builder, asked, sent, number):
    req = builder(asked)
    assert (req.request_type, req.request, req.value, req.index, req.length) == (
        0xC0,
        number,
        0,
        sent,
        1,
    )


@pytest.mark.parametrize(
    "builder, bad, name",
    [
        (protocol.set_lna_gain, 41, "lna_gain_db must be in \\[0, 40\\]"),
        (protocol.set_vga_gain, -1, "vga_gain_db must be in \\[0, 62\\]"),
        (protocol.set_txvga_gain, 48, "txvga_gain_db must be in \\[0, 47\\]"),
    ],
)
def test_gain_range_named(builder, bad, name):
    with pytest.raises(ValueError, match=name):
        builder(bad)


def test_simple_requests():
    assert protocol.set_transceiver_mode(0) == protocol.ControlRequest(0x40, 1, 0, 0)
    assert (
        protocol.set_transceiver_mode(1).value == 1 and protocol.set_transceiver_mode(2).value == 2
    )
    with pytest.raises(ValueError, match="mode must be one of"):
        protocol.set_transceiver_mode(3)
    assert protocol.set_amp_enable(True) == protocol.ControlRequest(0x40, 17, 1, 0)
    assert protocol.set_antenna_enable(True) == protocol.ControlRequest(0x40, 23, 1, 0)
    assert protocol.set_hw_sync_mode(False) == protocol.ControlRequest(0x40, 29, 0, 0)
    assert protocol.read_board_id() == protocol.ControlRequest(0xC0, 14, 0, 0, b"", 1)
    assert protocol.read_version_string() == protocol.ControlRequest(0xC0, 15, 0, 0, b"", 255)
    assert protocol.read_partid_serial() == protocol.ControlRequest(0xC0, 18, 0, 0, b"", 24)
    assert protocol.read_m0_state() == protocol.ControlRequest(0xC0, 41, 0, 0, b"", 40)


def test_baseband_filter_round_down():
    assert protocol.baseband_filter_round_down(5.2e6) == 5_000_000
    assert protocol.baseband_filter_round_down(1e6) == 1_750_000
    assert protocol.baseband_filter_round_down(30e6) == 28_000_000
    with pytest.raises(ValueError, match="baseband_filter_hz must be one of"):
        protocol.set_baseband_filter(4_000_000)


def test_m0_state_and_serial_layouts():
    m0 = M0State(2, 0, 2, 1024, 2048, 3, 512, 0, 0, 0, 0)
    raw = m0.pack()
    assert len(raw) == 40 and raw[:8].hex() == "0200000002000000" and raw[16:20].hex() == "03000000"
    assert M0State.unpack(raw) == m0
    payload = bytes.fromhex("3ccb00a0614f57000000000000000000dc68b057403d2e1f")
    part, serial = protocol.parse_partid_serial(payload)
    assert part == (0xA000CB3C, 0x00574F61)
    assert serial == "000000000000000057b068dc1f2e3d40"
    assert protocol.usb_api_version_string(0x0108) == "1.08"
