"""Shared input checks and noise draws for the channels (private)."""

from __future__ import annotations

import torch
from torch import Tensor

from phy.conventions import snr_db_to_noise_var, validate_snr_db

MODES = ("block", "fast")


def check_symbols(x: Tensor, name: str = "x") -> Tensor:
    """Raise ValueError naming ``name`` unless ``x`` is a complex tensor of shape [batch, ...]."""
    if not isinstance(x, Tensor):
        raise ValueError(
            f"{name} must be a complex64 torch.Tensor [batch, num_symbols], got {type(x).__name__}"
        )
    if not x.is_complex():
        raise ValueError(f"{name} must be complex64 (or complex128), got dtype {x.dtype}")
    if x.dim() < 2:
        raise ValueError(
            f"{name} must be [batch, num_symbols] (2 or more dims), got shape {tuple(x.shape)}"
        )
    return x


def check_mode(mode: str) -> str:
    if mode not in MODES:
        raise ValueError(f"mode must be one of {list(MODES)}, got {mode!r}")
    return mode


def noise_var_per_batch(snr_db, batch: int, device=None) -> Tensor:
    """[batch] float32 noise variance per complex sample from Es/N0 ``snr_db`` (float or
    [batch])."""
    validate_snr_db(snr_db)
    if isinstance(snr_db, Tensor):
        s = snr_db.detach().to(dtype=torch.float32, device=device).flatten()
        if s.numel() == 1:
            s = s.expand(batch)
        elif s.numel() != batch:
            raise ValueError(
                f"snr_db must be a float or have {batch} (batch) values, got {s.numel()}"
            )
        return snr_db_to_noise_var(s)
    return torch.full(
        (batch,), snr_db_to_noise_var(float(snr_db)), dtype=torch.float32, device=device
    )


def complex_normal(
    shape, generator: torch.Generator | None, dtype=torch.complex64, device=None
) -> Tensor:
    """CN(0, 1) samples: real and imaginary parts N(0, 1/2), drawn from ``generator``."""
    real_dtype = torch.float64 if dtype == torch.complex128 else torch.float32
    z = torch.randn((*shape, 2), generator=generator, dtype=real_dtype, device=device)
    return torch.view_as_complex(z * (0.5**0.5)).to(dtype)


def add_noise(y: Tensor, noise_var: Tensor, generator: torch.Generator | None) -> Tensor:
    """y + CN(0, noise_var) with ``noise_var`` [batch] broadcast over the other dims."""
    nv = noise_var.to(y.device).reshape(-1, *([1] * (y.dim() - 1)))
    return y + complex_normal(y.shape, generator, y.dtype, y.device) * torch.sqrt(nv).to(y.dtype)


def fading_shape(x: Tensor, mode: str) -> tuple[int, ...]:
    """One coefficient per block ([batch, 1, ...]) or per symbol (x's shape)."""
    return (x.shape[0], *([1] * (x.dim() - 1))) if mode == "block" else tuple(x.shape)
