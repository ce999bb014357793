"""hil: hardware in the loop. HackRF One over pure pyusb, ADALM-Pluto through pyadi-iio,
their emulators, SigMF, loopback.

May import ``phy`` only. Public names::

    DEVICES, DeviceKind           the one table of front ends ("hackrf", "pluto")
    HackRF                        the driver (HackRF.open(serial=None, backend=None))
    Pluto, find_plutos            the Pluto front end (Pluto.open(uri=None)) on pyadi-iio
    SoapyRadio, SoapyCounts       any SoapySDR device (SoapyRadio.open("driver=uhd")) and what
                                  its streams reported; find_soapy_devices
    EmulatedSoapyDevice, SoapyRemoteServer   an emulated device served over SoapyRemote
    ZmqRadio                      a GNU Radio flowgraph as the air (gr-zeromq's stream format)
    Flowgraph, FLOWGRAPHS, ota_noise_voltage   gnuradio/*.grc run in their own process
    EmulatedPluto, IiodServer     an emulated Pluto served over iiod's network protocol
    Emulator, EmulatorBackend     emulated boards as a pyusb backend
    EmulatorProcess               the same boards served from a process of their own
    EmulatedHackRF, RadioSpec, Faults, Medium, AirChannel
    AirPath, PathSegment          the air's time-varying multipath: paths (delay, gain, Doppler)
    segments_from_arrays          such paths from arrays (e.g. phy.raytrace.MovingCIR's)
    open_loopback, loopback_pair  the same driver without USB
    Radio                         what the over-the-air path uses of a front end (a Protocol)
    write_sigmf, read_sigmf, SigmfReplay, Annotation, Recording
    OtaConfig, send_blocks, save_sigmf, save_partial_capture   over-the-air bursts in phy's frames
    burst_num_samples             how long such a burst is
    decode_capture                a recorded capture decoded again, offline
    stream_over_the_air, build_views, RingBuffer, StreamReceiver, StreamRun
                                  views streamed one after another, decoded as they arrive
    HilError and subclasses
"""

from hil.devices import DEVICES, DeviceKind, device_kind
from hil.emulation.air import (
    AIR_SNR_DB_RANGE,
    MAX_DELAY_S,
    MAX_MULTIPATH_DELAY,
    AirChannel,
    fractional_resample,
    iq_imbalance,
    quantize_ci8,
)
from hil.emulation.hackrf import FAULT_NAMES, PPM_RANGE, EmulatedHackRF, Faults, RadioSpec
from hil.emulation.iiod import IIOD_PORT, IiodServer
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
from hil.hackrf import protocol
from hil.hackrf.driver import HackRF
from hil.hackrf.iq import to_int8_iq
from hil.hackrf.loopback import DirectTransport, loopback_pair, open_loopback
from hil.hackrf.protocol import (
    BOARD_IDS,
    FREQ_RANGE_HZ,
    SAMPLE_RATE_RANGE_HZ,
    ControlRequest,
    M0State,
    usb_api_version_string,
)
from hil.hackrf.stream import StreamStats
from hil.hackrf.usb_transport import find_hackrfs
from hil.ota.burst import BurstResult, FrameReport, PhyFrames
from hil.ota.capture import save_partial_capture, save_sigmf
from hil.ota.config import OtaConfig
from hil.ota.link import burst_num_samples, decode_capture, send_blocks
from hil.ota.sigmf_io import Annotation, Recording, SigmfReplay, read_sigmf, write_sigmf
from hil.ota.stream import RingBuffer, StreamCounts, StreamReceiver, StreamView, build_views
from hil.ota.stream_link import StreamRun, stream_over_the_air
from hil.pluto.driver import Pluto
from hil.pluto.iio_access import find_plutos
from hil.radio import Radio
from hil.soapy.driver import SoapyCounts, SoapyRadio, find_soapy_devices
from hil.zmq.flowgraph import FLOWGRAPHS, Flowgraph, compile_flowgraph, ota_noise_voltage
from hil.zmq.radio import ZmqRadio

__all__ = [
    "AIR_SNR_DB_RANGE",
    "BOARD_IDS",
    "FAULT_NAMES",
    "FREQ_RANGE_HZ",
    "MAX_DELAY_S",
    "MAX_DOPPLER_HZ",
    "MAX_PATH_DELAY_S",
    "MAX_MULTIPATH_DELAY",
    "NETWORK_FAULTS",
    "PPM_RANGE",
    "SAMPLE_RATE_RANGE_HZ",
    "usb_api_version_string",
    "DEVICES",
    "DeviceKind",
    "device_kind",
    "EmulatedPluto",
    "IIOD_PORT",
    "IiodServer",
    "Pluto",
    "Radio",
    "SOAPY_FAULTS",
    "EmulatedSoapyDevice",
    "SoapyCounts",
    "SoapyRadio",
    "SoapyRemoteServer",
    "find_soapy_devices",
    "FLOWGRAPHS",
    "Flowgraph",
    "ZmqRadio",
    "compile_flowgraph",
    "ota_noise_voltage",
    "find_plutos",
    "TimedOutError",
    "AirChannel",
    "AirPath",
    "PathSegment",
    "BurstResult",
    "FrameReport",
    "OtaConfig",
    "PhyFrames",
    "save_partial_capture",
    "save_sigmf",
    "burst_num_samples",
    "decode_capture",
    "RingBuffer",
    "StreamCounts",
    "StreamReceiver",
    "StreamRun",
    "StreamView",
    "build_views",
    "stream_over_the_air",
    "send_blocks",
    "Annotation",
    "ControlRequest",
    "DeviceNotFoundError",
    "DirectTransport",
    "DisconnectedError",
    "EmulatedHackRF",
    "Emulator",
    "EmulatorBackend",
    "EmulatorProcess",
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
    "segments_from_arrays",
    "to_int8_iq",
    "write_sigmf",
]
