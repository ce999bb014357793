"""Links: channel + receiver front end, ``link(x, snr_db, generator=None) -> LinkOutput``.

A link hides how symbols cross the air (flat channel, OFDM with pilots, a real radio) and
hands back equalised symbols plus the effective noise variance per symbol, which is what a
soft demapper or a JSCC decoder needs. Links are differentiable in ``x``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import torch
from torch import Tensor

from phy.channels._common import check_symbols
from phy.channels.base import Channel
from phy.ofdm.equalization import EQUALIZERS, equalize
from phy.ofdm.estimation import INTERPOLATIONS, ls_channel_estimate
from phy.ofdm.lmmse import LMMSEEstimator
from phy.ofdm.resource_grid import ResourceGrid, extract_data, map_to_grid

CSI_FLAT = ("perfect", "none")
CSI_OFDM = ("perfect", "ls", "lmmse")


@dataclass
class LinkOutput:
    """What a link delivers.

    Attributes:
        x_hat: [batch, num_symbols] complex64 after equalisation.
        noise_var: [batch, num_symbols] float32 effective post-equalisation noise variance.
        outage: [batch] bool where the channel had no path, or ``None``.
    """

    x_hat: Tensor
    noise_var: Tensor
    outage: Tensor | None = None


@runtime_checkable
class Link(Protocol):
    """What every link is: flat, OFDM, ray-traced per position or over the air.

    ``link(x, snr_db, generator=None) -> LinkOutput`` with ``x`` [batch, num_symbols]
    complex64 of unit mean power per row. Links built with ``equalizer="zf"`` return
    *unbiased* estimates with their per-symbol effective noise variance (sionna's LMMSE
    convention), which is what MRC, soft demappers and the JSCC decoder expect.
    """

    def __call__(
        self, x: Tensor, snr_db, generator: torch.Generator | None = None
    ) -> LinkOutput: ...


def combine_repetitions(x_hat: Tensor, noise_var: Tensor) -> tuple[Tensor, Tensor]:
    """Maximum-ratio combining of repeated unbiased (ZF) receptions of the same block.

    ``x_hat_r = x + n_r`` with per-symbol variance ``noise_var_r``; weighting by
    ``1 / noise_var_r`` is MRC: the effective SNR per symbol is the sum of the copies' SNRs.

    Args:
        x_hat: [repetitions, num_symbols] complex64; noise_var: [repetitions, num_symbols].
    Returns:
        (x [1, num_symbols] complex64, noise_var [1, num_symbols] float32).
    """
    wgt = 1.0 / noise_var.clamp_min(1e-12)
    x = (x_hat * wgt).sum(0, keepdim=True) / wgt.sum(0, keepdim=True)
    return x.to(torch.complex64), (1.0 / wgt.sum(0, keepdim=True)).to(torch.float32)


def check_link_input(x: Tensor) -> Tensor:
    """Raise ValueError unless ``x`` is [batch, num_symbols] complex."""
    check_symbols(x)
    if x.dim() != 2:
        raise ValueError(f"x must be [batch, num_symbols] complex64, got shape {tuple(x.shape)}")
    return x


class FlatLink(torch.nn.Module):
    """A flat (one tap per symbol) channel and a one-tap equaliser.

    Args:
        channel: any :class:`phy.Channel` (AWGN, Rayleigh block/fast, Rician, ...).
        csi: ``"perfect"`` (the receiver knows h) or ``"none"`` (it equalises nothing:
            ``x_hat = y`` and ``noise_var`` is the channel's noise variance).
        equalizer: ``"mmse"`` or ``"zf"``; see :func:`phy.equalize` for what each returns.
    """

    def __init__(self, channel: Channel, csi: str = "perfect", equalizer: str = "mmse"):
        super().__init__()
        if not isinstance(channel, torch.nn.Module) or not callable(channel):
            raise ValueError(f"channel must be a phy Channel, got {type(channel).__name__}")
        if csi not in CSI_FLAT:
            raise ValueError(f"csi must be one of {list(CSI_FLAT)}, got {csi!r}")
        if equalizer not in EQUALIZERS:
            raise ValueError(f"equalizer must be one of {list(EQUALIZERS)}, got {equalizer!r}")
        self.channel = channel
        self.csi = csi
        self.equalizer = equalizer

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> LinkOutput:
        """Args: x [batch, num_symbols] complex64; snr_db float or [batch] (Es/N0, dB).

        Returns: LinkOutput with x_hat [batch, num_symbols] complex64 and noise_var
        [batch, num_symbols] float32.
        """
        check_link_input(x)
        out = self.channel(x, snr_db, generator=generator)
        nv = out.noise_var.reshape(-1, 1).to(torch.float32)
        if out.h is None or self.csi == "none":
            return LinkOutput(out.y, nv.expand(out.y.shape).contiguous(), out.outage)
        x_hat, nv_eff = equalize(out.y, out.h, nv, self.equalizer)
        return LinkOutput(x_hat, nv_eff, out.outage)

    def extra_repr(self) -> str:
        return f"csi={self.csi!r}, equalizer={self.equalizer!r}"


class OFDMLink(torch.nn.Module):
    """Symbols on an OFDM resource grid with pilots, a frequency-domain channel, estimation
    and one-tap equalisation per resource element.

    The symbols fill the data resource elements of as many slots as needed (zero-padded);
    the grid ``[batch, num_slots * num_ofdm_symbols, fft_size]`` goes through the channel in
    the frequency domain (a cyclic prefix longer than the channel is assumed; the
    time-domain path with real synchronisation is :func:`phy.receive_frame`). ``snr_db`` is
    Es/N0 per resource element (data and pilots have unit power).

    Args:
        grid: the :class:`ResourceGrid`.
        channel: a channel accepting ``[batch, num_ofdm_symbols, fft_size]`` grids (all flat
            channels, ``TDLChannel``, ``CDLChannel``).
        csi: ``"perfect"`` (the channel's h), ``"ls"`` (pilot LS estimate, interpolated) or
            ``"lmmse"`` (sionna's LMMSE filtering of the LS pilot estimates, ``estimator``);
            with an estimate its error variance is added to the reported ``noise_var``.
        equalizer: ``"mmse"`` or ``"zf"``.
        interpolation: ``"linear"`` or ``"nearest"`` (for ``csi="ls"``).
        estimator: for ``csi="lmmse"``, a :class:`phy.ofdm.LMMSEEstimator` (it holds the
            channel statistics the receiver assumes).
    """

    def __init__(
        self,
        grid: ResourceGrid,
        channel: Channel,
        csi: str = "ls",
        equalizer: str = "mmse",
        interpolation: str = "linear",
        estimator: LMMSEEstimator | None = None,
    ):
        super().__init__()
        if not isinstance(grid, ResourceGrid):
            raise ValueError(f"grid must be a phy.ResourceGrid, got {type(grid).__name__}")
        if not isinstance(channel, torch.nn.Module) or not callable(channel):
            raise ValueError(f"channel must be a phy Channel, got {type(channel).__name__}")
        if csi not in CSI_OFDM:
            raise ValueError(f"csi must be one of {list(CSI_OFDM)}, got {csi!r}")
        if equalizer not in EQUALIZERS:
            raise ValueError(f"equalizer must be one of {list(EQUALIZERS)}, got {equalizer!r}")
        if interpolation not in INTERPOLATIONS:
            raise ValueError(
                f"interpolation must be one of {list(INTERPOLATIONS)}, got {interpolation!r}"
            )
        if csi == "ls" and not grid.pilot_ofdm_symbols:
            raise ValueError("csi='ls' needs a grid with pilot_ofdm_symbols")
        if csi == "lmmse" and not isinstance(estimator, LMMSEEstimator):
            raise ValueError("csi='lmmse' needs estimator=phy.ofdm.LMMSEEstimator(grid, ...)")
        if estimator is not None and estimator.grid != grid:
            raise ValueError("estimator must be built for the link's grid")
        self.estimator = estimator
        self.grid = grid
        self.channel = channel
        self.csi = csi
        self.equalizer = equalizer
        self.interpolation = interpolation

    def forward(self, x: Tensor, snr_db, generator: torch.Generator | None = None) -> LinkOutput:
        """Args: x [batch, num_symbols] complex64; snr_db float or [batch].

        Returns: LinkOutput(x_hat [batch, num_symbols] complex64, noise_var [batch, num_symbols]).
        """
        check_link_input(x)
        b, n = x.shape
        total = self.grid.num_slots(n) * self.grid.num_data_symbols
        xp = torch.nn.functional.pad(x, (0, total - n)) if total > n else x
        g = map_to_grid(xp, self.grid)  # [batch, num_slots * num_ofdm_symbols, fft_size]
        out = self.channel(g, snr_db, generator=generator)
        nv = out.noise_var.to(torch.float32)
        err: Tensor | float
        if self.csi == "perfect":
            h = torch.ones_like(g) if out.h is None else torch.broadcast_to(out.h, g.shape)
            err = 0.0
        elif self.csi == "lmmse":
            assert self.estimator is not None  # checked in __init__
            h, err = self.estimator(out.y, nv)
        else:
            h, err = ls_channel_estimate(out.y, self.grid, nv, self.interpolation)
        x_hat, nv_eff = equalize(out.y, h, nv, self.equalizer, err)
        x_hat = extract_data(x_hat, self.grid)[:, :n]
        nv_eff = extract_data(nv_eff, self.grid)[:, :n]
        return LinkOutput(x_hat, nv_eff, out.outage)

    def extra_repr(self) -> str:
        return (
            f"csi={self.csi!r}, equalizer={self.equalizer!r}, interpolation={self.interpolation!r}"
        )
