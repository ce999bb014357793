"""SoapySDR's Python binding (Debian's ``python3-soapysdr``), loaded once.

The binding links no numpy and takes buffers through ``__array_interface__``, so it loads
beside the venv's numpy 2. ``make soapysdr`` makes it importable from the venv: a ``.pth``
names a folder holding only the binding (``SoapySDR.py`` and its ``_SoapySDR`` module),
after site-packages, so nothing else of Debian's ``dist-packages`` shadows the venv.
"""

from __future__ import annotations

import functools

from hil.errors import DeviceNotFoundError

INSTALL_HINT = (
    "SoapySDR's Python binding is not importable: install Debian's python3-soapysdr and "
    "soapysdr-module-remote ('make soapysdr' as root, or 'sudo apt-get install "
    "python3-soapysdr soapysdr-module-remote'), then re-run make"
)


@functools.cache
def soapysdr():
    """The ``SoapySDR`` module, its log at warnings and above.

    Raises:
        DeviceNotFoundError: the binding is not installed.
    """
    try:
        import SoapySDR
    except ImportError as e:
        raise DeviceNotFoundError(INSTALL_HINT) from e
    SoapySDR.setLogLevel(SoapySDR.SOAPY_SDR_WARNING)
    return SoapySDR


def available() -> bool:
    """Whether the binding loads."""
    try:
        soapysdr()
    except DeviceNotFoundError:
        return False
    return True


def args_string(kwargs) -> str:
    """A Soapy device's kwargs as a device string, ``key=value,...`` (sorted)."""
    return ",".join(f"{k}={kwargs[k]}" for k in sorted(dict(kwargs)))
