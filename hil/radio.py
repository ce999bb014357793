"""The radio a front end is to the over-the-air path: :class:`Radio`, and :class:`StreamingRadio`
for one whose receiver also streams without pause.

:func:`hil.send_blocks`, :func:`hil.stream_over_the_air` and
:class:`osnerf.ota_link.OtaLink` use exactly these members of a transmitter and a receiver,
whatever the board: :class:`hil.HackRF` (over USB, over :class:`hil.emulation.EmulatorBackend`,
or looped back without USB), :class:`hil.Pluto` (a real board, or :class:`hil.EmulatedPluto`
behind :class:`hil.IiodServer`), :class:`hil.SoapyRadio` (any SoapySDR device, or
:class:`hil.emulation.EmulatedSoapyDevice` behind :class:`hil.emulation.SoapyRemoteServer`) and
:class:`hil.ZmqRadio` (a GNU Radio flowgraph). Every front end declares every member with its
own value (a HackRF starts transmitting at once: ``tx_start_latency_s`` 0; its air is never
its own to set: ``air_settable`` False), so the path calls them directly and never asks
whether a board has one. The settings behind ``apply_ota_config`` are each front end's own
knobs (a HackRF's gain properties, a Pluto's ``ad9361_*`` gains of :class:`hil.OtaConfig`).
"""

from __future__ import annotations

from collections.abc import Generator
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from hil.hackrf.stream import StreamStats

if TYPE_CHECKING:
    from hil.emulation.air import AirChannel
    from hil.hackrf.driver import HackRF
    from hil.ota.config import OtaConfig
    from hil.pluto.driver import Pluto
    from hil.soapy.driver import SoapyRadio
    from hil.zmq.radio import ZmqRadio


@runtime_checkable
class Radio(Protocol):
    """A front end as the over-the-air path drives it.

    Attributes:
        last_stats: what the last receive or transmit stream did (None before the first).
        tx_start_latency_s: how long after ``tx`` is called the first samples may leave (a
            Pluto's buffer set-up; 0 for a HackRF); a capture runs that much longer.
    """

    last_stats: StreamStats | None
    tx_start_latency_s: float

    @property
    def receiving(self) -> bool:
        """True while a receive stream is running (the transmitter waits for it to start)."""
        ...

    @property
    def air_settable(self) -> bool:
        """True where the host sets the air this board receives (:meth:`set_air`): an
        emulated board served over the network; False on real hardware."""
        ...

    def apply_ota_config(self, cfg: OtaConfig) -> None:
        """Set ``cfg``'s tuning and gains with the front end's own knobs."""
        ...

    def set_air(self, channel: AirChannel, *, ppm: float = 0.0, seed: int = 0) -> None:
        """The emulated air from now on (its crystal error and noise seed); raises
        ``hil.HilError`` where :attr:`air_settable` is False."""
        ...

    def rx(self, num_samples: int, *, max_shortfalls: int | None = None) -> np.ndarray:
        """``[1, num_samples]`` complex64 received, full scale 1.0; raises ``hil.StreamError``
        beyond ``max_shortfalls`` overruns, a ``hil.HilError`` carrying the capture so far."""
        ...

    def tx(self, samples: np.ndarray) -> StreamStats:
        """Transmit ``samples`` (|I|, |Q| <= 1) once and return what the stream did."""
        ...

    def close(self) -> None:
        """Stop streaming and release the board."""
        ...


@runtime_checkable
class StreamingRadio(Radio, Protocol):
    """A front end whose receiver streams without pause (:func:`hil.stream_over_the_air`):
    a HackRF, or a Pluto.

    Attributes:
        emulated_rx_loss: after a stream, an emulated Pluto's own count of what a late
            reader lost, ``(overruns, lost_blocks, lost_samples)``; None on a real board and
            on a HackRF, whose overruns are its M0's (``last_stats.device_shortfalls``).
    """

    emulated_rx_loss: tuple[int, int, int] | None

    @property
    def rx_transfer_samples(self) -> int:
        """Samples of one transfer of the receive stream at least: what the driver may still
        hold when the air has passed."""
        ...

    def stream(self, chunk_samples: int) -> Generator[np.ndarray, None, None]:
        """``[1, n]`` complex64 blocks (full scale 1.0) until the generator is closed; then
        :attr:`last_stats` hold what the stream did."""
        ...


if TYPE_CHECKING:  # the type checker proves that the front ends are radios

    def _front_ends_are_radios(
        hackrf: HackRF, pluto: Pluto, soapy: SoapyRadio, zmq: ZmqRadio
    ) -> tuple[Radio, Radio, Radio, Radio]:
        return hackrf, pluto, soapy, zmq

    def _streaming_front_ends(hackrf: HackRF, pluto: Pluto) -> tuple[StreamingRadio, ...]:
        return hackrf, pluto
