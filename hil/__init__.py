"""hil: hardware in the loop. HackRF One over pure pyusb, its emulator, SigMF, loopback.

May import ``phy`` only. Public names::

    HackRF                        the driver (HackRF.open(serial=None, backend=None))
    Emulator, EmulatorBackend     emulated boards as a pyusb backend
    EmulatedHackRF, RadioSpec, Faults, Medium, AirChannel
    open_loopback, loopback_pair  the same driver without USB
    write_sigmf, read_sigmf, SigmfReplay, Annotation, Recording
    OtaConfig, send_blocks, save_sigmf, save_partial_capture   over-the-air bursts in phy's frames
    decode_capture                a recorded capture decoded again, offline
    HilError and subclasses
"""

from hil import protocol
from hil.air import AirChannel, fractional_resample, iq_imbalance, quantize_ci8
from hil.emulator import (
    EmulatedHackRF,
    Emulator,
    EmulatorBackend,
    Faults,
    RadioSpec,
    default_serial,
)
from hil.errors import (
    DeviceNotFoundError,
    DisconnectedError,
    HilError,
    RequestFailedError,
    SigmfError,
    StallError,
    StreamError,
    UsbTimeoutError,
)
from hil.hackrf import HackRF, StreamStats, find_hackrfs, to_int8_iq
from hil.loopback import DirectTransport, loopback_pair, open_loopback
from hil.medium import Medium
from hil.ota import (
    BurstResult,
    FrameReport,
    OtaConfig,
    PhyFrames,
    decode_capture,
    save_partial_capture,
    save_sigmf,
    send_blocks,
)
from hil.protocol import ControlRequest, M0State
from hil.sigmf_io import Annotation, Recording, SigmfReplay, read_sigmf, write_sigmf

__all__ = [
    "AirChannel",
    "BurstResult",
    "FrameReport",
    "OtaConfig",
    "PhyFrames",
    "save_partial_capture",
    "save_sigmf",
    "decode_capture",
    "send_blocks",
    "Annotation",
    "ControlRequest",
    "DeviceNotFoundError",
    "DirectTransport",
    "DisconnectedError",
    "EmulatedHackRF",
    "Emulator",
    "EmulatorBackend",
    "Faults",
    "HackRF",
    "HilError",
    "M0State",
    "Medium",
    "RadioSpec",
    "Recording",
    "RequestFailedError",
    "SigmfError",
    "SigmfReplay",
    "StallError",
    "StreamError",
    "StreamStats",
    "UsbTimeoutError",
    "default_serial",
    "find_hackrfs",
    "fractional_resample",
    "iq_imbalance",
    "loopback_pair",
    "open_loopback",
    "protocol",
    "quantize_ci8",
    "read_sigmf",
    "to_int8_iq",
    "write_sigmf",
]
