"""hil.Radio: every front end the over-the-air path can drive meets the protocol, and the
over-the-air functions are annotated with it (the type checker proves the front ends'
side in hil.radio)."""

import socket
import typing

import pytest

from hil import (
    EmulatedPluto,
    Emulator,
    HackRF,
    IiodServer,
    Pluto,
    Radio,
    StreamingRadio,
    loopback_pair,
    open_loopback,
    send_blocks,
    stream_over_the_air,
)
from hil.emulation import EmulatedHackRF
from hil.ota.link import transmit_and_capture

RADIO_MEMBERS = {
    "receiving",
    "air_settable",
    "apply_ota_config",
    "set_air",
    "rx",
    "tx",
    "close",
    "last_stats",
    "tx_start_latency_s",
}
STREAMING_MEMBERS = {"emulated_rx_loss", "rx_transfer_samples", "stream"}


def _members(protocol) -> set:
    names = {*vars(protocol), *protocol.__annotations__}
    return {n for n in names if not n.startswith("_")}


def test_the_protocol_is_what_the_ota_path_uses():
    assert _members(Radio) == RADIO_MEMBERS
    assert _members(StreamingRadio) == STREAMING_MEMBERS  # and Radio's, inherited
    for fn in (send_blocks, transmit_and_capture):
        hints = typing.get_type_hints(fn)
        assert hints["tx"] is Radio and hints["rx"] is Radio
    hints = typing.get_type_hints(stream_over_the_air)
    assert hints["tx"] is Radio and hints["rx"] is StreamingRadio


def test_hackrf_front_ends_are_radios():
    emu = Emulator(ppm=(0.0, 0.0))
    with HackRF.open(emu.serials[0], backend=emu.backend) as usb:
        assert isinstance(usb, StreamingRadio)
        assert usb.tx_start_latency_s == 0.0 and not usb.air_settable
        assert usb.emulated_rx_loss is None and usb.rx_transfer_samples == usb.rx_chunk_bytes // 2
    with open_loopback(emu.radios[1]) as direct:
        assert isinstance(direct, Radio)
    tx, rx, _ = loopback_pair()
    with tx, rx:
        assert isinstance(tx, Radio) and isinstance(rx, Radio)
    assert not isinstance(emu.radios[0], Radio)  # a board, not a front end
    assert isinstance(emu.radios[0], EmulatedHackRF)
    assert not isinstance(object(), Radio)


def test_a_pluto_on_the_emulated_board_is_a_radio():
    pytest.importorskip("adi", reason="pyadi-iio (and libiio0) are not installed")
    address = "127.0.0.9"
    with socket.socket() as s:
        s.bind((address, 0))
        port = s.getsockname()[1]
    board = EmulatedPluto.for_link(20.0, seed=1)
    assert not isinstance(board, Radio)
    with IiodServer(board, address, port).serve_in_background() as srv:
        with Pluto.open(srv.uri) as sdr:
            assert isinstance(sdr, StreamingRadio) and sdr.air_settable
            assert sdr.emulated_rx_loss is None  # until a stream ends
