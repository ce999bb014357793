"""hil: hardware in the loop. The radios the over-the-air path drives and their emulators.

May import ``common`` and ``phy`` only. Subpackages (each re-exports its public names)::

    hil.hackrf      the HackRF One on pure pyusb: USB protocol, driver, settings, receive stream
    hil.pluto       the ADALM-Pluto through pyadi-iio on libiio
    hil.soapy       any SoapySDR device (USRP via SoapyUHD, LimeSDR, bladeRF, RTL-SDR, ...)
    hil.zmq         a GNU Radio flowgraph as the air (gr-zeromq's stream format), gnuradio/*.grc
    hil.emulation   emulated radios and the air between them (channels, paths, medium, iiod)
    hil.ota         over-the-air bursts and streams of phy frames, their receiver and SigMF

The names a user needs are here at the top::

    DEVICES, DeviceKind           the one table of front ends
    Radio, StreamingRadio         what the over-the-air path uses of a front end (Protocols)
    HackRF, find_hackrfs, Pluto, find_plutos, SoapyRadio, ZmqRadio
    open_loopback, loopback_pair  the HackRF driver talking straight to emulated boards
    Emulator, EmulatorProcess, EmulatedPluto, IiodServer, AirChannel, Medium
    OtaConfig, send_blocks, burst_num_samples, decode_capture, save_sigmf, save_partial_capture
    stream_over_the_air, StreamRun, build_views
    read_sigmf, write_sigmf, SigmfReplay, Recording, Annotation   SigMF recordings
    HilError and subclasses
"""

from hil.devices import DEVICES, DeviceKind
from hil.emulation import (
    AirChannel,
    EmulatedPluto,
    Emulator,
    EmulatorProcess,
    IiodServer,
    Medium,
    loopback_pair,
    open_loopback,
)
from hil.errors import (
    DeviceNotFoundError,
    DisconnectedError,
    HilError,
    RequestFailedError,
    SigmfError,
    StallError,
    StreamError,
    TimedOutError,
    UsbTimeoutError,
)
from hil.hackrf import HackRF, find_hackrfs
from hil.ota import (
    OtaConfig,
    StreamRun,
    build_views,
    burst_num_samples,
    decode_capture,
    save_partial_capture,
    save_sigmf,
    send_blocks,
    stream_over_the_air,
)
from hil.pluto import Pluto, find_plutos
from hil.radio import Radio, StreamingRadio
from hil.sigmf_io import Annotation, Recording, SigmfReplay, read_sigmf, write_sigmf
from hil.soapy import SoapyRadio
from hil.zmq import ZmqRadio

__all__ = [
    "AirChannel",
    "Annotation",
    "DEVICES",
    "DeviceKind",
    "DeviceNotFoundError",
    "DisconnectedError",
    "EmulatedPluto",
    "Emulator",
    "EmulatorProcess",
    "HackRF",
    "HilError",
    "IiodServer",
    "Medium",
    "OtaConfig",
    "Pluto",
    "Radio",
    "Recording",
    "RequestFailedError",
    "SigmfError",
    "SigmfReplay",
    "SoapyRadio",
    "StallError",
    "StreamError",
    "StreamRun",
    "StreamingRadio",
    "TimedOutError",
    "UsbTimeoutError",
    "ZmqRadio",
    "build_views",
    "burst_num_samples",
    "decode_capture",
    "find_hackrfs",
    "find_plutos",
    "loopback_pair",
    "open_loopback",
    "read_sigmf",
    "save_partial_capture",
    "save_sigmf",
    "send_blocks",
    "stream_over_the_air",
    "write_sigmf",
]
