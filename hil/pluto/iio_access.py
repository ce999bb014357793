"""libiio access for the Pluto: loading the binding, finding boards, and mapping its
errors onto :class:`hil.HilError`."""

from __future__ import annotations

import ctypes
import errno
import os

from hil.errors import (
    DeviceNotFoundError,
    DisconnectedError,
    HilError,
    RequestFailedError,
    TimedOutError,
)
from hil.pluto.context import AIR_ATTR, DEVICE_NAMES, OVERRUN_ATTR, PHY, RX_DEV

_GONE = {
    errno.EPIPE,
    errno.ECONNRESET,
    errno.ENOTCONN,
    errno.ECONNABORTED,
    errno.ENODEV,
    errno.EBADF,
    errno.ESHUTDOWN,
}


def iio_error_to_hil(exc: BaseException, what: str) -> HilError:
    """Map a libiio ``OSError`` (or pyadi-iio's plain ``Exception``) to a ``HilError``."""
    err = getattr(exc, "errno", None)
    text = os.strerror(err) if err else str(exc)
    if err == errno.ETIMEDOUT:
        return TimedOutError(f"{what}: the board did not answer in time ({text})")
    if err in _GONE or err == errno.ECONNREFUSED:
        return DisconnectedError(f"{what}: the board is gone (connection dropped: {text})")
    if err == errno.EINVAL:
        return RequestFailedError(f"{what}: the driver refused the value ({text})")
    return HilError(f"{what}: libiio error: {text}")


def receive_error(exc: BaseException, waited_s: float, timeout_ms: int) -> HilError:
    """The ``HilError`` of a failed receive that waited ``waited_s`` for its buffer: libiio
    0.24's network backend reports its own timeout as EPIPE, so a wait as long as the
    timeout is a timeout."""
    if isinstance(exc, HilError):
        return exc
    if waited_s >= 0.95 * timeout_ms / 1000:
        return TimedOutError(
            f"receive: the board did not answer in time (no buffer within {timeout_ms} ms; "
            f"libiio: {exc})"
        )
    return iio_error_to_hil(exc, "receive")


def air_attribute(sdr):
    """The debug attribute through which an emulated board's air is set
    (``hil.pluto.context.AIR_ATTR`` of its ``ad9361-phy``), or None on a real board."""
    try:
        return sdr.ctx.find_device(DEVICE_NAMES[PHY]).debug_attrs.get(AIR_ATTR)
    except Exception:  # noqa: BLE001 - no such device or attribute: not our emulator
        return None


def rx_overrun_counts(sdr) -> tuple[int, int, int] | None:
    """``(overruns, lost_blocks, lost_samples)`` of an emulated board's last receive buffer
    (``hil.pluto.context.OVERRUN_ATTR`` of its ``cf-ad9361-lpc``), or None on a real board
    (libiio 0.x reports no overruns)."""
    try:
        attr = sdr.ctx.find_device(DEVICE_NAMES[RX_DEV]).debug_attrs.get(OVERRUN_ATTR)
        if attr is None:
            return None
        overruns, blocks, samples = (int(x) for x in attr.value.split())
    except Exception:  # noqa: BLE001 - no such device or attribute: not our emulator
        return None
    return overruns, blocks, samples


def find_plutos() -> list[tuple[str, str]]:
    """``(uri, description)`` of every Pluto libiio finds: its USB (and DNS-SD) scan, and
    ``ip:$IIOD_REMOTE`` when that variable (libiio's default network host) is set.

    Raises:
        DeviceNotFoundError: libiio or its Python binding cannot be loaded.
    """
    iio = import_iio()
    found = []
    remote = os.environ.get("IIOD_REMOTE")
    if remote:
        found.append((f"ip:{remote}", "IIOD_REMOTE"))
    try:
        scanned = iio.scan_contexts()
    except OSError:
        scanned = {}
    for uri, desc in scanned.items():
        if "pluto" in desc.lower() or "ad9361" in desc.lower() or "ad9363" in desc.lower():
            found.append((uri, desc))
    return found


def import_iio():
    """The ``iio`` module (pylibiio); DeviceNotFoundError when it cannot be loaded."""
    try:
        import iio
    except (ImportError, OSError) as e:
        raise DeviceNotFoundError(
            "libiio is not available: install libiio0 (Debian) and pip install pylibiio==0.25"
        ) from e
    _order_teardown(iio)
    return iio


def _address(pointer) -> int:
    return ctypes.cast(pointer, ctypes.c_void_p).value or 0


def _order_teardown(iio) -> None:
    """Make pylibiio destroy every buffer before its context, whatever order the garbage
    collector finalises them in.

    An ``iio.Buffer`` holds its context, so reference counting frees it first; but when both
    are in a reference cycle (pyadi-iio's devices, an exception's frames), the collector calls
    their ``__del__`` in any order, and a buffer destroyed after its context is a use after
    free in libiio. Each context here remembers its live buffers (as addresses, holding no
    Python object) and destroys them before itself; a buffer already destroyed that way skips
    its own destroy."""
    if getattr(iio, "_osnerf_ordered_teardown", False):
        return
    live: dict[int, set[int]] = {}
    buffer_init, buffer_del, context_del = (
        iio.Buffer.__init__,
        iio.Buffer.__del__,
        iio.Context.__del__,
    )

    def init(self, device, *args, **kwargs):
        self._owner = 0
        buffer_init(self, device, *args, **kwargs)
        self._owner = _address(device._ctx._context)
        live.setdefault(self._owner, set()).add(_address(self._buffer))

    def destroy_buffer(self):
        pointer = self.__dict__.get("_buffer")
        owned = live.get(self.__dict__.get("_owner", 0), set())
        if pointer is not None and _address(pointer) not in owned:
            self._buffer = None  # its context destroyed it already
            return
        owned.discard(_address(pointer) if pointer is not None else 0)
        buffer_del(self)

    def destroy_context(self):
        pointer = self.__dict__.get("_context")
        if pointer is not None:
            for address in live.pop(_address(pointer), set()):
                iio._buffer_destroy(ctypes.cast(address, iio._BufferPtr))
        context_del(self)

    iio.Buffer.__init__, iio.Buffer.__del__ = init, destroy_buffer
    iio.Context.__del__ = destroy_context
    iio._osnerf_ordered_teardown = True


def destroy_buffers(*destroys) -> None:
    """Call pyadi-iio's ``tx_destroy_buffer`` / ``rx_destroy_buffer`` methods given, each
    whatever the others do: stopping is best effort, the connection may be gone already."""
    for destroy in destroys:
        try:
            destroy()
        except Exception:  # noqa: BLE001 - libiio raises OSError, pyadi Exception
            pass


def release_frames(exc: BaseException) -> None:
    """Drop the locals of the frames in ``exc``'s traceback: pyadi-iio's frames hold its
    ``iio.Buffer``, which must be destroyed before its context (libiio frees the buffer
    through the context; garbage collection in the wrong order crashes the process)."""
    import traceback

    traceback.clear_frames(exc.__traceback__)
