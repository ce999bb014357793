"""One error hierarchy for every front-end: ``HilError`` and its subclasses.

Driver code raises these ``from`` the pyusb / sigmf error that caused them, so the
original errno stays visible in the traceback.
"""

from __future__ import annotations

import errno as _errno

import numpy as np


class HilError(RuntimeError):
    """Base class of every hardware-in-the-loop failure.

    Attributes:
        capture: the samples received before the failure, ``[1, num_samples] complex64``
            (or ``None`` when nothing was being received).
        sigmf_path: where that partial capture was saved as SigMF, or ``None``.
        partial_raw: the raw int8 interleaved I/Q a HackRF stream read before it failed
            (set only by the HackRF driver's reader, absent otherwise).
    """

    partial_raw: np.ndarray

    def __init__(self, message: str, *, capture=None, sigmf_path=None):
        super().__init__(message)
        self.capture = capture
        self.sigmf_path = sigmf_path


class DeviceNotFoundError(HilError):
    """No board matched (no HackRF on USB, nothing at a Pluto's URI, no libusb / libiio)."""


class StallError(HilError):
    """The device stalled a request (USB errno 32): the firmware refused a value."""


class TimedOutError(HilError):
    """A transfer or request timed out (errno 110): over USB or to a network board."""


class UsbTimeoutError(TimedOutError):
    """A USB transfer timed out (errno 110)."""


class DisconnectedError(HilError):
    """The device went away (unplugged, errno 19 / ENODEV)."""


class RequestFailedError(HilError):
    """A request completed but the device reported failure (e.g. a gain it refused)."""


class StreamError(HilError):
    """Overruns / underruns beyond what the caller allowed, or a broken stream."""


class SigmfError(HilError):
    """A SigMF recording is missing, truncated or corrupt."""


def usb_error_to_hil(exc: Exception, what: str) -> HilError:
    """Map a pyusb error to the matching ``HilError`` subclass (message names ``what``).

    Use as ``raise usb_error_to_hil(e, "set sample rate") from e``.
    """
    import usb.core

    err = getattr(exc, "errno", None)
    if isinstance(exc, usb.core.USBTimeoutError) or err == _errno.ETIMEDOUT:
        return UsbTimeoutError(f"{what}: USB transfer timed out ({exc})")
    if err == _errno.EPIPE:
        return StallError(
            f"{what}: the device stalled the request (errno 32, value refused by the firmware)"
        )
    if err in (_errno.ENODEV, _errno.ENOENT, _errno.ESHUTDOWN):
        return DisconnectedError(f"{what}: the device is gone (unplugged?): {exc}")
    return HilError(f"{what}: USB error: {exc}")
