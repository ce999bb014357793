"""hil's one table of hardware front ends: ``DEVICES`` (name -> :class:`DeviceKind`).

Every list of device names elsewhere (``osnerf ota --tx``, ``osnerf run --ota-device``,
``osnerf hil info``) is derived from it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from common import Registry
from hil.emulation.iiod import IIOD_PORT, IiodServer
from hil.emulation.pluto import EmulatedPluto
from hil.emulation.soapy_device import EmulatedSoapyDevice
from hil.emulation.soapy_remote import SoapyRemoteServer
from hil.emulation.soapy_rpc import DEFAULT_PORT as SOAPY_REMOTE_PORT
from hil.errors import DeviceNotFoundError
from hil.hackrf import protocol
from hil.hackrf.driver import HackRF
from hil.hackrf.usb_transport import find_hackrfs
from hil.pluto import ad9361
from hil.pluto.driver import Pluto
from hil.pluto.iio_access import find_plutos
from hil.soapy.driver import SoapyRadio, find_soapy_devices
from hil.zmq.radio import ZmqRadio


@dataclass(frozen=True)
class DeviceKind:
    """One family of SDR front ends.

    Attributes:
        name: the key in :data:`DEVICES`.
        label: what SigMF files and reports call it (``core:hw``).
        id_name: what picks one board (a HackRF's serial, a Pluto's libiio URI).
        full_duplex: one board can transmit and receive at once (a whole link).
        find: ``() -> [id, ...]`` of the boards present.
        open: ``(id or None) -> device`` (None: the first found).
        emulator: ``(snr_db, **kwargs) -> board`` for a board served over the network
            (:meth:`hil.EmulatedPluto.for_link`), or None.
        center_freq_range_hz: the LO range it tunes, (low, high) Hz.
        sample_rate_range_hz: the sample rates it runs at, (low, high) S/s.
        part: what fixes those ranges, for messages (the RF chip).
        serve: ``(board, address, port) -> server`` that serves an emulated board over the
            network (``osnerf hil emulate``), or None.
        default_port: the TCP port such a server listens on by default.
        device_ranges: ``(id) -> {"center_freq_range_hz": ..., "sample_rate_range_hz": ...}``
            asked of the device itself (a SoapySDR device's ``get*Range``), or None: the
            fixed ranges above.
        open_link: ``(tx_id, rx_id) -> (tx, rx)`` where one object is both ends whatever
            the ids (the ZMQ radio: two endpoints, one clock), or None.
    """

    name: str
    label: str
    id_name: str
    full_duplex: bool
    find: Callable[[], list]
    open: Callable
    emulator: Callable | None = None
    center_freq_range_hz: tuple[float, float] = (0.0, float("inf"))
    sample_rate_range_hz: tuple[float, float] = (0.0, float("inf"))
    part: str = ""
    serve: Callable | None = None
    default_port: int = 0
    device_ranges: Callable | None = None
    open_link: Callable | None = None

    def ranges_of(self, ids) -> tuple[tuple[float, float], tuple[float, float], str]:
        """``(center_freq_range_hz, sample_rate_range_hz, part)`` of the boards ``ids``
        name: the device's own where it reports them (every board in ``ids`` opened and
        asked), else the fixed ranges of this kind."""
        if self.device_ranges is None:
            return self.center_freq_range_hz, self.sample_rate_range_hz, self.part
        asked = [self.device_ranges(i) for i in dict.fromkeys(ids)]

        def both(key: str) -> tuple[float, float]:  # what every board reaches
            return (max(r[key][0] for r in asked), min(r[key][1] for r in asked))

        parts = ", ".join(r["part"] for r in asked)
        return both("center_freq_range_hz"), both("sample_rate_range_hz"), parts

    def open_pair(self, tx_id: str | None = None, rx_id: str | None = None):
        """``(tx, rx)`` for a link: a full-duplex kind uses one board for both ends unless
        two ids are given; a half-duplex one needs two boards.

        Raises:
            DeviceNotFoundError: a board is missing (only one half-duplex board present).
        """
        if self.open_link is not None:
            return self.open_link(tx_id, rx_id)
        tx = self.open(tx_id)
        if self.full_duplex and (rx_id is None or rx_id == tx_id):
            return tx, tx
        try:
            if rx_id is None:
                own = getattr(tx, "serial_number", None)
                others = [i for i in self.find() if i != own]
                if not others:
                    raise DeviceNotFoundError(
                        f"only one {self.label} found: over the air needs two (TX and RX; "
                        f"osnerf ota: --rx {self.name}:{self.id_name.upper()})"
                    )
                rx_id = others[0]
            rx = self.open(rx_id)
        except BaseException:
            tx.close()
            raise
        return tx, rx


def _find_hackrfs() -> list:
    return [d.serial_number for d in find_hackrfs()]


def _open_hackrf(serial=None):
    return HackRF.open(serial)


def _emulated_pluto(snr_db: float, **kwargs):
    return EmulatedPluto.for_link(snr_db, **kwargs)


def _serve_iiod(board, address: str, port: int):
    return IiodServer(board, address, port)


def _find_plutos() -> list:
    return [uri for uri, _ in find_plutos()]


def _open_pluto(uri=None):
    return Pluto.open(uri)


def _find_soapy() -> list:
    return find_soapy_devices()


def _open_soapy(args=None):
    return SoapyRadio.open(args)


def _soapy_ranges(args) -> dict:
    with SoapyRadio.open(args) as radio:
        r = radio.ranges()
        return {**r, "part": f"{radio.hardware_key} via SoapySDR driver {radio.driver_key}"}


def _emulated_soapy(snr_db: float, **kwargs):
    return EmulatedSoapyDevice.for_link(snr_db, **kwargs)


def _serve_soapy_remote(device, address: str, port: int):
    return SoapyRemoteServer(device, address, port)


def _open_zmq(endpoint=None):
    return ZmqRadio(endpoint, None)


def _open_zmq_link(tx_endpoint, rx_endpoint):
    radio = ZmqRadio(tx_endpoint, rx_endpoint)
    return radio, radio


DEVICES = Registry[DeviceKind](
    "device",
    {
        "hackrf": DeviceKind(
            "hackrf",
            "HackRF One",
            "serial",
            False,
            _find_hackrfs,
            _open_hackrf,
            center_freq_range_hz=protocol.FREQ_RANGE_HZ,
            sample_rate_range_hz=protocol.SAMPLE_RATE_RANGE_HZ,
            part="MAX2837 + RFFC5072",
        ),
        "pluto": DeviceKind(
            "pluto",
            "ADALM-Pluto",
            "uri",
            True,
            _find_plutos,
            _open_pluto,
            _emulated_pluto,
            center_freq_range_hz=ad9361.LO_RANGE_HZ,
            sample_rate_range_hz=(ad9361.FIR_SAMPLE_RATE_MIN_HZ, ad9361.SAMPLE_RATE_RANGE_HZ[1]),
            part="AD9363, a stock Pluto",
            serve=_serve_iiod,
            default_port=IIOD_PORT,
        ),
        "soapy": DeviceKind(
            "soapy",
            "SoapySDR device",
            "args",
            True,
            _find_soapy,
            _open_soapy,
            _emulated_soapy,
            part="the device's own ranges (SoapySDR get*Range)",
            serve=_serve_soapy_remote,
            default_port=SOAPY_REMOTE_PORT,
            device_ranges=_soapy_ranges,
        ),
        "zmq": DeviceKind(
            "zmq",
            "GNU Radio flowgraph over ZMQ",
            "endpoint",
            True,
            list,  # nothing to find: a flowgraph is where it is told to be
            _open_zmq,
            part="the flowgraph's (ZMQ carries samples, not settings)",
            open_link=_open_zmq_link,
        ),
    },
)


def device_kind(name: str) -> DeviceKind:
    """The :class:`DeviceKind` called ``name``; ``KeyError`` lists the known ones."""
    try:
        return DEVICES[name]
    except KeyError:
        raise KeyError(f"unknown device {name!r}; known: {', '.join(DEVICES)}") from None
