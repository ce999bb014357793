"""One-tap equalisation (ZF, MMSE) and the post-equalisation SNR it leaves."""

from __future__ import annotations

import torch
from torch import Tensor

EQUALIZERS = ("mmse", "zf")
_TINY = 1e-12


def _per_element(v, like: Tensor) -> Tensor:
    """A float, a [batch] tensor (1-D always means per batch row) or a tensor
    broadcastable to ``like`` -> float32 broadcastable to ``like``."""
    v = torch.as_tensor(v, dtype=torch.float32, device=like.device)
    if v.dim() == 1 and like.dim() > 1:
        v = v.reshape(-1, *([1] * (like.dim() - 1)))  # [batch, 1, ...]
    return v


def equalize(y: Tensor, h_hat: Tensor, noise_var, mode: str = "mmse", estimation_error_var=0.0):
    """Equalise ``y = h x + n`` with a channel estimate ``h_hat``.

    Treats the estimation error ``(h - h_hat) x`` (unit-power x) as extra noise of variance
    ``estimation_error_var``; with perfect CSI it is 0. Let
    ``s = noise_var + estimation_error_var``:

    * ``"zf"``: ``x_hat = y / h_hat`` (unbiased); ``noise_var_eff = s / |h_hat|^2``.
    * ``"mmse"``: ``x_hat = conj(h_hat) y / (|h_hat|^2 + s)`` (biased towards 0, bounded in
      deep fades); ``noise_var_eff = s / (|h_hat|^2 + s)``, the MMSE ``E|x_hat - x|^2``.
      For soft demapping of QAM prefer ``"zf"`` (the MMSE output is scaled by
      ``|h|^2 / (|h|^2 + s)``).

    Args:
        y: [batch, ...] complex64 received symbols.
        h_hat: complex64 broadcastable to ``y``.
        noise_var: float, [batch] (1-D means per batch row), or broadcastable to ``y``:
            noise variance per complex sample.
        mode: ``"mmse"`` or ``"zf"``.
        estimation_error_var: float or broadcastable to ``y``.
    Returns:
        (x_hat [y.shape] complex64, noise_var_eff [y.shape] float32).
    """
    if mode not in EQUALIZERS:
        raise ValueError(f"equalizer must be one of {list(EQUALIZERS)}, got {mode!r}")
    s = _per_element(noise_var, y) + _per_element(estimation_error_var, y)
    g = h_hat.real**2 + h_hat.imag**2
    if mode == "zf":
        safe = torch.where(g > _TINY, h_hat, torch.full_like(h_hat, _TINY**0.5))
        x_hat = y / safe
        nv = s / g.clamp_min(_TINY)
    else:
        x_hat = y * h_hat.conj() / (g + s).to(y.dtype)
        nv = s / (g + s)
    return x_hat, torch.broadcast_to(nv, x_hat.shape).to(torch.float32)


def post_equalization_snr(h_hat: Tensor, noise_var, estimation_error_var=0.0) -> Tensor:
    """Per-symbol (per-subcarrier) SINR after one-tap equalisation, linear.

    ``|h_hat|^2 / (noise_var + estimation_error_var)``: the SNR of the unbiased ZF output,
    which is also the unbiased-MMSE SINR of a one-tap receiver.

    Args:
        h_hat: [batch, ...] complex64.
        noise_var: float, [batch] or broadcastable to ``h_hat``.
    Returns:
        float32 of h_hat's shape.
    """
    s = _per_element(noise_var, h_hat) + _per_element(estimation_error_var, h_hat)
    return ((h_hat.real**2 + h_hat.imag**2) / s).to(torch.float32)
