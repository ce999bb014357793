"""Emulated radios and the air between them: channels, time-varying paths, the medium, emulated
HackRFs (a pyusb backend, in-process or in a process of their own) and an emulated Pluto served
over iiod."""

from hil.emulation.air import (
    AIR_SNR_DB_RANGE,
    MAX_DELAY_S,
    MAX_MULTIPATH_DELAY,
    AirChannel,
    fractional_resample,
    iq_imbalance,
)
from hil.emulation.hackrf import FAULT_NAMES, PPM_RANGE, EmulatedHackRF, Faults, RadioSpec
from hil.emulation.iiod import IIOD_PORT, IiodServer
from hil.emulation.loopback import DirectTransport, loopback_pair, open_loopback
from hil.emulation.medium import Medium
from hil.emulation.paths import (
    MAX_DOPPLER_HZ,
    MAX_PATH_DELAY_S,
    AirPath,
    PathSegment,
    segments_from_arrays,
)
from hil.emulation.pluto import NETWORK_FAULTS, EmulatedPluto
from hil.emulation.process import EmulatorProcess
from hil.emulation.soapy_device import SOAPY_FAULTS, EmulatedSoapyDevice
from hil.emulation.soapy_remote import SoapyRemoteServer
from hil.emulation.usb_backend import Emulator, EmulatorBackend, default_serial

__all__ = [
    "AIR_SNR_DB_RANGE",
    "AirChannel",
    "AirPath",
    "DirectTransport",
    "EmulatedHackRF",
    "EmulatedPluto",
    "EmulatedSoapyDevice",
    "Emulator",
    "EmulatorBackend",
    "EmulatorProcess",
    "FAULT_NAMES",
    "Faults",
    "IIOD_PORT",
    "IiodServer",
    "MAX_DELAY_S",
    "MAX_DOPPLER_HZ",
    "MAX_MULTIPATH_DELAY",
    "MAX_PATH_DELAY_S",
    "Medium",
    "NETWORK_FAULTS",
    "PPM_RANGE",
    "PathSegment",
    "RadioSpec",
    "SOAPY_FAULTS",
    "SoapyRemoteServer",
    "default_serial",
    "fractional_resample",
    "iq_imbalance",
    "loopback_pair",
    "open_loopback",
    "segments_from_arrays",
]
