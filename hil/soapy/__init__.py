"""Every SDR with a SoapySDR module (USRP via SoapyUHD, HackRF, LimeSDR, bladeRF, RTL-SDR,
a SoapyRemote server): :class:`SoapyRadio` on Debian's python3-soapysdr."""

from hil.soapy.driver import SoapyCounts, SoapyRadio, find_soapy_devices

__all__ = [
    "SoapyCounts",
    "SoapyRadio",
    "find_soapy_devices",
]
