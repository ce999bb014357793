"""Full-resolution rays of the field itself where the feature renderer's low-resolution pass
is unsure: :func:`edge_mask` picks the pixels, :func:`field_colours` renders them.

The feature renderer decodes a view from a pass at a fraction of its resolution. Away from
edges that is close to the full render; on a silhouette or a thin part (a pixel the pass
sees partly transparent) and across a sharp change of colour, the decoder has to guess what
the coarse pass could not see. Those pixels are few, so they are rendered again as the
full render renders them: one ray each at the field's own marching step, its density and
colour, ended once opaque (:func:`~renderer.march.march_until_opaque`).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

from renderer.cameras import Intrinsics
from renderer.march import march_until_opaque
from renderer.model import RadianceField
from renderer.volume import packed_sum


def edge_mask(
    opacity: Tensor, rgb: Tensor, downsample: int, partial: float, contrast: float
) -> Tensor:
    """The pixels to render again: [num_views, height, width] bool.

    Args:
        opacity: [num_views, h, w] the low-resolution pass's opacity; pixel (i, j) covers
            full-resolution pixels [s i, s i + s) x [s j, s j + s), s = ``downsample``.
        rgb: [num_views, height, width, 3] the decoded view.
        partial: a low-resolution pixel whose opacity is in (partial, 1 - partial) flags
            its whole block, in (0, 0.5); 0 flags none.
        contrast: a pixel whose 3 x 3 neighbourhood (itself included) spans more than this
            in some colour channel is flagged, > 0; at least 1 flags none.
    """
    height, width = rgb.shape[1:3]
    flagged = torch.zeros(rgb.shape[:3], dtype=torch.bool)
    if partial > 0:
        unsure = (opacity > partial) & (opacity < 1.0 - partial)
        n, h, w = unsure.shape
        s = downsample
        block = unsure[:, :, None, :, None].expand(n, h, s, w, s).reshape(n, h * s, w * s)
        flagged |= block[:, :height, :width]
    if contrast < 1:
        flagged |= (_span(rgb.permute(0, 3, 1, 2).contiguous()) > contrast).any(1)
    return flagged


def _span(x: Tensor) -> Tensor:
    """Largest minus smallest value over each pixel's 3 x 3 neighbourhood of ``x`` [n, c, h,
    w], per channel: shifted maxima and minima of the edge-replicated image, rows then
    columns (a fraction of the time of ``F.max_pool2d`` on these sizes)."""
    p = F.pad(x, (1, 1, 1, 1), mode="replicate")
    h, w = x.shape[2:]
    a, b, c = (p[..., j : j + w] for j in range(3))
    hi, lo = torch.maximum(torch.maximum(a, b), c), torch.minimum(torch.minimum(a, b), c)
    hi = torch.maximum(torch.maximum(hi[..., :h, :], hi[..., 1 : h + 1, :]), hi[..., 2:, :])
    lo = torch.minimum(torch.minimum(lo[..., :h, :], lo[..., 1 : h + 1, :]), lo[..., 2:, :])
    return hi - lo


def masked_rays(poses: Tensor, intrinsics: Intrinsics, mask: Tensor) -> tuple[Tensor, Tensor]:
    """The rays of :func:`~renderer.cameras.camera_rays` at the pixels of ``mask``
    [num_views, height, width] only, in its order: (origins, unit directions), [num_masked,
    3] each."""
    view, v, u = mask.nonzero(as_tuple=True)
    k = intrinsics
    u, v = u.float(), v.float()
    cam = torch.stack([(u + 0.5 - k.cx) / k.fx, -(v + 0.5 - k.cy) / k.fy, -torch.ones_like(u)], -1)
    rot = poses[:, :3, :3].float().index_select(0, view)  # [num_masked, 3, 3]
    dirs = F.normalize(torch.bmm(rot, cam[:, :, None])[:, :, 0], dim=-1)
    return poses[:, :3, 3].float().index_select(0, view), dirs


@torch.no_grad()
def field_colours(
    model: RadianceField,
    origins: Tensor,
    directions: Tensor,
    min_transmittance: float = 1e-4,
    weight_threshold: float = 1e-5,
) -> Tensor:
    """The field's colour [num_rays, 3] along rays [num_rays, 3] (unit directions) at its
    own marching step, as :func:`~renderer.model.render_views` renders it to within about
    ``min_transmittance`` plus the weights dropped below ``weight_threshold``."""
    run = march_until_opaque(
        origins,
        directions,
        model.aabb,
        model.step_m,
        model.occupancy,
        model.field.density,
        min_transmittance,
        weight_threshold,
    )
    n = origins.shape[0]
    if run.rays.numel():
        _, rgb = model.field(run.positions, directions.index_select(0, run.rays))
        colour = packed_sum(run.weights[:, None] * rgb, run.rays, n)
    else:
        colour = origins.new_zeros(n, 3)
    return (colour + (1.0 - run.opacity)[:, None] * model.background).clamp(0, 1)
