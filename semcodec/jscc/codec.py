"""The codec as transmitter and receiver use it: ``load_codec``, ``Codec.encode/decode``.

Rate: channel truncation (:mod:`semcodec.jscc.truncation`), with part of the budget on the
analog refinement layer where the transmitter's simulation favours it
(:mod:`semcodec.jscc.layer_plan`).

On-demand focus (paper section 3.2): with an object ``mask`` (and weights ``lambda_j`` over
K demanded objects), a Grad-CAM-style heat map ranks the encoder's feature positions by
how much they serve the demand, and only the box of the positions that serve it most is
sent, at the rate the budget allows; the box goes to the receiver as side information
(``meta.crop``, charged to the budget). See :mod:`semcodec.jscc.focus`.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
from pathlib import Path

import torch
from torch import Tensor

from phy import power_normalize, validate_snr_db
from semcodec.contract.checkpoint import save_checkpoint, weights_sha256
from semcodec.contract.protocol import FOCUS_FILL, Encoded, box_side_symbols, check_images
from semcodec.contract.registry import CODECS
from semcodec.jscc.analog import decode_residual
from semcodec.jscc.encoded_meta import EncodedMeta, centre_first
from semcodec.jscc.focus import attribution_box, demand_heatmap, demand_positions, densest_box
from semcodec.jscc.layer_plan import LayerPlanner
from semcodec.jscc.model import (
    JSCC_ARCHITECTURES,
    features_to_symbols,
    lmmse_input,
    load_checkpoint,
    make_model,
    reliability_to_features,
    side_info,
    symbols_to_features,
)
from semcodec.jscc.train_link import forward_train, load_compatible
from semcodec.jscc.truncation import ChannelTruncationCodec, pad4

DEFAULT_CHECKPOINT = Path(__file__).resolve().parents[1] / "checkpoints" / "default.safetensors"


class Codec(LayerPlanner, ChannelTruncationCodec):
    """A loaded JSCC (encoder + decoder) with its model card and hash: semcodec's own
    :class:`semcodec.SemanticCodec` and :class:`semcodec.TrainableCodec` (registry name
    ``jscc``; architectures :data:`semcodec.jscc.JSCC_ARCHITECTURES`)."""

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
    architectures = ("adjscc_s4_w96", *(m for m in JSCC_ARCHITECTURES if m != "adjscc_s4_w96"))
    """Architectures :meth:`untrained` builds; the first is the default."""

    def untrained(self, architecture: str | None = None) -> Codec:
        """A fresh JSCC of ``architecture`` (a :data:`semcodec.jscc.JSCC_ARCHITECTURES` name; None =
        the first of :attr:`architectures`)."""
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
        """Start from ``init``'s weights (:func:`semcodec.training.loop.load_compatible`)."""
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
        xp = pad4(x)
        if mask is None:
            m, sym, crop, analog = self._encode_whole(xp, snr, cbr)
        else:
            m, sym, crop, analog = self._encode_focus(xp, snr, cbr, mask, demand_weights, (h, w))
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

    def _encode_whole(self, xp: Tensor, snr: Tensor, cbr) -> tuple:
        """Every position of the padded images ``xp`` at the channels nearest ``cbr``:
        (learned channels, unit-power symbols, crop None, analog side information or None)."""
        b = xp.shape[0]
        cfg = self.model.cfg
        hf, wf = xp.shape[2] // 4, xp.shape[3] // 4
        analog = None
        m = self.channels_for_cbr(cbr)
        crop = None
        plan = self._layer_plan(xp, snr, m * hf * wf, hf * wf, m)
        if plan is not None:
            m, sym, analog = plan
        else:
            with torch.no_grad():
                feat = self.model.encoder(xp, side_info(snr, m, cfg.num_complex_channels, b))
            sym = power_normalize(features_to_symbols(feat, m))
        return m, sym, crop, analog

    def _focus_cbr(self, cbr) -> float:
        """``cbr`` as a float in (0, largest CBR]; ValueError otherwise."""
        lo, hi = self.cbr_range
        try:
            cbr = float(cbr)
        except (TypeError, ValueError):
            raise ValueError(f"cbr must be a number in (0, {hi:.4g}], got {cbr!r}") from None
        if not 0 < cbr <= hi * 1.001:
            raise ValueError(f"cbr in focus mode must be in (0, {hi:.4g}], got {cbr!r}")
        return cbr

    def _attribution(self, xp: Tensor, snr: Tensor, mask, demand_weights, size) -> tuple:
        """The demand's heat map over the feature grid of ``xp`` and the box (feature-grid
        units) of the positions that hold its attribution, the objects themselves included."""
        b = xp.shape[0]
        c = self.model.cfg.num_complex_channels
        with torch.no_grad():
            feat = self.model.encoder(xp, side_info(snr, c, c, b))
        heat = demand_heatmap(self.model, xp, feat, snr, mask, demand_weights, size)
        # feature-grid units; the demanded objects themselves are always in the box
        objects = demand_positions(mask, demand_weights, size, tuple(xp.shape[2:]))
        return heat, attribution_box(heat, include=objects)

    def _encode_focus(self, xp: Tensor, snr: Tensor, cbr, mask, demand_weights, size) -> tuple:
        """Focus mode: the box holding the demand's attribution at the rate ``cbr``'s budget
        allows over it, less the box's side information: (learned channels, unit-power
        symbols, crop in pixels, analog side information or None)."""
        h, w = size
        b = xp.shape[0]
        analog = None
        cbr = self._focus_cbr(cbr)
        c = self.model.cfg.num_complex_channels
        heat, box = self._attribution(xp, snr, mask, demand_weights, (h, w))
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
        return m, sym, crop, analog

    def decode(
        self,
        x_hat: Tensor,
        meta: EncodedMeta,
        snr_db,
        expected_sha256: str | None = None,
        noise_var=None,
    ) -> Tensor:
        """Received symbols -> images.

        The equaliser convention (stated once, :func:`semcodec.jscc.model.lmmse_input`): ``x_hat``
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
                "x_hat must be [batch, num_symbols] complex64, got "
                f"{getattr(x_hat, 'shape', type(x_hat))}"
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
        transmitter simulates it (:func:`semcodec.jscc.link.refine_symbols`). ``snr`` [batch]."""
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
                f"noise_var must be a float, [batch] or [batch, num_symbols] = [{b}, "
                f"{meta.num_symbols}]"
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


def load_codec(path: str | os.PathLike | None = None) -> Codec:
    """Load a codec checkpoint (None = the shipped default, offline).

    Raises FileNotFoundError when missing and ValueError (one line) when corrupt.
    """
    p = DEFAULT_CHECKPOINT if path is None else Path(path)
    model, card = load_checkpoint(p)
    return Codec(model, card, p)


@CODECS.register("jscc")
def _jscc(checkpoint: str | None = None) -> Codec:
    """semcodec's ADJSCC (:func:`load_codec`; None = the shipped checkpoint)."""
    return load_codec(checkpoint)
