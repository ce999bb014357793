"""The radio a front end is to the over-the-air path: :class:`Radio`.

:func:`hil.send_blocks` and :class:`osnerf.ota_link.OtaLink` use exactly these members of a
transmitter and a receiver, whatever the board: :class:`hil.HackRF` (over USB, over
:class:`hil.emulation.EmulatorBackend`, or looped back without USB), :class:`hil.Pluto` (a real
board, or :class:`hil.EmulatedPluto` behind :class:`hil.IiodServer`) and
:class:`hil.SoapyRadio` (any SoapySDR device, or :class:`hil.emulation.EmulatedSoapyDevice` behind
:class:`hil.emulation.SoapyRemoteServer`). Settings are not part
of it: each front end has its own knobs (a Pluto's ``apply_ota_config``, a HackRF's gain
properties), which :mod:`hil.ota.link` sets from :class:`hil.OtaConfig`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from hil.hackrf.stream import StreamStats

if TYPE_CHECKING:
    from hil.hackrf.driver import HackRF
    from hil.pluto.driver import Pluto
    from hil.soapy.driver import SoapyRadio


@runtime_checkable
class Radio(Protocol):
    """A front end as the over-the-air path drives it."""

    @property
    def receiving(self) -> bool:
        """True while a receive stream is running (the transmitter waits for it to start)."""
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


if TYPE_CHECKING:  # the type checker proves that the front ends are radios

    def _front_ends_are_radios(
        hackrf: HackRF, pluto: Pluto, soapy: SoapyRadio
    ) -> tuple[Radio, Radio, Radio]:
        return hackrf, pluto, soapy
