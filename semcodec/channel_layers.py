"""Channels inside training: masked features -> phy channel -> receiver features.

Each training channel is a name in :data:`TRAIN_CHANNELS`:
* ``awgn``: phy's AWGN.
* ``rayleigh``: block Rayleigh fading with perfect CSI, MMSE-equalised; the decoder is told
  the post-equalisation SNR ``|h|^2 * snr``.
* ``rayleigh_nocsi``: block Rayleigh fading, no CSI: the decoder sees ``y = h x + n`` and the
  nominal SNR.
* ``ofdm_rayleigh_ls`` / ``ofdm_tdl_ls``: ``phy.OFDMLink`` on the default ``phy.ResourceGrid``
  (pilots, LS estimate + linear interpolation, MMSE) over block Rayleigh fading or 3GPP
  TDL-A (100 ns); the decoder is told the SNR the link's effective noise variance implies.
"""

from __future__ import annotations

import torch
from torch import Tensor

from phy import make_channel, noise_var_to_snr_db
from semcodec.model import side_info

TRAIN_CHANNELS: dict[str, tuple[str, str]] = {
    "awgn": ("awgn", "none"),
    "rayleigh": ("rayleigh", "perfect"),
    "rayleigh_nocsi": ("rayleigh", "none"),
    "ofdm_rayleigh_ls": ("rayleigh", "ofdm"),
    "ofdm_tdl_ls": ("tdl", "ofdm"),
}
_LINKS: dict[str, torch.nn.Module] = {}


def _ofdm_link(name: str):
    """The OFDM link of a training channel (built once)."""
    if name not in _LINKS:
        import phy

        kwargs = {"model": "A", "delay_spread_s": 100e-9} if name == "tdl" else {}
        _LINKS[name] = phy.OFDMLink(phy.ResourceGrid(), make_channel(name, **kwargs), csi="ls")
    return _LINKS[name]


def channel_mask(m: Tensor, num_complex_channels: int) -> Tensor:
    """[batch, 2*C, 1, 1] float32: 1 for the real/imag planes of the first m[i] channels."""
    k = torch.arange(num_complex_channels).repeat_interleave(2)  # [2*C]
    return (k[None, :] < m[:, None]).float()[:, :, None, None]


def masked_transmit(
    feat: Tensor,
    m: Tensor,
    snr_db: Tensor,
    channel: str,
    generator: torch.Generator | None,
    num_complex_channels: int,
) -> tuple[Tensor, Tensor]:
    """Keep the first m[i] complex channels of image i, normalise its power to 1, send, receive.

    Equivalent to ``power_normalize(features_to_symbols(feat, m))`` per image followed by the
    channel, but with a different m per image in one batch (dropped planes are zero and stay zero).

    Args:
        feat: [batch, 2*C, h, w] float32 encoder output.
        m: [batch] int64 kept complex channels.
        snr_db: [batch] float32 Es/N0 per complex symbol.
    Returns:
        (received features [batch, 2*C, h, w] float32 with dropped planes zero,
         side information [batch, 2] for the decoder's AF modules).
    """
    try:
        name, csi = TRAIN_CHANNELS[channel]
    except KeyError:
        raise KeyError(
            f"unknown training channel {channel!r}; known: {sorted(TRAIN_CHANNELS)}"
        ) from None
    b, c2, h, w = feat.shape
    mask = channel_mask(m.to(torch.long), num_complex_channels)
    kept = feat * mask
    count = (m.float() * h * w).reshape(b, 1, 1, 1)  # complex symbols per image
    power = (kept**2).sum(dim=(1, 2, 3), keepdim=True) / count  # mean |x|^2 per complex symbol
    kept = kept * torch.rsqrt(power + 1e-12)
    pairs = kept.reshape(b, c2 // 2, 2, h, w).permute(0, 1, 3, 4, 2).contiguous()  # [b, C, h, w, 2]
    x = torch.view_as_complex(pairs).reshape(b, -1)  # [batch, C*h*w] complex64
    if csi == "ofdm":
        lo = _ofdm_link(name)(x, snr_db, generator=generator)
        nv = lo.noise_var.reshape(b, -1).mean(dim=1).clamp(1e-6, 1e3)
        snr_rx = noise_var_to_snr_db(nv).clamp(-30.0, 60.0)
        z = torch.view_as_real(lo.x_hat.reshape(b, c2 // 2, h, w)).permute(0, 1, 4, 2, 3)
        return z.reshape(b, c2, h, w) * mask, side_info(snr_rx, m, num_complex_channels, b)
    out = make_channel(name)(x, snr_db, generator=generator)
    snr_rx = snr_db
    if out.h is not None and csi == "perfect":
        y = out.equalized("mmse")
        gain = (out.h.abs() ** 2).reshape(b, -1)[:, 0]
        snr_rx = noise_var_to_snr_db(out.noise_var / gain.clamp_min(1e-6)).clamp(-30.0, 60.0)
    else:
        y = out.y
    z = torch.view_as_real(y.reshape(b, c2 // 2, h, w)).permute(0, 1, 4, 2, 3).reshape(b, c2, h, w)
    return z * mask, side_info(snr_rx, m, num_complex_channels, b)
