"""Emulated HackRF Ones as a pyusb backend (``usb.backend.IBackend``).

The backend enumerates boards like real ones (descriptors, strings, serial through
GET_DESCRIPTOR) and hands their requests and transfers to :class:`hil.emulation.EmulatedHackRF`
(the radio state and its faults, :mod:`hil.emulation.hackrf`); :class:`Emulator` builds the
boards on one :class:`hil.Medium`. The same :class:`hil.HackRF` code runs on it and on
real hardware::

    emu = Emulator(channel=AirChannel(snr_db=15), ppm=(0.0, 20.0), seed=0)
    with HackRF.open(emu.serials[1], backend=emu.backend) as rx: ...
"""

from __future__ import annotations

import errno
from collections.abc import Sequence
from typing import Protocol

import usb.backend
import usb.core

from hil.emulation.air import AirChannel, prepare_resampler
from hil.emulation.hackrf import EmulatedHackRF, RadioSpec, gone_error, stall_error
from hil.emulation.medium import Medium
from hil.hackrf import protocol as p

_STRINGS = {1: "Great Scott Gadgets", 2: "HackRF One", 3: "Transceiver"}


class _Desc:
    def __init__(self, **fields):
        self.__dict__.update(fields)


class UsbBoard(Protocol):
    """A board as :class:`EmulatorBackend` serves it: an :class:`EmulatedHackRF`, or the
    stand-in for one that runs in a process of its own (:class:`hil.EmulatorProcess`)."""

    spec: RadioSpec
    index: int
    unplugged: bool
    configuration: int
    claimed: bool

    @property
    def serial(self) -> str: ...

    def control(self, request_type: int, request: int, value: int, index: int, data_or_length):
        """A control request: the bytes read, or the count written."""
        ...

    def bulk_read(self, num_bytes: int) -> bytes: ...

    def bulk_write(self, data: bytes) -> int: ...


