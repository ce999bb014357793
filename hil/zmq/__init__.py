"""The GNU Radio bridge: :class:`ZmqRadio` (gr-zeromq's stream format) and the flowgraphs of
``gnuradio/``, compiled by ``grcc`` and run on Debian's python3 in their own process."""

from hil.zmq.flowgraph import FLOWGRAPHS, Flowgraph, compile_flowgraph, ota_noise_voltage
from hil.zmq.radio import ZmqRadio

__all__ = [
    "FLOWGRAPHS",
    "Flowgraph",
    "ZmqRadio",
    "compile_flowgraph",
    "ota_noise_voltage",
]
