"""An over-the-air link: symbols through two radios (emulated or real HackRFs, a Pluto).

:class:`OtaLink` has the interface of ``phy``'s links (``link(x, snr_db, generator) ->
phy.LinkOutput``), so every scheme of ``osnerf run`` can cross the air: each call sends
the batch's blocks as one burst of ``phy`` OFDM frames through ``hil.send_blocks`` and
returns zero-forced (unbiased) symbols with the receiver's own per-symbol effective noise
variance, the codec's convention (lost frames come back erased: zero symbols with noise
variance ``hil.ota.receiver.ERASED_NOISE_VAR``). A decoder should get that variance
(``codec.decode(x_hat, meta, snr_db, noise_var=out.noise_var)``) and, as its SNR, the
receiver's measured one (``snr_db_measured``) rather than ``1 / mean(noise_var)``, which
one erased frame dominates.

:meth:`OtaLink.send_blocks` is the same burst for blocks of any length (one per image,
what ``semcodec``'s framed schemes send): it returns ``hil``'s :class:`hil.ota.BurstResult`
(one report per frame, the burst and the capture), and :func:`received_blocks` turns that
into ``semcodec.links.ReceivedBlock`` s for a framed scheme's receiver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import torch

from hil import DEVICES as _HARDWARE
from hil import AirChannel, Emulator, HackRF, HilError, open_loopback, send_blocks
from phy import LinkOutput
from semcodec.links import ReceivedBlock

if TYPE_CHECKING:
    from hil import OtaConfig, Radio

DEVICES = ("emulated", *_HARDWARE)  # emulated HackRFs, then hil's table of real front ends
DEFAULT_PPM = (0.0, 20.0)
ONE_BOARD_PPM = (0.0, 0.0)  # a full-duplex board: TX and RX on one crystal
DEFAULT_MULTIPATH = ((2, 0.4 + 0j), (5, 0.2j))
DEFAULT_DELAY_S = 5e-6
OTA_AIRS = ("fixed", "raytraced")
"""The emulated air of ``osnerf run --channel ota``: "fixed" (:data:`DEFAULT_MULTIPATH` at
``snr_db``) or "raytraced" (each view's drone's ray-traced paths: ``osnerf.run.ota_air``)."""


def air_channel(device: str, snr_db: float, ota_cfg, delay_s: float, multipath, path_segments=()):
    """The one air model of every emulated path: a ``hil.AirChannel`` at ``snr_db`` for the
    frames' mean power (``ota_cfg.tx_power_dbfs``) sent and received at ``ota_cfg``'s gains
    of ``device`` ("emulated" HackRFs, an emulated "pluto" or "soapy" device), with the fixed
    ``multipath`` taps or, given ``path_segments`` (``hil.emulation.PathSegment`` s), those
    paths' gains as they are."""
    if device in ("pluto", "soapy"):  # an emulated SoapySDR device is an AD9363 too
        txvga, rx_gain = ota_cfg.ad9361_tx_gain_db, ota_cfg.ad9361_rx_gain_db
    else:
        txvga, rx_gain = ota_cfg.txvga_gain_db, ota_cfg.lna_gain_db + ota_cfg.vga_gain_db
    return AirChannel(
        snr_db=float(snr_db),
        reference_power_dbfs=ota_cfg.tx_power_dbfs,
        reference_txvga_db=txvga,
        reference_rx_gain_db=rx_gain,
        delay_s=delay_s,
        multipath=() if path_segments else tuple(multipath),
        path_segments=tuple(path_segments),
        normalize_taps=not path_segments,
    )


def open_radios(
    device: str,
    snr_db: float | None,
    ota_cfg,
    seed: int = 0,
    ppm: tuple[float, float] | None = None,
    multipath=DEFAULT_MULTIPATH,
    delay_s: float = DEFAULT_DELAY_S,
    loopback: bool = False,
    tx_serial: str | None = None,
    rx_serial: str | None = None,
) -> tuple[Radio, Radio, Emulator | None]:
    """(tx, rx, emulator or None): two emulated boards ``ppm`` apart with the air at
    ``snr_db`` (``loopback``: the same without USB), or boards of a kind of ``hil.DEVICES``
    (a full-duplex Pluto is both ends; its id is a libiio URI). An emulated Pluto
    (``tx.air_settable``) gets the same air: ``snr_db``, ``multipath``, ``delay_s``, ``seed``
    and ``ppm`` (one crystal: TX and RX equal); a real board's air is left alone.

    Args:
        device: "emulated" or a key of ``hil.DEVICES``.
        snr_db: the emulated air's SNR, dB; None leaves an emulated Pluto's air as it is.
        ppm: crystal errors (TX, RX); None: :data:`DEFAULT_PPM` for emulated HackRFs,
            :data:`ONE_BOARD_PPM` for one full-duplex board.
        tx_serial, rx_serial: which boards (HackRF serial, Pluto URI); None: the first found.
        ota_cfg: ``hil.OtaConfig`` (its powers and gains calibrate the emulated SNR).
    Raises:
        ValueError: ``ppm`` with TX and RX apart for one full-duplex board.
    """
    if device not in DEVICES:
        raise ValueError(f"ota device must be one of {', '.join(DEVICES)}, got {device!r}")
    if device == "emulated":
        channel = air_channel(device, snr_db, ota_cfg, delay_s, multipath)
        ppm = DEFAULT_PPM if ppm is None else ppm
        emu = Emulator(channel, ppm=tuple(ppm), seed=seed, wait_for_bursts=1)
        if loopback:
            return open_loopback(emu.radios[0]), open_loopback(emu.radios[1]), emu
        return (
            HackRF.open(emu.serials[0], backend=emu.backend),
            HackRF.open(emu.serials[1], backend=emu.backend),
            emu,
        )
    one_board = _HARDWARE[device].full_duplex and rx_serial in (None, tx_serial)
    ppm = (ONE_BOARD_PPM if one_board else DEFAULT_PPM) if ppm is None else tuple(ppm)
    if one_board and ppm[0] != ppm[1]:
        raise ValueError(
            f"ppm: one {_HARDWARE[device].label} is both ends of the link on one crystal, so "
            f"TX and RX are equal, got {ppm[0]:g},{ppm[1]:g}"
        )
    tx, rx = _HARDWARE[device].open_pair(tx_serial, rx_serial)
    if snr_db is not None and tx.air_settable and rx is tx:
        try:
            tx.set_air(
                air_channel(device, snr_db, ota_cfg, delay_s, multipath), ppm=ppm[0], seed=seed
            )
        except BaseException:
            tx.close()
            raise
    return tx, rx, None


