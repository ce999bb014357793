"""`osnerf ota`'s flag values that need more than a type: the radios (``--tx``/``--rx``), a
Pluto's libiio URI (``--uri``), the emulated air's echoes (``--multipath``) and clock
offsets (``--ppm``). Each refusal is one usage error naming the flag."""

from __future__ import annotations

import argparse
import re

import numpy as np

from hil import DEVICES as HARDWARE
from hil.emulation import MAX_MULTIPATH_DELAY, PPM_RANGE
from osnerf.cli import UsageError

DEVICE_KINDS = ("emulated", "loopback", *HARDWARE)  # simulated kinds, then hil's table


def usage_error(msg: str):
    return UsageError(msg)


def parse_device(value: str, name: str) -> tuple[str, str | None]:
    kind, _, serial = value.partition(":")
    bad = kind not in DEVICE_KINDS or (serial and kind not in HARDWARE)
    if bad or (kind == "zmq" and not serial):  # a flowgraph's address is not optional
        raise usage_error(
            f"{name} must be one of {', '.join(DEVICE_KINDS)}, hackrf:SERIAL or zmq:ENDPOINT "
            f"(a ZeroMQ address, e.g. zmq:tcp://127.0.0.1:5555), got {value!r}"
        )
    return kind, serial or None


URI_FORMATS = "ip:HOST[:PORT], usb:[BUS.ADDR.INTF] or local:"
_URI = re.compile(
    r"ip:(?P<host>[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?|\[[0-9A-Fa-f:.]+\])"
    r"(?::(?P<port>\d{1,5}))?|usb:(?:\d{1,3}\.\d{1,3}\.\d{1,3})?|local:"
)


def parse_uri(text: str) -> str:
    """An argparse type for ``--uri``: one of libiio's URIs a Pluto answers at (its port, if
    any, in 1..65535)."""
    m = _URI.fullmatch(text)
    if m is None or (m["port"] is not None and not 1 <= int(m["port"]) <= 65535):
        raise argparse.ArgumentTypeError(f"expected {URI_FORMATS}, got {text!r}")
    return text


def parse_multipath(value: str) -> tuple[tuple[int, complex], ...]:
    if value.strip().lower() in ("", "none"):
        return ()

    out = []
    try:
        for item in value.split(","):
            d, g = item.split(":")
            out.append((int(d), complex(g.replace(" ", ""))))
            if not 1 <= out[-1][0] <= MAX_MULTIPATH_DELAY or not np.isfinite(out[-1][1]):
                raise ValueError
    except ValueError:
        raise usage_error(
            f"--multipath must look like '2:0.4,5:0.2j' (delay_samples in [1, "
            f"{MAX_MULTIPATH_DELAY}]:finite gain) or 'none', got {value!r}"
        ) from None
    return tuple(out)


def parse_ppm(value: str) -> tuple[float, float]:
    lo, hi = PPM_RANGE
    try:
        a, b = (float(v) for v in value.split(","))
        if not (lo <= a <= hi and lo <= b <= hi):  # also false for NaN
            raise ValueError
    except ValueError:
        raise usage_error(
            f"--ppm must be two numbers 'TX,RX' in [{lo:g}, {hi:g}] ppm, e.g. 0,20, got {value!r}"
        ) from None
    return a, b
