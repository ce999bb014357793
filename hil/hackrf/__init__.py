"""The HackRF One on pure pyusb: its USB protocol, driver, settings, receive stream and the
loopback without USB."""

from hil.hackrf import protocol
from hil.hackrf.driver import HackRF
from hil.hackrf.protocol import (
    BOARD_IDS,
    FREQ_RANGE_HZ,
    SAMPLE_RATE_RANGE_HZ,
    ControlRequest,
    M0State,
    usb_api_version_string,
)
from hil.hackrf.stream import StreamStats
from hil.hackrf.usb_transport import find_hackrfs

__all__ = [
    "BOARD_IDS",
    "ControlRequest",
    "FREQ_RANGE_HZ",
    "HackRF",
    "M0State",
    "SAMPLE_RATE_RANGE_HZ",
    "StreamStats",
    "find_hackrfs",
    "protocol",
    "usb_api_version_string",
]