class EmulatorBackend(usb.backend.IBackend):
    """pyusb backend serving emulated HackRFs (pass as ``backend=`` to ``usb.core.find``)."""

    def __init__(self, radios: Sequence[UsbBoard]):
        super().__init__()
        self.radios = list(radios)

    def enumerate_devices(self):
        return iter([r for r in self.radios if not r.unplugged])

    def get_parent(self, dev):
        return None

    def get_device_descriptor(self, dev):
        s = dev.spec
        return _Desc(
            bLength=18,
            bDescriptorType=1,
            bcdUSB=0x0200,
            bDeviceClass=0,
            bDeviceSubClass=0,
            bDeviceProtocol=0,
            bMaxPacketSize0=64,
            idVendor=p.VENDOR_ID,
            idProduct=s.product_id,
            bcdDevice=s.usb_api_version,
            iManufacturer=1,
            iProduct=2,
            iSerialNumber=4,
            bNumConfigurations=1,
            address=dev.index + 2,
            bus=1,
            port_number=dev.index + 1,
            port_numbers=(dev.index + 1,),
            speed=3,
        )

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError("configuration index out of range")
        return _Desc(
            bLength=9,
            bDescriptorType=2,
            wTotalLength=32,
            bNumInterfaces=1,
            bConfigurationValue=p.CONFIGURATION_VALUE,
            iConfiguration=3,
            bmAttributes=0x80,
            bMaxPower=250,
            extra_descriptors=[],
        )

    def get_interface_descriptor(self, dev, intf, alt, config):
        if config != 0 or intf != 0 or alt != 0:
            raise IndexError("interface / alternate setting out of range")
        return _Desc(
            bLength=9,
            bDescriptorType=4,
            bInterfaceNumber=0,
            bAlternateSetting=0,
            bNumEndpoints=2,
            bInterfaceClass=0xFF,
            bInterfaceSubClass=0xFF,
            bInterfaceProtocol=0xFF,
            iInterface=0,
            extra_descriptors=[],
        )

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        if config != 0 or intf != 0 or alt != 0 or ep not in (0, 1):
            raise IndexError("endpoint out of range")
        return _Desc(
            bLength=7,
            bDescriptorType=5,
            bEndpointAddress=(p.ENDPOINT_RX, p.ENDPOINT_TX)[ep],
            bmAttributes=2,
            wMaxPacketSize=p.PACKET_BYTES,
            bInterval=0,
            bRefresh=0,
            bSynchAddress=0,
            extra_descriptors=[],
        )

    def open_device(self, dev):
        if dev.unplugged:
            raise gone_error()
        return dev

    def close_device(self, dev_handle):
        pass

    def set_configuration(self, dev_handle, config_value):
        if dev_handle.unplugged:
            raise gone_error()
        if config_value != p.CONFIGURATION_VALUE:
            raise stall_error(f"configuration {config_value}")
        dev_handle.configuration = config_value

    def get_configuration(self, dev_handle):
        if dev_handle.unplugged:
            raise gone_error()
        return dev_handle.configuration

    def set_interface_altsetting(self, dev_handle, intf, altsetting):
        if intf != 0 or altsetting != 0:
            raise stall_error("alternate setting")

    def claim_interface(self, dev_handle, intf):
        if dev_handle.unplugged:
            raise gone_error()
        if intf != 0:
            raise usb.core.USBError("Entity not found", -5, errno.ENOENT)
        if dev_handle.claimed:
            raise usb.core.USBError("Resource busy", -6, errno.EBUSY)
        dev_handle.claimed = True

    def release_interface(self, dev_handle, intf):
        dev_handle.claimed = False

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        if dev_handle.unplugged:
            raise gone_error()
        if bmRequestType == 0x80 and bRequest == 6:  # standard GET_DESCRIPTOR
            reply = self._get_descriptor(dev_handle, wValue)
        elif bmRequestType & 0x80:
            reply = dev_handle.control(bmRequestType, bRequest, wValue, wIndex, len(data))
        else:
            return dev_handle.control(bmRequestType, bRequest, wValue, wIndex, bytes(data))
        n = min(len(reply), len(data))
        data[:n] = type(data)(data.typecode, reply[:n])
        return n

    def _get_descriptor(self, dev, w_value: int) -> bytes:
        kind, idx = w_value >> 8, w_value & 0xFF
        if kind != 3:
            raise stall_error(f"descriptor type {kind}")
        if idx == 0:
            return bytes([4, 3, 0x09, 0x04])  # LANGID en-US
        text = dev.spec.serial if idx == 4 else _STRINGS.get(idx)
        if text is None:
            raise stall_error(f"string {idx}")
        body = text.encode("utf-16-le")
        return bytes([2 + len(body), 3]) + body

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        if ep != p.ENDPOINT_TX:
            raise stall_error(f"endpoint {ep:#x}")
        return dev_handle.bulk_write(bytes(data))

    def bulk_read(self, dev_handle, ep, intf, buff, timeout):
        if ep != p.ENDPOINT_RX:
            raise stall_error(f"endpoint {ep:#x}")
        out = dev_handle.bulk_read(len(buff) * buff.itemsize)
        memoryview(buff).cast("B")[: len(out)] = out
        return len(out)

    def clear_halt(self, dev_handle, ep):
        pass

    def reset_device(self, dev_handle):
        pass

    def is_kernel_driver_active(self, dev_handle, intf):
        return False

    def detach_kernel_driver(self, dev_handle, intf):
        pass

    def attach_kernel_driver(self, dev_handle, intf):
        pass


def default_serial(index: int) -> str:
    """Deterministic serials for emulated boards: 32 hex digits, differing in the tail."""
    return f"0000000000000000{0x57B068DC:08x}{0x1F2E3D40 + index:08x}"


class Emulator:
    """Emulated HackRFs sharing one medium, with the pyusb backend that serves them.

    Args:
        channel: the air between transmitter and receivers.
        ppm: one crystal error per board (its length is the number of boards).
        seed: noise seed.
        wait_for_bursts: see :class:`hil.Medium` (1 for one deterministic TX burst).
        usb_api_version: bcdDevice of every board.
        paced: every board streams at its sample rate against the wall clock, with the
            board's overrun and underrun model (:mod:`hil.emulation.pacing`); otherwise
            streams run as fast as the host reads and writes.
    """

    def __init__(
        self,
        channel: AirChannel | None = None,
        ppm=(0.0, 20.0),
        seed: int = 0,
        wait_for_bursts: int = 0,
        usb_api_version: int = 0x0108,
        paced: bool = False,
    ):
        self.medium = Medium(channel, seed=seed, wait_for_bursts=wait_for_bursts)
        self.radios = [
            EmulatedHackRF(
                RadioSpec(default_serial(i), ppm=float(x), usb_api_version=usb_api_version),
                self.medium,
                i,
            )
            for i, x in enumerate(ppm)
        ]
        for radio in self.radios:
            radio.paced = bool(paced)
        if paced:  # no first receive late for the compiler
            prepare_resampler()
        self.backend = EmulatorBackend(self.radios)

    @property
    def serials(self) -> list[str]:
        return [r.serial for r in self.radios]
