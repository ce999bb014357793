"""LPIPS (Zhang et al. 2018, v0.1, AlexNet backbone) in torch, from weights converted at setup.

    d(a, b) = sum_l mean_{h,w} sum_c w_l[c] (f_l(a)[c,h,w] - f_l(b)[c,h,w])^2

where f_l is the ReLU output of AlexNet's conv l (l = 1..5), divided at each pixel by its
L2 norm over channels (+1e-10), and w_l the learned linear (1x1 conv) weights. Images in
[0, 1] are mapped to [-1, 1], then (x - shift) / scale with shift (-0.030, -0.088, -0.188),
scale (0.458, 0.448, 0.450). 0 for equal images; about 0.1 is a visible, 0.5 a severe change.
Weights: :func:`renderer.lpips_weights.lpips_weights_path`, loaded once per path.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from renderer.lpips_weights import ENV_VAR, MAKE_TARGET, lpips_weights_path

SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)
# (features index, stride, padding, max-pool after): torchvision's alexnet().features.
_CONVS = ((0, 4, 2, True), (3, 1, 2, True), (6, 1, 1, False), (8, 1, 1, False), (10, 1, 1, False))
LPIPS_MIN_SIDE_PX = 31  # the second max-pool needs a 3x3 input
_CHUNK = 16  # images per forward pass (bounds memory on large images)


@functools.lru_cache(maxsize=4)
def _load(path: str) -> dict[str, Tensor]:
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(
            f"LPIPS weights not found at {p}: run `{MAKE_TARGET}` (part of `make setup`) "
            f"or point {ENV_VAR} at the file"
        )
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    try:
        tensors = load_file(str(p))
    except (SafetensorError, OSError, ValueError) as e:
        first = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise ValueError(
            f"LPIPS weights {p} (from {ENV_VAR} or the default path) are not a readable "
            f"safetensors file ({first}): run `{MAKE_TARGET}` again or point {ENV_VAR} at the file"
        ) from None
    return {k: v.float().contiguous() for k, v in tensors.items()}


def lpips_weights(path: str | Path | None = None) -> dict[str, Tensor]:
    """The converted weights (keys in :mod:`renderer.lpips_weights`), read once per path.

    Raises FileNotFoundError (one line naming the path and the make target) when absent.
    """
    return _load(str(Path(path) if path is not None else lpips_weights_path()))


def alexnet_features(x: Tensor, weights: dict[str, Tensor]) -> list[Tensor]:
    """ReLU outputs of AlexNet's five convs.

    Args:
        x: [batch, 3, height, width] float32, already shifted and scaled.
    Returns:
        five [batch, channels, height_l, width_l] tensors, channels 64, 192, 384, 256, 256.
    """
    feats = []
    for idx, stride, pad, pool in _CONVS:
        x = F.relu(
            F.conv2d(
                x, weights[f"features.{idx}.weight"], weights[f"features.{idx}.bias"], stride, pad
            )
        )
        feats.append(x)
        if pool:
            x = F.max_pool2d(x, kernel_size=3, stride=2)
    return feats


def _unit(f: Tensor, eps: float = 1e-10) -> Tensor:
    return f / (torch.sqrt(torch.sum(f * f, dim=1, keepdim=True)) + eps)


def _lpips_nchw(a: Tensor, b: Tensor, weights: dict[str, Tensor]) -> Tensor:
    """[batch, 3, height, width] in [0, 1] twice -> [batch] distances."""
    shift = torch.tensor(SHIFT, dtype=a.dtype, device=a.device).view(1, 3, 1, 1)
    scale = torch.tensor(SCALE, dtype=a.dtype, device=a.device).view(1, 3, 1, 1)
    x = (torch.cat([a, b]) * 2.0 - 1.0 - shift) / scale  # [2 * batch, 3, height, width]
    n = a.shape[0]
    total = a.new_zeros(n)
    for k, f in enumerate(alexnet_features(x, weights)):
        f = _unit(f)
        d = (f[:n] - f[n:]) ** 2  # [batch, channels, height_l, width_l]
        total = total + F.conv2d(d, weights[f"lin{k}.weight"]).mean(dim=(1, 2, 3))
    return total


def lpips(a, b, weights_path: str | Path | None = None):
    """LPIPS (AlexNet, v0.1) per image; lower is more alike, 0 for equal images.

    Args:
        a, b: images in [0, 1], same shape: numpy [height, width, 3] or [num_views, height,
            width, 3] (channel-last, as :func:`psnr`), or torch [batch, 3, height, width]
            (channel-first, the project convention). height, width >= 31.
        weights_path: the converted weights (default :func:`lpips_weights_path`).
    Returns:
        float for one numpy image; numpy [num_views] float64 for a numpy stack; torch
        [batch] float32 for torch input (differentiable when an input requires grad).
    Raises:
        ValueError on shapes; FileNotFoundError when the weights are missing.
    """
    is_torch = isinstance(a, Tensor)
    if is_torch != isinstance(b, Tensor):
        raise TypeError("lpips: pass two torch tensors or two numpy arrays, not one of each")
    if tuple(a.shape) != tuple(b.shape):
        raise ValueError(f"lpips: shapes differ: {tuple(a.shape)} and {tuple(b.shape)}")
    if is_torch:
        if a.ndim != 4 or a.shape[1] != 3:
            raise ValueError(
                f"lpips: torch input must be [batch, 3, height, width], got {tuple(a.shape)}"
            )
        ta, tb = a.float(), b.float()
    else:
        a, b = np.asarray(a), np.asarray(b)
        if a.ndim not in (3, 4) or a.shape[-1] != 3:
            raise ValueError(
                "lpips: numpy input must be [height, width, 3] or [num_views, height, width, 3], "
                f"got {a.shape}"
            )
        ta = torch.from_numpy(np.ascontiguousarray(a, np.float32)).reshape(-1, *a.shape[-3:])
        tb = torch.from_numpy(np.ascontiguousarray(b, np.float32)).reshape(-1, *b.shape[-3:])
        ta, tb = ta.permute(0, 3, 1, 2), tb.permute(0, 3, 1, 2)  # [batch, 3, height, width]
    if min(ta.shape[-2:]) < LPIPS_MIN_SIDE_PX:
        raise ValueError(
            f"lpips: images must be at least {LPIPS_MIN_SIDE_PX}x{LPIPS_MIN_SIDE_PX} px, "
            f"got {ta.shape[-1]}x{ta.shape[-2]}"
        )
    w = lpips_weights(weights_path)
    if ta.shape[0] == 0:
        return ta.new_zeros(0) if is_torch else np.zeros(0)
    if w["features.0.weight"].device != ta.device:
        w = {k: v.to(ta.device) for k, v in w.items()}
    grad = torch.is_grad_enabled() and (ta.requires_grad or tb.requires_grad)
    with torch.set_grad_enabled(grad):
        d = torch.cat(
            [
                _lpips_nchw(ta[i : i + _CHUNK], tb[i : i + _CHUNK], w)
                for i in range(0, ta.shape[0], _CHUNK)
            ]
        )
    if is_torch:
        return d
    d = d.detach().double().numpy()
    return float(d[0]) if a.ndim == 3 else d
