"""USB access to HackRF boards on pure pyusb: the bulk/control transport and discovery."""

from __future__ import annotations

import array

import numpy as np

from hil.errors import DeviceNotFoundError
from hil.hackrf import protocol as p


class UsbTransport:
    """Control and bulk transfers on one pyusb device (claimed interface 0)."""

    def __init__(self, device):
        self.device = device

    def control(self, req: p.ControlRequest, timeout_ms: int = p.CONTROL_TIMEOUT_MS):
        if req.is_in:
            return bytes(
                self.device.ctrl_transfer(
                    req.request_type, req.request, req.value, req.index, req.length, timeout_ms
                )
            )
        return self.device.ctrl_transfer(
            req.request_type,
            req.request,
            req.value,
            req.index,
            req.data if req.data else None,
            timeout_ms,
        )

    def read(self, num_bytes: int, timeout_ms: int) -> np.ndarray:
        buf = array.array("b", bytes(num_bytes))
        n = self.device.read(p.ENDPOINT_RX, buf, timeout_ms)
        return np.frombuffer(buf, dtype=np.int8, count=n)

    def write(self, data: bytes, timeout_ms: int) -> int:
        return self.device.write(p.ENDPOINT_TX, data, timeout_ms)

    def close(self) -> None:
        import usb.util

        try:
            usb.util.release_interface(self.device, p.INTERFACE)
        finally:
            usb.util.dispose_resources(self.device)


def find_hackrfs(backend=None) -> list:
    """Every HackRF-family board (pyusb ``Device`` objects) on ``backend`` (None: libusb).

    Raises:
        DeviceNotFoundError: no libusb backend could be loaded.
    """
    import usb.core

    try:
        found = usb.core.find(find_all=True, idVendor=p.VENDOR_ID, backend=backend)
        return [d for d in found if d.idProduct in p.PRODUCT_IDS]
    except usb.core.NoBackendError as e:
        raise DeviceNotFoundError(
            "no libusb backend: install libusb-1.0 (Debian libusb-1.0-0, or pip install "
            "libusb-package)"
        ) from e
