"""The JSCC network: a Deep-JSCC-style conv encoder/decoder with GDN/IGDN and PReLU,
ADJSCC attention-feature (AF) modules that take the SNR and the rate, and channel
features ordered by importance so that keeping the first ``m`` complex channels gives
CBR ``m / (3 * downsample**2)``.

Shapes: images [batch, 3, height, width] float32 in [0, 1]; features
[batch, num_complex_channels, height/4, width/4] complex64.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from common import Registry
from semcodec.contract.checkpoint import JSCC_CODEC, read_checkpoint
from semcodec.jscc.gdn import GDN

SNR_SCALE_DB = 10.0  # snr_db / SNR_SCALE_DB is what the AF modules see


@dataclass(frozen=True)
class JSCCConfig:
    """Architecture of one JSCC model (stored in the model card).

    Attributes:
        name: registry name of this architecture.
        width: feature channels of the hidden layers.
        num_res_blocks: residual GDN units at 1/4 resolution, each followed by an AF module.
        num_complex_channels: complex symbols per 4x4 pixel block at full rate (CBR = m/48).
        af_hidden: hidden units of each AF module's MLP.
        snr_min_db, snr_max_db: SNR range the model is trained for (Es/N0 per complex symbol).
        decoder_reliability: the decoder also sees each received symbol's reliability
            ``1 / (1 + noise_var_eff)`` (knowledge-base version 2); without it (version 1) it
            sees the LMMSE estimates and one scalar SNR only.
    """

    name: str = "adjscc_s4_w96"
    width: int = 96
    num_res_blocks: int = 2
    num_complex_channels: int = 8
    af_hidden: int = 32
    snr_min_db: float = -5.0
    snr_max_db: float = 20.0
    decoder_reliability: bool = False

    def __post_init__(self):
        if not 8 <= self.width <= 512:
            raise ValueError(f"width must be in [8, 512], got {self.width}")
        if not 0 <= self.num_res_blocks <= 8:
            raise ValueError(f"num_res_blocks must be in [0, 8], got {self.num_res_blocks}")
        if not 1 <= self.num_complex_channels <= 24:
            raise ValueError(
                f"num_complex_channels must be in [1, 24], got {self.num_complex_channels}"
            )
        if not 1 <= self.af_hidden <= 512:
            raise ValueError(f"af_hidden must be in [1, 512], got {self.af_hidden}")
        if not -30.0 <= self.snr_min_db < self.snr_max_db <= 60.0:
            raise ValueError(
                f"snr_min_db < snr_max_db must lie in [-30, 60] dB, got {self.snr_min_db}, "
                f"{self.snr_max_db}"
            )

    @property
    def downsample(self) -> int:
        """Spatial downsampling factor of the encoder."""
        return 4

    @property
    def cbr_per_channel(self) -> float:
        """CBR that one kept complex channel adds: 1 / (3 * downsample**2)."""
        return 1.0 / (3 * self.downsample**2)

    @property
    def cbr_range(self) -> tuple[float, float]:
        """(smallest, largest) CBR the model serves."""
        return (self.cbr_per_channel, self.num_complex_channels * self.cbr_per_channel)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


class AFModule(nn.Module):
    """Attention-feature module (ADJSCC): channel-wise gains from pooled features + SNR + rate.

    forward(x [batch, width, h, w], side [batch, 2] = (snr_db/10, m/num_complex_channels))
    -> [batch, width, h, w].
    """

    def __init__(self, width: int, hidden: int):
        super().__init__()
        self.fc1 = nn.Linear(width + 2, hidden)
        self.fc2 = nn.Linear(hidden, width)

    def forward(self, x: Tensor, side: Tensor) -> Tensor:
        ctx = torch.cat([x.mean(dim=(2, 3)), side], dim=1)  # [batch, width + 2]
        gain = torch.sigmoid(self.fc2(F.relu(self.fc1(ctx))))  # [batch, width]
        return x * gain[:, :, None, None]


class _ResUnit(nn.Module):
    """x + PReLU(GDN(conv3x3(x))) followed by an AF module."""

    def __init__(self, width: int, hidden: int, inverse: bool):
        super().__init__()
        self.conv = nn.Conv2d(width, width, 3, padding=1)
        self.gdn = GDN(width, inverse=inverse)
        self.act = nn.PReLU(width)
        self.af = AFModule(width, hidden)

    def forward(self, x: Tensor, side: Tensor) -> Tensor:
        return self.af(x + self.act(self.gdn(self.conv(x))), side)


class Encoder(nn.Module):
    """Image [batch, 3, H, W] (H, W multiples of 4) -> real features [batch, 2*C, H/4, W/4]."""

    def __init__(self, cfg: JSCCConfig):
        super().__init__()
        w = cfg.width
        self.conv1 = nn.Conv2d(3, w, 5, stride=2, padding=2)
        self.gdn1, self.act1 = GDN(w), nn.PReLU(w)
        self.conv2 = nn.Conv2d(w, w, 5, stride=2, padding=2)
        self.gdn2, self.act2 = GDN(w), nn.PReLU(w)
        self.af = AFModule(w, cfg.af_hidden)
        self.res = nn.ModuleList(
            _ResUnit(w, cfg.af_hidden, inverse=False) for _ in range(cfg.num_res_blocks)
        )
        self.out = nn.Conv2d(w, 2 * cfg.num_complex_channels, 3, padding=1)

    def forward(self, x: Tensor, side: Tensor) -> Tensor:
        x = self.act1(self.gdn1(self.conv1(x * 2.0 - 1.0)))
        x = self.af(self.act2(self.gdn2(self.conv2(x))), side)
        for unit in self.res:
            x = unit(x, side)
        return self.out(x)


class Decoder(nn.Module):
    """LMMSE features [batch, 2*C, H/4, W/4] (+ reliability [batch, C, H/4, W/4] when
    ``cfg.decoder_reliability``) -> image [batch, 3, H, W] in [0, 1]."""

    def __init__(self, cfg: JSCCConfig):
        super().__init__()
        w = cfg.width
        c = cfg.num_complex_channels
        self.reliability = cfg.decoder_reliability
        self.inp = nn.Conv2d(3 * c if self.reliability else 2 * c, w, 3, padding=1)
        self.gdn0, self.act0 = GDN(w, inverse=True), nn.PReLU(w)
        self.af = AFModule(w, cfg.af_hidden)
        self.res = nn.ModuleList(
            _ResUnit(w, cfg.af_hidden, inverse=True) for _ in range(cfg.num_res_blocks)
        )
        self.up1 = nn.ConvTranspose2d(w, w, 5, stride=2, padding=2, output_padding=1)
        self.gdn1, self.act1 = GDN(w, inverse=True), nn.PReLU(w)
        self.up2 = nn.ConvTranspose2d(w, 3, 5, stride=2, padding=2, output_padding=1)

    def forward(self, z: Tensor, side: Tensor, reliability: Tensor | None = None) -> Tensor:
        if self.reliability:
            if reliability is None:
                raise ValueError("this decoder needs the per-symbol reliability [batch, C, h, w]")
            z = torch.cat([z, reliability], dim=1)
        x = self.af(self.act0(self.gdn0(self.inp(z))), side)
        for unit in self.res:
            x = unit(x, side)
        x = self.act1(self.gdn1(self.up1(x)))
        return torch.sigmoid(self.up2(x))


def features_to_symbols(feat: Tensor, m: int) -> Tensor:
    """Keep the first ``m`` complex channels and flatten them into symbols (no normalisation).

    Args:
        feat: [batch, 2*C, h, w] float32, channel pairs (2k, 2k+1) = (real, imag) of channel k.
        m: complex channels kept, 1 <= m <= C.
    Returns:
        [batch, m*h*w] complex64.
    """
    b, c2, h, w = feat.shape
    if not 1 <= m <= c2 // 2:
        raise ValueError(f"m (kept complex channels) must be in [1, {c2 // 2}], got {m}")
    pairs = feat[:, : 2 * m].reshape(b, m, 2, h, w).permute(0, 1, 3, 4, 2)  # [batch, m, h, w, 2]
    return torch.view_as_complex(pairs.contiguous()).reshape(b, m * h * w)


def symbols_to_features(sym: Tensor, m: int, num_complex_channels: int, h: int, w: int) -> Tensor:
    """Inverse of :func:`features_to_symbols`; dropped channels are zero.

    Args:
        sym: [batch, m*h*w] complex64.
    Returns:
        [batch, 2*num_complex_channels, h, w] float32.
    """
    b = sym.shape[0]
    if sym.shape[1] != m * h * w:
        raise ValueError(
            f"symbols must be [batch, {m * h * w}] for m={m}, h={h}, w={w}, got {tuple(sym.shape)}"
        )
    real = torch.view_as_real(sym.reshape(b, m, h, w))  # [batch, m, h, w, 2]
    real = real.permute(0, 1, 4, 2, 3).reshape(b, 2 * m, h, w)
    return F.pad(real, (0, 0, 0, 0, 0, 2 * (num_complex_channels - m)))


def lmmse_input(x_hat: Tensor, noise_var) -> tuple[Tensor, Tensor]:
    """The decoder's view of received symbols (the one equaliser convention of the codec).

    Receivers hand the codec *unbiased* estimates ``x_hat = x + e`` with the effective noise
    variance ``noise_var = E|e|^2`` of each symbol (sionna's LMMSE convention; for one tap
    this is ``y / h`` with ``noise_var / |h|^2``). Channel symbols have unit mean power, so
    the linear MMSE estimate is ``x_hat / (1 + noise_var)``; the decoder sees that (bounded
    in deep fades) and the reliability ``1 / (1 + noise_var)`` in (0, 1].

    Args:
        x_hat: [batch, num_symbols] complex64 unbiased estimates.
        noise_var: float, [batch] or [batch, num_symbols]: effective noise variance per symbol.
    Returns:
        (LMMSE estimates [batch, num_symbols] complex64, reliability [batch, num_symbols] float32).
    """
    nv = torch.as_tensor(noise_var, dtype=torch.float32)
    if nv.dim() == 1 and x_hat.dim() == 2:
        nv = nv[:, None]
    nv = torch.nan_to_num(nv, nan=1e6, posinf=1e6).clamp(0.0, 1e6)
    w = torch.broadcast_to(1.0 / (1.0 + nv), x_hat.shape).contiguous()
    z = x_hat * w
    z = torch.where(torch.isfinite(z), z, torch.zeros_like(z))
    return z.to(torch.complex64), w


def reliability_to_features(
    w: Tensor, m: int, num_complex_channels: int, h: int, wd: int
) -> Tensor:
    """Per-symbol reliability [batch, m*h*wd] -> [batch, num_complex_channels, h, wd] (dropped:
    0)."""
    b = w.shape[0]
    return F.pad(w.reshape(b, m, h, wd).float(), (0, 0, 0, 0, 0, num_complex_channels - m))


def awgn_reliability(snr_db, shape: tuple[int, int, int, int]) -> Tensor:
    """[batch, C, h, w] reliability ``1 / (1 + 10**(-snr_db/10))`` of an AWGN link (snr_db float or
    [batch])."""
    snr = torch.as_tensor(snr_db, dtype=torch.float32).flatten()
    w = 1.0 / (1.0 + 10.0 ** (-snr / 10.0))
    return torch.broadcast_to(w.reshape(-1, 1, 1, 1), shape).contiguous()


def side_info(snr_db: Tensor, m: Tensor | int, num_complex_channels: int, batch: int) -> Tensor:
    """[batch, 2] float32 = (snr_db / 10, m / num_complex_channels), what the AF modules see."""
    snr = torch.as_tensor(snr_db, dtype=torch.float32).flatten()
    snr = snr.expand(batch) if snr.numel() == 1 else snr
    mm = torch.as_tensor(m, dtype=torch.float32).flatten()
    mm = mm.expand(batch) if mm.numel() == 1 else mm
    return torch.stack([snr / SNR_SCALE_DB, mm / num_complex_channels], dim=1)


class JSCCModel(nn.Module):
    """Encoder + decoder of one architecture; the channel sits between them (see
    ``semcodec.jscc.codec``)."""

    def __init__(self, cfg: JSCCConfig):
        super().__init__()
        self.cfg = cfg
        self.encoder = Encoder(cfg)
        self.decoder = Decoder(cfg)


_RELIABILITY = {"snr_min_db": -10.0, "decoder_reliability": True}
"""The knowledge-base version 2 architectures: per-symbol reliability, trained down to -10 dB."""

JSCC_ARCHITECTURES = Registry[Callable[[], JSCCConfig]](
    "jscc architecture",
    {
        "adjscc_s4_w96_rel": partial(
            JSCCConfig, name="adjscc_s4_w96_rel", width=96, num_res_blocks=2, **_RELIABILITY
        ),
        "adjscc_s4_w96_rel_c16": partial(
            JSCCConfig,
            name="adjscc_s4_w96_rel_c16",
            width=96,
            num_res_blocks=2,
            num_complex_channels=16,
            **_RELIABILITY,
        ),
        # capacity candidates for the shipped default (docs/training.md, "On a lent
        # GPU"); no checkpoint ships for them
        "adjscc_s4_w192_rel_c16": partial(
            JSCCConfig,
            name="adjscc_s4_w192_rel_c16",
            width=192,
            num_res_blocks=2,
            num_complex_channels=16,
            **_RELIABILITY,
        ),
        "adjscc_s4_w128_r4_rel_c16": partial(
            JSCCConfig,
            name="adjscc_s4_w128_r4_rel_c16",
            width=128,
            num_res_blocks=4,
            num_complex_channels=16,
            **_RELIABILITY,
        ),
        "adjscc_s4_w96": partial(JSCCConfig, name="adjscc_s4_w96", width=96, num_res_blocks=2),
        "adjscc_s4_w64": partial(JSCCConfig, name="adjscc_s4_w64", width=64, num_res_blocks=1),
        "adjscc_s4_w128": partial(JSCCConfig, name="adjscc_s4_w128", width=128, num_res_blocks=2),
    },
)


def make_model(name: str) -> JSCCModel:
    """Build a registered architecture; unknown names raise KeyError listing the known ones."""
    cfg = JSCC_ARCHITECTURES[name]()
    return JSCCModel(cfg)


def load_checkpoint(path: str | os.PathLike) -> tuple[JSCCModel, dict]:
    """Load a JSCC checkpoint; returns (model in eval mode, card). Verifies the stored hash.

    Raises FileNotFoundError when missing and ValueError (one line) when corrupt or of
    another codec.
    """
    state, card, cfg = read_checkpoint(path, JSCC_CODEC, JSCCConfig)
    model = JSCCModel(cfg)
    try:
        model.load_state_dict(state)
    except RuntimeError:
        raise ValueError(f"checkpoint {path} does not match its architecture {cfg.name}") from None
    return model.eval(), card