@dataclass
class OtaLink:
    """``link(x [batch, num_symbols] complex64, snr_db) -> phy.LinkOutput`` over the air.

    Attributes:
        tx, rx: open front ends, ``hil.Radio`` s (see :func:`open_radios`).
        snr_db: the air's SNR (emulated boards: fixed when they were opened); None for a
            real air, which only the receiver's measurement knows.
        ota_cfg: ``hil.OtaConfig``.
        emulator: the emulated HackRFs' ``hil.Emulator``, else None.
        air_ppm: the crystal error an emulated Pluto's air is set with (:meth:`set_air`).
        frames_sent, frames_lost: counted over every call.
        snr_db_measured: the receiver's pilot SNR of each call (None when all were lost).
    """

    tx: Radio
    rx: Radio
    snr_db: float | None
    ota_cfg: OtaConfig
    emulator: object | None = None
    air_ppm: float = ONE_BOARD_PPM[0]
    frames_sent: int = 0
    frames_lost: int = 0
    snr_db_measured: list = field(default_factory=list)

    def send_blocks(self, blocks: list):
        """Blocks of any length as one burst; updates the frame counters and the measured SNR.

        Args:
            blocks: one [num_symbols] complex64 array per image, unit mean power each.
        Returns:
            ``hil.ota.BurstResult``: per block ``(x_hat, noise_var)`` and one
            ``hil.ota.FrameReport`` per frame (``hil.HilError`` and subclasses propagate, with what
            was captured).
        """
        if self.emulator is not None:  # deterministic: receivers wait for this next burst
            medium = self.emulator.medium
            medium.wait_for_bursts = medium.bursts_completed + 1
        result = send_blocks(self.tx, self.rx, blocks, self.ota_cfg)
        self.frames_sent += result.frames_sent
        self.frames_lost += result.frames_lost
        self.snr_db_measured.append(result.snr_db_measured())
        return result

    @property
    def air_settable(self) -> bool:
        """Whether the air is ours to set: emulated HackRFs, or an emulated Pluto."""
        return self.emulator is not None or self.tx.air_settable

    def set_air(self, channel, seed: int) -> None:
        """The emulated air from now on: ``channel`` (a ``hil.AirChannel``) and the noise
        ``seed``; the channel's time starts at the next burst's first sample.

        Raises:
            ``hil.HilError``: real boards (their air is not the host's to set).
        """
        if self.emulator is not None:
            self.emulator.medium.set_channel(channel, seed)
        elif self.air_settable:
            self.tx.set_air(channel, ppm=self.air_ppm, seed=seed)
        else:
            raise HilError("the air between real boards is not the host's to set")

    def __call__(self, x: torch.Tensor, snr_db=None, generator: torch.Generator | None = None):
        if (
            snr_db is not None
            and self.snr_db is not None
            and abs(float(snr_db) - self.snr_db) > 1e-9
        ):
            raise ValueError(
                f"this over-the-air link runs at {self.snr_db:g} dB, asked for {float(snr_db):g} dB"
            )
        return self.transmit(x)

    def transmit(self, x: torch.Tensor):
        """``x`` [batch, num_symbols] complex64 as one burst -> ``phy.LinkOutput`` (the air
        as it is set, whatever SNR it has)."""
        x = torch.as_tensor(x)
        if x.dim() != 2:
            raise ValueError(f"x must be [batch, num_symbols] complex64, got {tuple(x.shape)}")
        blocks = [x[i].detach().cpu().numpy().astype(np.complex64) for i in range(x.shape[0])]
        result = self.send_blocks(blocks)
        x_hat = torch.from_numpy(np.stack([np.asarray(b[0], np.complex64) for b in result.blocks]))
        nv = torch.from_numpy(np.stack([np.asarray(b[1], np.float32) for b in result.blocks]))
        return LinkOutput(x_hat, nv, None)

    def close(self) -> None:
        """Close each radio once (a full-duplex board is both ends); best effort."""
        for dev in (self.tx, self.rx) if self.rx is not self.tx else (self.tx,):
            try:
                dev.close()
            except Exception:  # noqa: BLE001 - closing is best effort
                pass


def received_blocks(result) -> list:
    """``hil.ota.BurstResult`` -> one ``semcodec.links.ReceivedBlock`` per block sent: its symbols,
    noise variance, which of its frames were detected and its measured SNR."""
    return [
        ReceivedBlock(
            np.asarray(x_hat, np.complex64),
            np.asarray(noise_var, np.float32),
            [bool(f.detected) for f in result.block_frames(b)],
            result.snr_db_measured(b),
        )
        for b, (x_hat, noise_var) in enumerate(result.blocks)
    ]
