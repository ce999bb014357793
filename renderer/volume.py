"""Volume rendering, exactly as the paper's eq. 4, as pure functions.

For one ray with samples i = 0..n-1 at distances ``t_i`` (metres along a unit direction),
densities ``sigma_i`` (1/m) and segment lengths ``delta_i`` (m)::

    alpha_i = 1 - exp(-sigma_i * delta_i)
    T_i     = exp(-sum_{j<i} sigma_j * delta_j)       (transmittance, T_0 = 1)
    w_i     = T_i * alpha_i                            (weights, sum_i w_i = 1 - T_n <= 1)
    C       = sum_i w_i * c_i + (1 - sum_i w_i) * background
    D       = sum_i w_i * t_i                          (expected depth, not normalised)

Worked numbers (used in tests): sigma = [1, 2], delta = [0.5, 0.5] gives
alpha = [1 - e^-0.5, 1 - e^-1] = [0.3935, 0.6321], T = [1, e^-0.5] = [1, 0.6065],
w = [0.3935, 0.3834], opacity 0.7769.

Two layouts: *dense* ``[num_rays, num_samples_per_ray]`` tensors, and *packed* 1-D tensors
``[num_packed]`` with a ``ray_indices`` tensor saying which ray each sample belongs to
(samples of one ray contiguous and in order of increasing t). The packed form keeps only
the samples that survive empty-space skipping.
"""

from __future__ import annotations

import torch
from torch import Tensor


def alpha_from_density(sigma: Tensor, deltas: Tensor) -> Tensor:
    """alpha = 1 - exp(-sigma * delta).

    Args:
        sigma: [..., num_samples_per_ray] float32 density (1/m), >= 0.
        deltas: same shape, segment lengths (m).
    Returns:
        same shape, in [0, 1].
    """
    return -torch.expm1(-sigma * deltas)


def transmittance(sigma: Tensor, deltas: Tensor) -> Tensor:
    """T_i = exp(-sum_{j<i} sigma_j delta_j) (exclusive cumulative sum; T_0 = 1).

    Args:
        sigma, deltas: [num_rays, num_samples_per_ray] float32.
    Returns:
        [num_rays, num_samples_per_ray] float32 in (0, 1], non-increasing along the ray.
    """
    sd = sigma * deltas
    inclusive = torch.cumsum(sd.double(), dim=-1)
    return torch.exp(-(inclusive - sd.double())).to(sigma.dtype)


def render_weights(sigma: Tensor, deltas: Tensor) -> Tensor:
    """w_i = T_i * alpha_i.

    Args:
        sigma, deltas: [num_rays, num_samples_per_ray] float32.
    Returns:
        [num_rays, num_samples_per_ray] float32; each row sums to 1 - T_n <= 1.
    """
    return transmittance(sigma, deltas) * alpha_from_density(sigma, deltas)


def composite(weights: Tensor, values: Tensor, background: Tensor | None = None) -> Tensor:
    """C = sum_i w_i c_i + (1 - sum_i w_i) * background.

    Args:
        weights: [num_rays, num_samples_per_ray] float32.
        values: [num_rays, num_samples_per_ray, channels] float32.
        background: [channels] float32, or None for black.
    Returns:
        [num_rays, channels] float32.
    """
    out = (weights[..., None] * values).sum(dim=-2)
    if background is not None:
        out = out + (1.0 - weights.sum(dim=-1, keepdim=True)) * background
    return out


def expected_depth(weights: Tensor, t: Tensor) -> Tensor:
    """D = sum_i w_i t_i (not divided by the opacity; see :func:`normalized_depth`).

    Args:
        weights, t: [num_rays, num_samples_per_ray] float32.
    Returns:
        [num_rays] float32 (m).
    """
    return (weights * t).sum(dim=-1)


def normalized_depth(depth: Tensor, opacity: Tensor, far_m: float, eps: float = 1e-6) -> Tensor:
    """Depth of the visible surface: D / opacity, and ``far_m`` where nothing was hit.

    Args:
        depth, opacity: [num_rays] float32.
    Returns:
        [num_rays] float32 (m).
    """
    return torch.where(opacity > eps, depth / opacity.clamp_min(eps), torch.full_like(depth, far_m))


def packed_weights(
    sigma: Tensor, deltas: Tensor, ray_indices: Tensor, num_rays: int
) -> tuple[Tensor, Tensor]:
    """Eq. 4 weights and transmittance for packed samples.

    The exclusive cumulative sum of sigma*delta runs in float64 over all samples; the
    value at each ray's first sample is subtracted so every ray starts at T = 1.

    Args:
        sigma, deltas: [num_packed] float32.
        ray_indices: [num_packed] int64, non-decreasing (samples of a ray contiguous).
        num_rays: number of rays (rays may have no samples).
    Returns:
        (weights [num_packed] float32, transmittance [num_packed] float32).
    """
    if sigma.numel() == 0:
        return sigma.clone(), sigma.clone()
    sd = (sigma * deltas).double()
    exclusive = torch.cumsum(sd, dim=0) - sd
    positions = torch.arange(sigma.numel(), device=sigma.device)
    first = torch.full((num_rays,), sigma.numel(), dtype=torch.long, device=sigma.device)
    first = first.scatter_reduce(0, ray_indices, positions, reduce="amin")
    base = exclusive.index_select(0, first.index_select(0, ray_indices))
    trans = torch.exp(-(exclusive - base)).to(sigma.dtype)
    weights = trans * alpha_from_density(sigma, deltas)
    return weights, trans


def packed_sum(values: Tensor, ray_indices: Tensor, num_rays: int) -> Tensor:
    """Sum packed per-sample values into their rays.

    Args:
        values: [num_packed] or [num_packed, channels] float32.
        ray_indices: [num_packed] int64.
    Returns:
        [num_rays] or [num_rays, channels] float32.
    """
    out = values.new_zeros((num_rays, *values.shape[1:]))
    return out.index_add(0, ray_indices, values)


def packed_render(
    sigma: Tensor,
    rgb: Tensor,
    t: Tensor,
    deltas: Tensor,
    ray_indices: Tensor,
    num_rays: int,
    background: Tensor,
) -> dict[str, Tensor]:
    """Composite packed samples into per-ray colour, opacity and expected depth.

    Args:
        sigma, t, deltas: [num_packed] float32.
        rgb: [num_packed, channels] float32.
        ray_indices: [num_packed] int64, non-decreasing.
        background: [channels] float32.
    Returns:
        dict with ``rgb`` [num_rays, channels] (composited on the background), ``opacity``
        [num_rays] (= sum of weights), ``depth`` [num_rays] (= sum w t, not normalised),
        ``weights`` [num_packed].
    """
    weights, _ = packed_weights(sigma, deltas, ray_indices, num_rays)
    opacity = packed_sum(weights, ray_indices, num_rays)
    colour = packed_sum(weights[:, None] * rgb, ray_indices, num_rays)
    colour = colour + (1.0 - opacity)[:, None] * background
    depth = packed_sum(weights * t, ray_indices, num_rays)
    return {"rgb": colour, "opacity": opacity, "depth": depth, "weights": weights}
