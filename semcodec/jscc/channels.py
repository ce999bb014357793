"""Channels inside training: masked features -> phy link -> what the decoder sees.

Each training channel is a name in :data:`TRAIN_CHANNELS` -> (phy channel, receiver):
* ``awgn``: phy's AWGN.
* ``rayleigh`` / ``rayleigh_fast``: block (one h per image) or fast (one h per symbol)
  Rayleigh fading, receiver with perfect CSI.
* ``rayleigh_nocsi``: block Rayleigh fading, no CSI: the decoder sees ``y = h x + n``.
* ``ofdm_rayleigh_ls`` / ``ofdm_tdl_ls``: ``phy.OFDMLink`` on the default ``phy.ResourceGrid``
  (pilots, LS estimate + linear interpolation) over block Rayleigh fading or 3GPP TDL-A
  (100 ns).

Every receiver equalises to *unbiased* estimates with their per-symbol effective noise
variance (zero-forcing for one tap, the unbiased LMMSE), and :func:`semcodec.jscc.model.lmmse_input`
turns them into what the decoder sees: the LMMSE estimate and the reliability
``1 / (1 + noise_var)`` of each symbol. A comma-separated list of names trains on a mixture
(one channel drawn per step).
"""

from __future__ import annotations

import torch
from torch import Tensor

from common import Registry
from phy import channel_link, channel_record
from semcodec.jscc.model import lmmse_input, side_info

TRAIN_CHANNELS = Registry[tuple[str, str]](
    "training channel",
    {
        "awgn": ("awgn", "none"),
        "rayleigh": ("rayleigh", "perfect"),
        "rayleigh_fast": ("rayleigh_fast", "perfect"),
        "rayleigh_nocsi": ("rayleigh", "none"),
        "ofdm_rayleigh_ls": ("rayleigh", "ofdm"),
        "ofdm_tdl_ls": ("tdl", "ofdm"),
    },
)
_LINKS: dict[tuple[str, str], torch.nn.Module] = {}


def parse_train_channels(spec: str) -> list[str]:
    """``"awgn,rayleigh_fast"`` -> names; KeyError naming the known ones for an unknown name."""
    names = [n.strip() for n in str(spec).split(",")]
    for n in names:
        if n not in TRAIN_CHANNELS:
            raise KeyError(f"unknown training channel {n!r}; known: {sorted(TRAIN_CHANNELS)}")
    return names


def _link(channel: str) -> torch.nn.Module:
    """The phy link (channel + unbiased one-tap receiver) of a training channel, built once."""
    name, csi = TRAIN_CHANNELS[channel]
    if (name, csi) not in _LINKS:
        if csi == "ofdm":
            kwargs = {"model": "A", "delay_spread_s": 100e-9} if name == "tdl" else {}
            link = channel_link(name, ofdm=True, csi="ls", **kwargs)
        else:
            link = channel_link(name, ofdm=False, csi=csi)
        _LINKS[(name, csi)] = link
    return _LINKS[(name, csi)]


def train_channel_records(spec: str) -> dict[str, dict]:
    """What a model card records of each channel of the mixture ``spec``: ``phy``'s record
    of its link (``phy.channel_record``; TDL: profile, delay spread and the pinned TR 38.901
    ``spec_version``)."""
    return {name: channel_record(_link(name)) for name in parse_train_channels(spec)}


def channel_mask(m: Tensor, num_complex_channels: int) -> Tensor:
    """[batch, 2*C, 1, 1] float32: 1 for the real/imag planes of the first m[i] channels."""
    k = torch.arange(num_complex_channels, device=m.device).repeat_interleave(2)  # [2*C]
    return (k[None, :] < m[:, None]).float()[:, :, None, None]


