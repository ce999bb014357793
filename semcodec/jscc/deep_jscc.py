"""Deep JSCC (Bourtsoulatze, Burth Kurka and Gunduz, 2019), the classic CNN anchor, on
semcodec's codec contract. Registered as codec ``deepjscc`` through the same registry and
factory signature a plugin uses.

Encoder: five 5x5 convolutions with PReLU (16 and 32 channels at stride 2, then 32, 32 and
``2 * num_complex_channels`` at stride 1), average power normalisation. Decoder: the
mirror image in transposed convolutions, PReLU, and a sigmoid at the output. Neither sees
the SNR (the paper's model is trained for a range and used across it).

Rate by channel truncation: the encoder's output at 1/4 resolution holds
``num_complex_channels`` complex channels per position; keeping the first ``m`` gives CBR
``m / 48``. Trained with random ``m`` (the trainer's rate levels), the first channels learn
to carry the most. The decoder sees the LMMSE estimates ``x_hat / (1 + noise_var)`` with
dropped channels at zero; it has no focus mode (``supports_focus = False``: focus callers
use :func:`semcodec.contract.focus_by_box`).
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
from torch import Tensor, nn

from common import Registry
from phy import power_normalize, validate_snr_db
from semcodec.contract.checkpoint import (
    read_checkpoint,
    save_checkpoint,
    weights_sha256,
)
from semcodec.contract.protocol import Encoded, check_images
from semcodec.contract.registry import CODECS
from semcodec.jscc.channels import masked_transmit
from semcodec.jscc.encoded_meta import EncodedMeta
from semcodec.jscc.model import features_to_symbols, lmmse_input, symbols_to_features
from semcodec.jscc.truncation import ChannelTruncationCodec, pad4

CODEC_NAME = "deepjscc"


@dataclass(frozen=True)
class DeepJSCCConfig:
    """Architecture of a Deep JSCC model (stored in the model card).

    Attributes:
        name: architecture name (a key of :data:`DEEPJSCC_ARCHITECTURES`).
        hidden: the two hidden widths (paper: 16 after the first conv, 32 after).
        num_complex_channels: complex channels per 4x4 pixel block at full rate (CBR m/48).
        snr_min_db, snr_max_db: SNR range (Es/N0, dB) it is trained for.
    """

    name: str = "deepjscc_c16"
    hidden: tuple[int, int] = (16, 32)
    num_complex_channels: int = 8
    snr_min_db: float = -5.0
    snr_max_db: float = 20.0

    def __post_init__(self):
        object.__setattr__(self, "hidden", tuple(int(v) for v in self.hidden))
        if len(self.hidden) != 2 or not all(4 <= v <= 512 for v in self.hidden):
            raise ValueError(f"hidden must be two widths in [4, 512], got {self.hidden}")
        if not 1 <= self.num_complex_channels <= 24:
            raise ValueError(
                f"num_complex_channels must be in [1, 24], got {self.num_complex_channels}"
            )
        if not -30.0 <= self.snr_min_db < self.snr_max_db <= 60.0:
            raise ValueError(
                f"snr_min_db < snr_max_db must lie in [-30, 60] dB, got {self.snr_min_db}, "
                f"{self.snr_max_db}"
            )

    @property
    def cbr_per_channel(self) -> float:
        """CBR one kept complex channel adds: 1/48 (downsampling by 4)."""
        return 1.0 / 48

    @property
    def cbr_range(self) -> tuple[float, float]:
        return (self.cbr_per_channel, self.num_complex_channels * self.cbr_per_channel)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["hidden"] = list(self.hidden)
        return d


DEEPJSCC_ARCHITECTURES = Registry[DeepJSCCConfig](
    "deepjscc architecture",
    {
        "deepjscc_c16": DeepJSCCConfig(),
        "deepjscc_c16_w64": DeepJSCCConfig(name="deepjscc_c16_w64", hidden=(64, 64)),
    },
)


def _conv(cin: int, cout: int, stride: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 5, stride=stride, padding=2)


def _deconv(cin: int, cout: int, stride: int) -> nn.ConvTranspose2d:
    return nn.ConvTranspose2d(cin, cout, 5, stride=stride, padding=2, output_padding=stride - 1)


class DeepJSCCModel(nn.Module):
    """encoder: [batch, 3, H, W] (multiples of 4) -> [batch, 2*C, H/4, W/4] real features;
    decoder: the inverse, [batch, 3, H, W] in [0, 1]."""

    def __init__(self, cfg: DeepJSCCConfig):
        super().__init__()
        self.cfg = cfg
        a, b = cfg.hidden
        c = 2 * cfg.num_complex_channels
        widths = [(3, a, 2), (a, b, 2), (b, b, 1), (b, b, 1), (b, c, 1)]
        enc: list[nn.Module] = []
        for cin, cout, stride in widths:
            enc += [_conv(cin, cout, stride), nn.PReLU(cout)]
        self.encoder = nn.Sequential(*enc)
        dec: list[nn.Module] = []
        for cout, cin, stride in reversed(widths):
            dec += [_deconv(cin, cout, stride), nn.PReLU(cout) if cout != 3 else nn.Sigmoid()]
        self.decoder = nn.Sequential(*dec)


class DeepJSCC(ChannelTruncationCodec):
    """A Deep JSCC codec: :class:`semcodec.SemanticCodec` and :class:`semcodec.TrainableCodec`."""

    supports_focus = False
    architectures = tuple(DEEPJSCC_ARCHITECTURES)

    def encode(self, images, snr_db, cbr, mask=None, demand_weights=None) -> Encoded:
        """Images [batch, 3, height, width] in [0, 1] -> [batch, m*ceil(H/4)*ceil(W/4)]
        complex64 unit-power symbols. ``snr_db`` is checked but not used (not SNR-adaptive)."""
        if mask is not None:
            raise ValueError(f"{self.name} cannot focus (supports_focus=False); use focus_by_box")
        x = check_images(images)
        validate_snr_db(snr_db)
        b, _, h, w = x.shape
        m = self.channels_for_cbr(cbr)
        with torch.no_grad():
            feat = self.model.encoder(pad4(x))
        sym = power_normalize(features_to_symbols(feat, m)).to(torch.complex64)
        meta = EncodedMeta(h, w, m, sym.shape[1] / (3 * h * w), int(sym.shape[1]), self.sha256)
        return Encoded(sym, meta)

    def decode(self, x_hat, meta, snr_db, expected_sha256=None, noise_var=None) -> Tensor:
        """Unbiased symbols [batch, num_symbols] complex64 -> [batch, 3, height, width] float32;
        the decoder sees ``x_hat / (1 + noise_var)`` (noise_var None: ``10**(-snr_db/10)``)."""
        self.check_knowledge_base(expected_sha256, meta.codec_sha256)
        if not isinstance(x_hat, Tensor) or not x_hat.is_complex() or x_hat.dim() != 2:
            raise ValueError(f"x_hat must be [batch, num_symbols] complex64, got {x_hat!r:.60}")
        if x_hat.shape[1] != meta.num_symbols:
            raise ValueError(
                f"x_hat must have {meta.num_symbols} symbols per image, got {x_hat.shape[1]}"
            )
        validate_snr_db(snr_db)
        snr = torch.as_tensor(snr_db, dtype=torch.float32).flatten()
        nv = 10.0 ** (-snr / 10.0) if noise_var is None else noise_var
        z, _ = lmmse_input(x_hat.to(torch.complex64), nv)
        hf, wf = math.ceil(meta.height / 4), math.ceil(meta.width / 4)
        c = self.model.cfg.num_complex_channels
        with torch.no_grad():
            y = self.model.decoder(symbols_to_features(z, meta.num_channels, c, hf, wf))
        return y[:, :, : meta.height, : meta.width].clamp(0, 1)

    def forward_train(self, x, snr_db, cbr, channel, generator) -> Tensor:
        """:meth:`semcodec.TrainableCodec.forward_train` (m = cbr * 48 channels per image)."""
        cfg = self.model.cfg
        m = torch.round(torch.as_tensor(cbr) / cfg.cbr_per_channel).long()
        feat = self.model.encoder(x)
        z, _, _ = masked_transmit(feat, m, snr_db, channel, generator, cfg.num_complex_channels)
        return self.model.decoder(z)

    def untrained(self, architecture: str | None = None) -> DeepJSCC:
        return untrained(architecture)

    def save(self, path: str | os.PathLike, card: dict) -> str:
        self.sha256 = save_checkpoint(
            path, self.model, {"name": self.name, **card}, codec=CODEC_NAME
        )
        return self.sha256

    def load_compatible(self, init) -> None:
        """Copy ``init``'s weights; ValueError naming both when the architectures differ."""
        other = getattr(getattr(init, "model", None), "cfg", None)
        if other != self.model.cfg:
            raise ValueError(
                f"init codec {getattr(init, 'name', '?')} "
                f"({getattr(other, 'name', type(init).__name__)}) "
                f"does not fit {self.model.cfg.name}"
            )
        self.model.load_state_dict(init.model.state_dict())


def untrained(architecture: str | None = None) -> DeepJSCC:
    """A fresh Deep JSCC of ``architecture`` (None: the first of :data:`DEEPJSCC_ARCHITECTURES`)."""
    name = architecture or next(iter(DEEPJSCC_ARCHITECTURES))
    model = DeepJSCCModel(DEEPJSCC_ARCHITECTURES[name])
    sha = weights_sha256(model.state_dict(), model.cfg)
    return DeepJSCC(model, {"name": name, "sha256": sha})


@CODECS.register("deepjscc")
def make_deep_jscc(checkpoint: str | os.PathLike | None = None) -> DeepJSCC:
    """The ``deepjscc`` factory: the checkpoint's codec, or an untrained default (None).

    Raises FileNotFoundError when missing, ValueError (one line) when corrupt or of
    another codec.
    """
    if checkpoint is None:
        return untrained()
    state, card, cfg = read_checkpoint(checkpoint, CODEC_NAME, DeepJSCCConfig)
    model = DeepJSCCModel(cfg)
    try:
        model.load_state_dict(state)
    except RuntimeError:
        raise ValueError(
            f"checkpoint {checkpoint} does not match its architecture {cfg.name}"
        ) from None
    return DeepJSCC(model, card, Path(checkpoint))
