"""The transmitter's split of a budget between learned channels and the analog refinement
layer (:mod:`semcodec.jscc.analog`): it simulates each option on its own decoder and keeps the
layer only where it beats the learned channels alone (:class:`LayerPlanner`)."""

from __future__ import annotations

import math

import torch
from torch import Tensor

from phy import power_normalize
from semcodec.jscc.analog import (
    AnalogSide,
    decode_residual,
    encode_residual,
    layer_symbols,
    side_symbols,
)
from semcodec.jscc.encoded_meta import EncodedMeta
from semcodec.jscc.model import features_to_symbols, side_info

LAYER_FRACTIONS = (1 / 8, 1 / 4, 3 / 8, 1 / 2, 5 / 8, 3 / 4)
"""Learned channels, as fractions of the budget's, that :meth:`LayerPlanner._layer_plan` tries
under the analog refinement layer."""
PLAN_PROBE_PX = 192  # side of the central square the transmitter simulates the split on
LAYER_MARGIN_DB = 0.2
"""How much less simulated error (dB) the best split with the analog layer needs than the
learned channels alone: the simulation is one AWGN draw at the nominal SNR, and on fading
channels the layer gains less than that draw predicts, so a split must beat the learned
channels by this margin to be chosen."""


class LayerPlanner:
    """The split between learned channels and the analog layer, as a part of
    :class:`semcodec.jscc.codec.Codec`: it reads the host's ``model``, ``sha256``,
    ``analog_layer``, ``split_fusion`` and ``decode_differentiable``."""

    def _layer_plan(
        self, region: Tensor, snr: Tensor, budget: int, positions: int, m_full: int
    ) -> tuple[int, Tensor, AnalogSide] | None:
        """Split ``budget`` symbols over ``region`` between learned channels and the analog
        refinement layer (:mod:`semcodec.jscc.analog`), or None to send learned channels only.

        The transmitter simulates each option once on an AWGN channel at the nominal SNR,
        with its own fixed-seed noise (it knows the decoder, not the draw), on the central
        ``PLAN_PROBE_PX`` square of the region at the same symbols per position: ``m_full``
        channels alone, and ``round(f * m_full)`` channels for each f in
        :data:`LAYER_FRACTIONS` with the rest of the budget, less the side information's
        symbols (at most one symbol per two coefficients), as the layer over the residual of
        its own noiseless decode. The layer option with the smallest squared error over the
        batch wins if it beats the learned channels alone by :data:`LAYER_MARGIN_DB`.

        Args:
            region: [batch, 3, 4*rows, 4*cols] the pixels the learned channels cover.
            snr: [batch] nominal SNR in dB.
            budget: complex symbols per image; positions: rows * cols.
        Returns:
            (learned channels, unit-power symbols [batch, budget - side], side information).
        """
        if not self.analog_layer:
            return None
        probe = _centre(region, PLAN_PROBE_PX)
        m, bases = self._best_split(probe, snr, budget / positions, m_full)
        if m is None:
            return None
        h, w = region.shape[2:]
        with torch.no_grad():
            if probe.shape == region.shape:  # the probe was the whole region
                sym, residual = bases[m]
            else:
                sym, meta = self._base(region, snr, m)
                residual = region - self.decode_differentiable(sym, meta, snr)
            n = layer_symbols(h, w, budget - m * positions)
            if n < 1:
                return None
            layer, side = encode_residual(residual, n)
        return m, torch.cat([sym, layer], 1), side

    def _base(self, region: Tensor, snr: Tensor, m: int) -> tuple[Tensor, EncodedMeta]:
        """Unit-power symbols of ``m`` learned channels over a whole region, and their meta."""
        b, _, h, w = region.shape
        c = self.model.cfg.num_complex_channels
        sym = power_normalize(
            features_to_symbols(self.model.encoder(region, side_info(snr, m, c, b)), m)
        )
        n = sym.shape[1]
        return sym, EncodedMeta(h, w, m, n / (3 * h * w), n, self.sha256)

    def _best_split(
        self, probe: Tensor, snr: Tensor, per_position: float, m_full: int
    ) -> tuple[int | None, dict]:
        """Learned channels under the layer with the least simulated error on ``probe`` at
        ``per_position`` symbols per position, or None when ``m_full`` channels alone win;
        and each tried split's learned symbols and noiseless residual over the probe
        (learned channels -> (symbols, residual))."""
        h, w = probe.shape[2:]
        positions = h * w // 16
        gen = torch.Generator().manual_seed(0)
        nv = (10.0 ** (-snr / 10.0))[:, None] / self.split_fusion  # after the receiver's fusion

        def received(sym: Tensor) -> Tensor:
            noise = torch.randn(sym.shape, generator=gen, dtype=torch.complex64)
            return sym + noise * nv.sqrt()

        candidates = {}  # learned channels -> the layer's symbols
        for m in sorted({max(1, round(f * m_full)) for f in LAYER_FRACTIONS}):
            n = layer_symbols(h, w, int(per_position * positions) - m * positions)
            if m < m_full and n >= side_symbols(h, w, n):  # side information under half of it
                candidates[m] = n
        if not candidates:
            return None, {}
        best, choice, bases = math.inf, None, {}
        with torch.no_grad():
            sym, meta = self._base(probe, snr, m_full)
            learned = float(
                ((self.decode_differentiable(received(sym), meta, snr) - probe) ** 2).mean()
            )
            for m, n in candidates.items():
                sym, meta = self._base(probe, snr, m)
                bases[m] = sym, probe - self.decode_differentiable(sym, meta, snr)
                layer, side = encode_residual(bases[m][1], n)
                y = self.decode_differentiable(received(sym), meta, snr)
                y = (y + decode_residual(received(layer), nv, side)).clamp(0, 1)
                err = float(((y - probe) ** 2).mean())
                if err < best:
                    best, choice = err, m
        return (choice if best * 10 ** (LAYER_MARGIN_DB / 10) < learned else None), bases


def _centre(x: Tensor, side_px: int) -> Tensor:
    """The central ``side_px`` square of [b, c, H, W] (multiples of 4 kept), or all of it."""
    h, w = x.shape[2:]
    ch, cw = min(h, side_px), min(w, side_px)
    top, left = (h - ch) // 8 * 4, (w - cw) // 8 * 4
    return x[:, :, top : top + ch, left : left + cw]