def masked_transmit(
    feat: Tensor,
    m: Tensor,
    snr_db: Tensor,
    channel: str,
    generator: torch.Generator | None,
    num_complex_channels: int,
) -> tuple[Tensor, Tensor, Tensor]:
    """Keep the first m[i] complex channels of image i, normalise its power to 1, send, receive.

    Equivalent to ``power_normalize(features_to_symbols(feat, m))`` per image followed by the
    link, but with a different m per image in one batch (dropped planes are zero and stay zero).

    Args:
        feat: [batch, 2*C, h, w] float32 encoder output.
        m: [batch] int64 kept complex channels.
        snr_db: [batch] float32 Es/N0 per complex symbol.
    Returns:
        (LMMSE features [batch, 2*C, h, w] float32 with dropped planes zero,
         side information [batch, 2] for the AF modules (nominal SNR, rate),
         reliability [batch, C, h, w] float32 in [0, 1], zero on dropped channels).
    """
    if channel not in TRAIN_CHANNELS:
        raise KeyError(f"unknown training channel {channel!r}; known: {sorted(TRAIN_CHANNELS)}")
    b, c2, h, w = feat.shape
    mask = channel_mask(m.to(torch.long), num_complex_channels)
    kept = feat * mask
    count = (m.float() * h * w).reshape(b, 1, 1, 1)  # complex symbols per image
    power = (kept**2).sum(dim=(1, 2, 3), keepdim=True) / count  # mean |x|^2 per complex symbol
    kept = kept * torch.rsqrt(power + 1e-12)
    pairs = kept.reshape(b, c2 // 2, 2, h, w).permute(0, 1, 3, 4, 2).contiguous()  # [b, C, h, w, 2]
    x = torch.view_as_complex(pairs).reshape(b, -1)  # [batch, C*h*w] complex64
    out = _link(channel)(x, snr_db, generator=generator)
    z, rel = lmmse_input(out.x_hat, out.noise_var)
    z = torch.view_as_real(z.reshape(b, c2 // 2, h, w)).permute(0, 1, 4, 2, 3).reshape(b, c2, h, w)
    rel = rel.reshape(b, c2 // 2, h, w) * mask[:, ::2]
    return z * mask, side_info(snr_db, m, num_complex_channels, b), rel


def train_channel(
    symbols: Tensor, snr_db, channel: str, generator: torch.Generator | None = None
) -> tuple[Tensor, Tensor]:
    """A channel of the training mixture applied to a codec's symbols: what its ``decode``
    receives at inference (the public route for any ``TrainableCodec.forward_train``).

    Differentiable in ``symbols``. Every receiver but ``rayleigh_nocsi``'s returns
    *unbiased* estimates ``x + e`` and the effective variance of ``e`` per symbol (the
    contract's convention); ``rayleigh_nocsi`` returns what a receiver without CSI sees,
    ``h x + n``, with the noise's variance.

    Args:
        symbols: [batch, num_symbols] complex64, mean ``|x|^2 = 1`` per image (the codec's
            encoder output after power normalisation).
        snr_db: float or [batch] Es/N0 per complex symbol, dB.
        channel: a name of :data:`TRAIN_CHANNELS`.
        generator: the noise and fading draws.
    Returns:
        (x_hat [batch, num_symbols] complex64, noise_var [batch, num_symbols] float32).
    """
    if channel not in TRAIN_CHANNELS:
        raise KeyError(f"unknown training channel {channel!r}; known: {sorted(TRAIN_CHANNELS)}")
    if not isinstance(symbols, Tensor) or not symbols.is_complex() or symbols.dim() != 2:
        raise ValueError(
            "symbols must be [batch, num_symbols] complex64, got "
            f"{tuple(getattr(symbols, 'shape', ()))} {getattr(symbols, 'dtype', type(symbols))}"
        )
    b = symbols.shape[0]
    snr = torch.as_tensor(snr_db, dtype=torch.float32, device=symbols.device).flatten()
    if snr.numel() not in (1, b):
        raise ValueError(f"snr_db must be a float or have {b} (batch) values, got {snr.numel()}")
    out = _link(channel)(symbols.to(torch.complex64), snr.expand(b), generator=generator)
    nv = torch.as_tensor(out.noise_var, dtype=torch.float32, device=out.x_hat.device)
    nv = nv[:, None] if nv.dim() == 1 else nv
    return out.x_hat.to(torch.complex64), torch.broadcast_to(nv, out.x_hat.shape).contiguous()
