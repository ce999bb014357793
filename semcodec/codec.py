"""The codec as transmitter and receiver use it: ``load_codec``, ``Codec.encode/decode``.

Rate: keeping the first ``m`` of the model's importance-ordered complex channels gives
CBR ``m/48`` (the encoder downsamples by 4: 48 real values per position). A requested CBR
is served by the nearest such m; ``Encoded.meta.cbr`` is the CBR actually used.

On-demand focus (paper section 3.2): with an object ``mask`` (and weights ``lambda_j`` over
K demanded objects), a Grad-CAM-style heat map ranks the encoder's feature positions by
how much they serve the demand, and only the box of the positions that serve it most is
sent, at the rate the budget allows; the box goes to the receiver as side information
(``meta.crop``, charged to the budget). See :mod:`semcodec.focus`.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor
from torch.nn import functional as F

from phy import power_normalize, validate_snr_db
from semcodec.analog import (
    AnalogSide,
    decode_residual,
    encode_residual,
    layer_symbols,
    side_symbols,
)
from semcodec.checkpoint import (
    KnowledgeBaseMismatch,
    load_checkpoint,
    save_checkpoint,
    weights_sha256,
)
from semcodec.contract import (
    FOCUS_FILL,
    Encoded,
    box_bits,
    box_side_symbols,
    check_images,
)
from semcodec.focus import attribution_box, demand_heatmap, demand_positions, densest_box
from semcodec.jscc_train import forward_train, load_compatible
from semcodec.model import (
    MODELS,
    features_to_symbols,
    lmmse_input,
    make_model,
    reliability_to_features,
    side_info,
    symbols_to_features,
)

DEFAULT_CHECKPOINT = Path(__file__).resolve().parent / "checkpoints" / "default.safetensors"
LAYER_FRACTIONS = (1 / 8, 1 / 4, 3 / 8, 1 / 2, 5 / 8, 3 / 4)
"""Learned channels, as fractions of the budget's, that :meth:`Codec._layer_plan` tries
under the analog refinement layer."""
PLAN_PROBE_PX = 192  # side of the central square the transmitter simulates the split on
LAYER_MARGIN_DB = 0.2
"""How much less simulated error (dB) the best split with the analog layer needs than the
learned channels alone: the simulation is one AWGN draw at the nominal SNR, and on fading
channels the layer gains less than that draw predicts, so a split must beat the learned
channels by this margin to be chosen."""


@dataclass(frozen=True)
class EncodedMeta:
    """What the receiver needs besides the symbols (side information).

    Attributes:
        height, width: original image size in pixels.
        num_channels: complex channels kept per sent position (m). In focus mode a model
            whose decoder reads each symbol's reliability also sends channel m + 1 at the
            box's first ``num_symbols - m * positions`` positions of :func:`centre_first`
            (the budget's remainder; no side information needed).
        cbr: CBR actually used: num_symbols / (3 * height * width).
        num_symbols: complex symbols per image.
        codec_sha256: hash of the transmitter's codec (knowledge base identity).
        crop: (top, left, height, width) in pixels of the box sent in focus mode (the
            positions holding the demand's attribution), else None (whole image).
        analog: the analog refinement layer's side information when the last
            ``analog.num_symbols`` symbols carry the base's residual
            (:mod:`semcodec.analog`), else None.
    """

    height: int
    width: int
    num_channels: int
    cbr: float
    num_symbols: int
    codec_sha256: str
    crop: tuple[int, int, int, int] | None = None
    analog: AnalogSide | None = None

    @property
    def base_symbols(self) -> int:
        """Symbols of the learned channels (the first ones; the analog layer's follow)."""
        return self.num_symbols - (self.analog.num_symbols if self.analog is not None else 0)

    def side_info_bits(self) -> int:
        """Bits of side information per image: the focus box, plus the analog layer's
        chunk energies."""
        layer = self.analog.side_info_bits() if self.analog is not None else 0
        box = box_bits(self.height, self.width) if self.crop is not None else 0
        return box + layer


def _pad4(x: Tensor) -> Tensor:
    """Replicate-pad height and width up to multiples of 4. [b, c, H, W] -> [b, c, H4, W4]."""
    h, w = x.shape[-2:]
    ph, pw = (-h) % 4, (-w) % 4
    return F.pad(x, (0, pw, 0, ph), mode="replicate") if ph or pw else x


class ChannelTruncationCodec:
    """What semcodec's codecs share: a network whose encoder output holds
    ``num_complex_channels`` importance-ordered complex channels per 4x4 block (CBR m/48 for
    the first m), loaded with its model card and hash."""

    def __init__(self, model, card: dict, path: Path | None = None):
        self.model = model.eval()
        self.card = card
        self.path = path
        self.sha256: str = card["sha256"]

    @property
    def name(self) -> str:
        return self.card.get("name", self.model.cfg.name)

    @property
    def module(self):
        """The network (every trained parameter)."""
        return self.model

    @property
    def cbr_range(self) -> tuple[float, float]:
        """(smallest, largest) CBR: (1/48, num_complex_channels/48)."""
        return self.model.cfg.cbr_range

    @property
    def snr_range_db(self) -> tuple[float, float]:
        """SNR range (Es/N0, dB) the model was trained for."""
        return (self.model.cfg.snr_min_db, self.model.cfg.snr_max_db)

    @property
    def rate_levels(self) -> tuple[float, ...]:
        """CBRs m/48 for m = 1 .. num_complex_channels."""
        c = self.model.cfg.num_complex_channels
        return tuple(k * self.model.cfg.cbr_per_channel for k in range(1, c + 1))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, sha256={self.sha256[:12]}, cbr_range={self.cbr_range}, snr_range_db={self.snr_range_db})"

    def check_knowledge_base(self, expected_sha256: str | None, meta_sha256: str | None) -> None:
        """Raise :class:`KnowledgeBaseMismatch` unless both hashes (where given) are ours."""
        for label, sha in (
            ("expected_sha256", expected_sha256),
            ("meta.codec_sha256", meta_sha256),
        ):
            if sha is not None and sha != self.sha256:
                raise KnowledgeBaseMismatch(
                    f"knowledge base mismatch: transmitter codec {str(sha)[:12]} ({label}) != receiver codec {self.sha256[:12]}; load the same checkpoint on both ends"
                )

    def channels_for_cbr(self, cbr: float) -> int:
        """Kept complex channels m for a CBR (nearest multiple of 1/48); ValueError outside the range."""
        lo, hi = self.cbr_range
        try:
            c = float(cbr)
        except (TypeError, ValueError):
            raise ValueError(f"cbr must be a number in [{lo:.4g}, {hi:.4g}], got {cbr!r}") from None
        if not math.isfinite(c) or not lo * 0.999 <= c <= hi * 1.001:
            raise ValueError(
                f"cbr must be in the codec's range [1/48, {round(hi * 48)}/48] = [{lo:.4g}, {hi:.4g}], got {cbr!r}"
            )
        return int(
            min(
                max(round(c / self.model.cfg.cbr_per_channel), 1),
                self.model.cfg.num_complex_channels,
            )
        )


class Codec(ChannelTruncationCodec):
    """A loaded JSCC (encoder + decoder) with its model card and hash: semcodec's own
    :class:`semcodec.SemanticCodec` and :class:`semcodec.TrainableCodec` (registry name
    ``jscc``; architectures :data:`semcodec.MODELS`)."""

    supports_focus = True
    analog_layer = True
    """Whether :meth:`encode` may spend part of the budget on the analog refinement layer
    (set False on an instance for learned channels only)."""
    layer_fusion = 1.0
    """The receiver's estimate of the analog layer is the LMMSE against the noise variance
    divided by this (>= 1). 1: each image's own LMMSE. Where a later estimator averages about
    this many independently received images of the same surface (a radiance field fusing the
    views), shrinking each image's estimate less leaves it noisier but less biased, and the
    average better (:func:`for_fusion`)."""
    split_fusion = 1.0
    """The transmitter simulates the split between learned channels and the layer at the
    noise variance divided by this (>= 1): the noise left once the receiver has fused about
    this many receptions. Its refinement still targets each image's own error (refining
    against the fused receiver did worse end to end)."""
    architectures = ("adjscc_s4_w96", *(m for m in MODELS if m != "adjscc_s4_w96"))
    """Architectures :meth:`untrained` builds; the first is the default."""

    def untrained(self, architecture: str | None = None) -> Codec:
        """A fresh JSCC of ``architecture`` (a :data:`semcodec.MODELS` name; None = the first
        of :attr:`architectures`)."""
        model = make_model(architecture or self.architectures[0])
        name = model.cfg.name
        return Codec(model, {"name": name, "sha256": weights_sha256(model.state_dict(), model.cfg)})

    def forward_train(self, x, snr_db, cbr, channel, generator) -> Tensor:
        """:meth:`semcodec.TrainableCodec.forward_train`: ``cbr`` [batch] -> m = cbr * 48."""
        m = torch.round(torch.as_tensor(cbr) / self.model.cfg.cbr_per_channel).long()
        return forward_train(self.model, x, snr_db, m, channel, generator)

    def save(self, path, card: dict) -> str:
        """Write the checkpoint (``load_codec`` / ``make_codec("jscc:PATH")`` load it)."""
        self.sha256 = save_checkpoint(path, self.model, {"name": self.name, **card})
        return self.sha256

    def load_compatible(self, init: Codec) -> None:
        """Start from ``init``'s weights (:func:`semcodec.training.load_compatible`)."""
        if not isinstance(init, Codec):
            raise ValueError(
                f"init codec {getattr(init, 'name', type(init).__name__)} is not a jscc codec"
            )
        load_compatible(self.model, init.model)

    def _extra_symbols(self, budget: int, m: int, rows: int, cols: int) -> int:
        """Symbols of channel m + 1 that fill a focus budget's remainder over a box of
        ``m`` channels: only for models whose decoder reads each symbol's reliability (the
        positions left out look like erased symbols to it); 0 for the others."""
        if not self.model.cfg.decoder_reliability or m >= self.model.cfg.num_complex_channels:
            return 0
        return budget - m * rows * cols

    def _snr(self, snr_db, batch: int) -> Tensor:
        validate_snr_db(snr_db)
        s = torch.as_tensor(snr_db, dtype=torch.float32).flatten()
        if s.numel() not in (1, batch):
            raise ValueError(
                f"snr_db must be a float or have {batch} (batch) values, got {s.numel()}"
            )
        return s.expand(batch) if s.numel() == 1 else s

    def encode(
        self, images: Tensor, snr_db, cbr: float, mask: Tensor | None = None, demand_weights=None
    ) -> Encoded:
        """Images -> unit-power channel symbols.

        Args:
            images: [batch, 3, height, width] float32 in [0, 1] (any size >= 8 px).
            snr_db: float or [batch]: the SNR the transmitter expects (feeds the AF modules).
            cbr: channel symbols per real source value, in ``cbr_range`` (in focus mode any
                rate up to the largest CBR whose budget carries the box's side information
                and one symbol: fewer channels, or a smaller box, are sent).
            mask: optional [batch, K, height, width] (or [batch, height, width]) masks of the K
                demanded objects, values in [0, 1]: switches on focus mode.
            demand_weights: optional K weights lambda_j (or [batch, K]); default equal.
        Returns:
            :class:`Encoded` with symbols [batch, num_symbols] complex64.
        """
        x = check_images(images)
        b, _, h, w = x.shape
        snr = self._snr(snr_db, b)
        cfg = self.model.cfg
        xp = _pad4(x)
        hf, wf = xp.shape[2] // 4, xp.shape[3] // 4
        analog = None
        if mask is None:
            m = self.channels_for_cbr(cbr)
            crop = None
            plan = self._layer_plan(xp, snr, m * hf * wf, hf * wf, m)
            if plan is not None:
                m, sym, analog = plan
            else:
                with torch.no_grad():
                    feat = self.model.encoder(xp, side_info(snr, m, cfg.num_complex_channels, b))
                sym = power_normalize(features_to_symbols(feat, m))
        else:
            lo, hi = self.cbr_range
            try:
                cbr = float(cbr)
            except (TypeError, ValueError):
                raise ValueError(f"cbr must be a number in (0, {hi:.4g}], got {cbr!r}") from None
            if not 0 < cbr <= hi * 1.001:
                raise ValueError(f"cbr in focus mode must be in (0, {hi:.4g}], got {cbr!r}")
            c = cfg.num_complex_channels
            with torch.no_grad():
                feat = self.model.encoder(xp, side_info(snr, c, c, b))
            heat = demand_heatmap(self.model, xp, feat, snr, mask, demand_weights, (h, w))
            # feature-grid units; the demanded objects themselves are always in the box
            objects = demand_positions(mask, demand_weights, (h, w), tuple(xp.shape[2:]))
            box = attribution_box(heat, include=objects)
            budget = max(int(round(float(cbr) * 3 * h * w)), 1)
            box_side = box_side_symbols(h, w)  # the box's side information rides in the budget
            if budget <= box_side:
                raise ValueError(
                    f"cbr {cbr:.4g} gives {budget} symbols, which do not carry the focus box's "
                    f"side information ({box_side} symbols) and one more"
                )
            budget -= box_side
            # the box that holds the demand's attribution, at the rate that fits; below one
            # channel over it, the part of it that holds the most attribution
            top, left, rows, cols = densest_box(heat, box, budget)
            m = min(c, budget // (rows * cols))
            crop = (4 * top, 4 * left, 4 * rows, 4 * cols)
            xc = xp[:, :, crop[0] : crop[0] + crop[2], crop[1] : crop[1] + crop[3]]
            plan = self._layer_plan(xc, snr, budget, rows * cols, m)
            extra = self._extra_symbols(budget, m, rows, cols) if plan is None else 0
            if plan is not None:
                m, sym, analog = plan
            else:
                with torch.no_grad():
                    fc = self.model.encoder(xc, side_info(snr, m + (extra > 0), c, b))
                sym = features_to_symbols(fc, m)
                if extra:
                    part = features_to_symbols(fc[:, 2 * m : 2 * m + 2], 1)
                    sym = torch.cat([sym, part[:, centre_first(rows, cols)[:extra]]], 1)
                sym = power_normalize(sym)
        meta = EncodedMeta(
            height=h,
            width=w,
            num_channels=m,
            cbr=sym.shape[1] / (3 * h * w),
            num_symbols=int(sym.shape[1]),
            codec_sha256=self.sha256,
            crop=crop,
            analog=analog,
        )
        return Encoded(sym.to(torch.complex64), meta)

    def _layer_plan(
        self, region: Tensor, snr: Tensor, budget: int, positions: int, m_full: int
    ) -> tuple[int, Tensor, AnalogSide] | None:
        """Split ``budget`` symbols over ``region`` between learned channels and the analog
        refinement layer (:mod:`semcodec.analog`), or None to send learned channels only.

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

    def decode(
        self,
        x_hat: Tensor,
        meta: EncodedMeta,
        snr_db,
        expected_sha256: str | None = None,
        noise_var=None,
    ) -> Tensor:
        """Received symbols -> images.

        The equaliser convention (stated once, :func:`semcodec.model.lmmse_input`): ``x_hat``
        are *unbiased* estimates ``x + e`` (zero-forcing for one tap, sionna's LMMSE) and
        ``noise_var`` the effective variance of ``e`` per symbol, as ``phy`` links with
        ``equalizer="zf"`` return them. The decoder sees the LMMSE estimates and, for
        knowledge-base version 2 models, each symbol's reliability.

        Args:
            x_hat: [batch, num_symbols] complex64, unbiased equalised symbols.
            meta: the transmitter's :class:`EncodedMeta`.
            snr_db: float or [batch]: the receiver's average SNR estimate in dB (what the AF
                modules see; version-1 models given ``noise_var`` see the SNR it implies).
            noise_var: None (AWGN: ``10**(-snr_db/10)`` for every symbol), [batch] or
                [batch, num_symbols] effective noise variance per symbol.
            expected_sha256: the codec hash the transmitter announced (also checked against
                ``meta.codec_sha256``).
        Returns:
            [batch, 3, height, width] float32 in [0, 1].
        Raises:
            KnowledgeBaseMismatch: the hashes differ.
        """
        self.check_knowledge_base(expected_sha256, meta.codec_sha256)
        if not isinstance(x_hat, Tensor) or not x_hat.is_complex() or x_hat.dim() != 2:
            raise ValueError(
                f"x_hat must be [batch, num_symbols] complex64, got {getattr(x_hat, 'shape', type(x_hat))}"
            )
        if x_hat.shape[1] != meta.num_symbols:
            raise ValueError(
                f"x_hat must have {meta.num_symbols} symbols per image (meta), got {x_hat.shape[1]}"
            )
        snr = self._snr(snr_db, x_hat.shape[0])
        with torch.no_grad():
            return self.decode_differentiable(x_hat, meta, snr, noise_var)

    def decode_differentiable(self, x_hat: Tensor, meta: EncodedMeta, snr: Tensor, noise_var=None):
        """:meth:`decode` without its checks and with autograd on: the receiver as the
        transmitter simulates it (:func:`semcodec.baselines.refine_symbols`). ``snr`` [batch]."""
        b = x_hat.shape[0]
        if meta.analog is not None:
            return self._decode_layered(x_hat, meta, snr, noise_var)
        cfg = self.model.cfg
        hf, wf = math.ceil(meta.height / 4), math.ceil(meta.width / 4)
        m = meta.num_channels
        c = cfg.num_complex_channels
        nv = 10.0 ** (-snr / 10.0) if noise_var is None else noise_var
        if not cfg.decoder_reliability and noise_var is not None:
            # version 1 was trained on AWGN symbols as received, told their SNR. Give it the
            # effective SNR of the block (from the mean reliability, robust to deep fades:
            # exactly 1/noise_var when it is uniform) and every symbol scaled to look like
            # AWGN at that SNR: relative LMMSE (1 + nv_eff) / (1 + nv_i), 1 where nv_i = nv_eff.
            nv_i = torch.as_tensor(noise_var, dtype=torch.float32)
            nv_i = (nv_i.reshape(-1, 1) if nv_i.dim() <= 1 else nv_i).expand(b, -1).clamp(0.0, 1e6)
            w = 1.0 / (1.0 + nv_i)
            nv_eff = 1.0 / w.reshape(w.shape[0], -1).mean(1, keepdim=True) - 1.0
            snr = (-10.0 * torch.log10(nv_eff[:, 0].clamp_min(1e-12))).clamp(*self.snr_range_db)
            snr = snr.expand(b) if snr.numel() == 1 else snr
            x_hat = x_hat * ((1.0 + nv_eff) * w).to(torch.complex64)
        if not cfg.decoder_reliability:
            nv = 0.0
        try:
            x_hat, rel = lmmse_input(x_hat.to(torch.complex64), nv)
        except RuntimeError:
            raise ValueError(
                f"noise_var must be a float, [batch] or [batch, num_symbols] = [{b}, {meta.num_symbols}]"
            ) from None
        side = side_info(snr, m, c, b)
        if meta.crop is not None:
            t, left, ch, cw = meta.crop
            rows, cols = ch // 4, cw // 4
            n = m * rows * cols
            z = symbols_to_features(x_hat[:, :n], m, c, rows, cols)
            r = reliability_to_features(rel[:, :n], m, c, rows, cols)
            if meta.num_symbols > n:  # channel m + 1 at the box's central positions
                at = centre_first(rows, cols)[: meta.num_symbols - n]
                part = torch.zeros(b, rows * cols, dtype=x_hat.dtype)
                part[:, at] = x_hat[:, n:]
                z[:, 2 * m : 2 * m + 2] = symbols_to_features(part, 1, 1, rows, cols)
                r[:, m].view(b, -1)[:, at] = rel[:, n:]
                side = side_info(snr, m + 1, c, b)
            yc = self.model.decoder(z, side, r)
            y = torch.full((b, 3, 4 * hf, 4 * wf), FOCUS_FILL)
            y[:, :, t : t + ch, left : left + cw] = yc
            return y[:, :, : meta.height, : meta.width].clamp(0, 1)
        z = symbols_to_features(x_hat, m, c, hf, wf)
        r = reliability_to_features(rel, m, c, hf, wf)
        y = self.model.decoder(z, side, r)
        return y[:, :, : meta.height, : meta.width].clamp(0, 1)

    def _decode_layered(self, x_hat: Tensor, meta: EncodedMeta, snr: Tensor, noise_var=None):
        """The learned channels' decode plus the analog layer's residual estimate."""
        b, nb = x_hat.shape[0], meta.base_symbols
        base = dataclasses.replace(meta, num_symbols=nb, analog=None)
        if noise_var is None:
            nv, nv_base = (10.0 ** (-snr / 10.0))[:, None], None
        else:
            nv = torch.as_tensor(noise_var, dtype=torch.float32)
            nv = nv.reshape(-1, 1) if nv.dim() <= 1 else nv
            nv_base, nv = (nv, nv) if nv.shape[1] == 1 else (nv[:, :nb], nv[:, nb:])
            nv = nv.expand(b, -1) if nv.shape[0] == 1 else nv
        y = self.decode_differentiable(x_hat[:, :nb], base, snr, nv_base)
        res = decode_residual(x_hat[:, nb:], nv / self.layer_fusion, meta.analog)
        top, left = meta.crop[:2] if meta.crop is not None else (0, 0)
        rh, rw = res.shape[2:]
        full = torch.zeros(b, 3, max(y.shape[2], top + rh), max(y.shape[3], left + rw))
        full[:, :, top : top + rh, left : left + rw] = res
        return (y + full[:, :, : meta.height, : meta.width]).clamp(0, 1)


def learned_only(codec):
    """``codec`` without the analog refinement layer (a copy; codecs without one as they are)."""
    if not getattr(codec, "analog_layer", False):
        return codec
    out = copy.copy(codec)
    out.analog_layer = False
    return out


def for_fusion(codec, views: float, end: str = "receiver"):
    """``codec`` for images averaged over about ``views`` independent receptions after
    decoding (a copy; codecs without the analog layer as they are): as the ``"receiver"``
    (:attr:`Codec.layer_fusion`) or as the ``"transmitter"`` that splits its budget for
    such a receiver (:attr:`Codec.split_fusion`)."""
    views = float(views)
    if not (math.isfinite(views) and views >= 1):
        raise ValueError(f"views must be a finite number >= 1, got {views!r}")
    attr = {"receiver": "layer_fusion", "transmitter": "split_fusion"}.get(end)
    if attr is None:
        raise ValueError(f"end must be 'receiver' or 'transmitter', got {end!r}")
    if not hasattr(codec, attr) or views == getattr(codec, attr):
        return codec
    out = copy.copy(codec)
    setattr(out, attr, views)
    return out


def _centre(x: Tensor, side_px: int) -> Tensor:
    """The central ``side_px`` square of [b, c, H, W] (multiples of 4 kept), or all of it."""
    h, w = x.shape[2:]
    ch, cw = min(h, side_px), min(w, side_px)
    top, left = (h - ch) // 8 * 4, (w - cw) // 8 * 4
    return x[:, :, top : top + ch, left : left + cw]


def load_codec(path: str | os.PathLike | None = None) -> Codec:
    """Load a codec checkpoint (None = the shipped default, offline).

    Raises FileNotFoundError when missing and ValueError (one line) when corrupt.
    """
    p = DEFAULT_CHECKPOINT if path is None else Path(path)
    model, card = load_checkpoint(p)
    return Codec(model, card, p)


def centre_first(rows: int, cols: int) -> Tensor:
    """The positions of a rows x cols box (row-major indices), nearest its centre first
    (ties in row-major order): where a partial channel goes, known to both ends."""
    r, c = torch.meshgrid(torch.arange(rows), torch.arange(cols), indexing="ij")
    d = (2 * r - (rows - 1)) ** 2 + (2 * c - (cols - 1)) ** 2
    return torch.sort(d.flatten(), stable=True).indices


def receiver_mask(meta: EncodedMeta, height: int, width: int) -> np.ndarray | None:
    """[height, width] float32: the pixels the focus-mode side information says were sent
    (the ``meta.crop`` box); None = whole image."""
    if meta.crop is None:
        return None
    top, left, rows, cols = (int(v) for v in meta.crop)
    m = np.zeros((height, width), np.float32)
    m[max(top, 0) : min(top + rows, height), max(left, 0) : min(left + cols, width)] = 1.0
    return m
