"""Over the air: bursts and streams of phy frames through any radio, their header, receiver and
SigMF captures."""

from hil.ota.burst import BurstResult, FrameReport, PhyFrames
from hil.ota.capture import save_partial_capture, save_sigmf
from hil.ota.config import OtaConfig
from hil.ota.link import burst_num_samples, decode_capture, send_blocks
from hil.ota.stream import RingBuffer, StreamCounts, StreamReceiver, StreamView, build_views
from hil.ota.stream_link import StreamRun, stream_over_the_air

__all__ = [
    "BurstResult",
    "FrameReport",
    "OtaConfig",
    "PhyFrames",
    "RingBuffer",
    "StreamCounts",
    "StreamReceiver",
    "StreamRun",
    "StreamView",
    "build_views",
    "burst_num_samples",
    "decode_capture",
    "save_partial_capture",
    "save_sigmf",
    "send_blocks",
    "stream_over_the_air",
]
