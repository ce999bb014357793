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
    loopback_pair,
    open_loopback,
    send_blocks,
)
from hil.emulation import EmulatedHackRF
from hil.ota.link import transmit_and_capture

RADIO_MEMBERS = {"receiving", "rx", "tx", "close"}


def test_the_protocol_is_what_the_ota_path_uses():
    members = {n for n in vars(Radio) if not n.startswith("_")}
    assert members == RADIO_MEMBERS
    for fn in (send_blocks, transmit_and_capture):
        hints = typing.get_type_hints(fn)
        assert hints["tx"] is Radio and hints["rx"] is Radio


def test_hackrf_front_ends_are_radios():
    emu = Emulator(ppm=(0.0, 0.0))
    with HackRF.open(emu.serials[0], backend=emu.backend) as usb:
        assert isinstance(usb, Radio)
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
            assert isinstance(sdr, Radio)
