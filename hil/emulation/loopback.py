"""A loopback front-end without USB: :class:`hil.HackRF` talking straight to emulated boards.

Same properties, same ``rx`` / ``tx`` and the same requests as over USB, minus pyusb's
per-transfer overhead: for fast simulation of over-the-air runs.
"""

from __future__ import annotations

import numpy as np

from hil.emulation.air import AirChannel
from hil.emulation.hackrf import EmulatedHackRF
from hil.emulation.usb_backend import Emulator
from hil.hackrf import protocol as p
from hil.hackrf.driver import HackRF


class DirectTransport:
    """The transport interface of :class:`hil.HackRF`, calling an emulated board directly."""

    def __init__(self, radio: EmulatedHackRF):
        self.radio = radio

    def control(self, req: p.ControlRequest, timeout_ms: int = p.CONTROL_TIMEOUT_MS):
        arg = req.length if req.is_in else req.data
        return self.radio.control(req.request_type, req.request, req.value, req.index, arg)

    def read(self, num_bytes: int, timeout_ms: int) -> np.ndarray:
        return np.frombuffer(self.radio.bulk_read(num_bytes), dtype=np.int8)

    def write(self, data: bytes, timeout_ms: int) -> int:
        return self.radio.bulk_write(bytes(data))

    def close(self) -> None:
        self.radio.claimed = False


def open_loopback(radio: EmulatedHackRF, **kwargs) -> HackRF:
    """A :class:`hil.HackRF` on one emulated board, without USB."""
    return HackRF(
        DirectTransport(radio),
        serial_number=radio.serial,
        usb_api_version=radio.spec.usb_api_version,
        **kwargs,
    )


def loopback_pair(
    channel: AirChannel | None = None,
    ppm=(0.0, 20.0),
    seed: int = 0,
    wait_for_bursts: int = 1,
    **kwargs,
) -> tuple[HackRF, HackRF, Emulator]:
    """``(tx, rx, emulator)``: two loopback HackRFs sharing one medium."""
    emu = Emulator(channel, ppm=ppm, seed=seed, wait_for_bursts=wait_for_bursts)
    return open_loopback(emu.radios[0], **kwargs), open_loopback(emu.radios[1], **kwargs), emu
