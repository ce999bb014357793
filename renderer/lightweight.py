"""The paper's lightweight renderer (§3.3), for fast rendering of camera paths.

Per frame: volume-render the field at low resolution (features: RGB and opacity, plus
depth; a coarser marching step), upsample them bilinearly, and let a small U-Net map
[upsampled current features, reprojected buffered frames and their validity] to a
residual on the upsampled colour (so an untrained decoder is plain bilinear upsampling).

Every ``keyframe_every``-th frame is a keyframe, volume-rendered at full resolution (its
cost is included in the time per view); the buffer holds the last ``buffer_frames``
keyframes. Their surface points, projected into the current view with a z-buffer,
replace the blurry upsampled depth wherever they land, and each keyframe is warped into
the current view by that depth (:func:`renderer.reprojection.reproject`): full-resolution
detail for what the keyframe saw. With ``keyframe_every=0`` the buffer holds previous
outputs instead (their detail is only what the decoder made up).

With ``bidirectional`` the buffer holds the keyframes before and after the current frame
(a path is known in advance; the next keyframe is rendered when first needed, its time
counted): half the distance to the nearest keyframe, and what one side hides the other
often shows.

Two exact shortcuts around the decoder: pixels that the low-resolution pass shows empty
(its opacity, max-pooled over 3 x 3 low-resolution pixels, below ``empty_opacity``) are
the background (:func:`empty_pixels`); with ``rerender`` the remaining pixels that no
buffered keyframe explains (invalid in every reprojection, or, with two, where the two
disagree by more than ``max_disagreement``) are volume-rendered at full resolution: there
the output is the full render.

What limits it (lego at 100 px, a 27.75 dB field): even with the true depth, two full
renders one test-path step (2.45 degrees) away, warped into a view and averaged, are only
32.5 dB against that view's full render (bilinear resampling of per-pixel detail), and
keyframes 8 steps apart 29.5 dB; the field is soft (its weight spreads over ~25 samples
per ray), so depth-bounded marching saves little. Within 1 dB of the full render took a
full-resolution pass (``downsample = 1``) at a coarser step; >= 5x took the 1/4-resolution
pass with keyframes (see :data:`LIGHTWEIGHT_PRESETS`).

The decoder is trained by distillation: on short camera sequences around the training
views (keyframes, then a frame 1..K-1 steps later) its target is the full-resolution
volume rendering of the same field. The training views need no images: the cameras
stored with the field (``model.spec["camera"]``) serve when no dataset is given. The
features are the field's rendered colour and opacity; a learned feature field (extra
channels trained with the decoder) is not implemented.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from renderer.cameras import Intrinsics, camera_rays, intersect_aabb, look_at
from renderer.dataset import Dataset
from renderer.model import RadianceField, render_views
from renderer.reprojection import reproject, rotate_pose_about, splat_depth, surface_points
from renderer.volume import normalized_depth

FEATURES = 4  # rgb + opacity


@dataclass(frozen=True)
class LightweightConfig:
    """How the lightweight renderer renders and trains."""

    downsample: int = 4
    """Low-resolution factor per axis (volume rendering at height/downsample), >= 1."""
    empty_downsample: int | None = None
    """When set (> downsample): a pass this much coarser first finds the empty pixels
    (:func:`empty_pixels`), and the low-resolution pass marches only the others (with
    ``downsample = 1``: a full-resolution coarse-step pass of the object alone)."""
    low_res_step_factor: float = 2.0
    """Marching step of the low-resolution render relative to the field's own, >= 1
    (its pixels are ``downsample`` times wider, so fewer samples per ray suffice)."""
    buffer_frames: int = 1
    """L: previous frames kept and reprojected, >= 0."""
    keyframe_every: int = 16
    """K: every K-th frame of a path (the first included) is volume-rendered at full
    resolution and the buffer holds the last L such keyframes: the reprojected frames
    then carry detail the low-resolution render lacks. Its cost is in the time per view.
    0: no keyframes; the buffer holds the last L output frames. >= 0."""
    hidden_channels: int = 8
    """Width of the U-Net decoder, >= 1."""
    train_seconds: float = 60.0
    """Decoder training budget (s) after the teacher renders, > 0."""
    num_sequences: int = 96
    """Training sequences of buffer_frames + 1 views around training poses, >= 1."""
    sequence_step_deg: float = 3.0
    """Mean rotation between consecutive frames of a sequence (deg), > 0."""
    lr: float = 3e-3
    """Adam learning rate, > 0."""
    batch_size: int = 4
    """Sequences per optimiser step, >= 1."""
    splat_depth: bool = True
    """Replace the upsampled low-resolution depth by the most recent buffered frame's
    surface points projected into the current view (z-buffered, full resolution) wherever
    they land: sharp depth edges, so the reprojection lines up and its validity test
    works at silhouettes."""
    depth_tolerance: float = 0.05
    """Relative depth disagreement above which a reprojected pixel is invalid, > 0."""
    bidirectional: bool = False
    """With keyframes and buffer_frames = 2: the buffer holds the keyframes before and
    after the current frame (the path's last frame is a keyframe too)."""
    skip_empty: bool = True
    """Pixels the low-resolution pass shows empty are the background (:func:`empty_pixels`)."""
    empty_opacity: float = 0.01
    """Low-resolution opacity (max over 3 x 3 low-resolution pixels) below which a pixel is
    empty, in (0, 1)."""
    rerender: bool = False
    """Volume-render at full resolution the non-empty pixels no buffered keyframe explains."""
    max_disagreement: float | None = None
    """With rerender and two buffered frames: also re-render where both reproject but their
    colours differ by more than this (max over channels, in [0, 1]); None: never."""
    rerender_step_factor: float = 1.0
    """Marching step of the re-rendered pixels relative to the field's own, >= 1 (1: exactly
    the full render)."""
    progress: bool = True
    """Progress bar on stderr."""

    def __post_init__(self):
        for name in ("downsample", "hidden_channels", "num_sequences", "batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("buffer_frames", "keyframe_every"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("low_res_step_factor", "rerender_step_factor"):
            if not getattr(self, name) >= 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.empty_downsample is not None and not self.empty_downsample > self.downsample:
            raise ValueError(
                f"empty_downsample must be > downsample ({self.downsample}) or None, "
                f"got {self.empty_downsample}"
            )
        if not 0 < self.empty_opacity < 1:
            raise ValueError(f"empty_opacity must be in (0, 1), got {self.empty_opacity}")
        if self.max_disagreement is not None and not self.max_disagreement >= 0:
            raise ValueError(f"max_disagreement must be >= 0 or None, got {self.max_disagreement}")
        if self.bidirectional and (self.buffer_frames != 2 or self.keyframe_every < 2):
            raise ValueError(
                "bidirectional needs buffer_frames = 2 and keyframe_every >= 2, got "
                f"{self.buffer_frames} and {self.keyframe_every}"
            )
        for name in ("train_seconds", "sequence_step_deg", "lr", "depth_tolerance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")

    def as_dict(self) -> dict:
        return asdict(self)


LIGHTWEIGHT_PRESETS: dict[str, LightweightConfig] = {
    "keyframes": LightweightConfig(),
    "coarse_step": LightweightConfig(
        downsample=1, low_res_step_factor=2.5, keyframe_every=0, buffer_frames=0
    ),
}
"""Named settings. ``keyframes`` (the default, the paper's shape): 1/4-resolution pass,
a full keyframe every 16 frames reprojected, the decoder. ``coarse_step``: a
full-resolution pass at 2.5x the field's marching step, corrected by the decoder, no
keyframes. ``python -m benchmarks renderer`` on lego's first 64 test views, the field of
`osnerf train-nerf` at 120 s (28.21 dB on them), side by side in one run: keyframes 4.9x
faster per view than the full render, 4.8 dB under it against ground truth (1 thread);
coarse_step 1.8x, 0.8 dB under (2 threads). Neither meets >= 5x within 1 dB. Later, on a
field at 27.91 dB (1 thread, 60 s decoder training): downsample 2 without keyframes 4.9x,
3.1 dB under; downsample 2 with keyframes 2.9x, 2.5 dB under; a 16-channel decoder no
better than 8; marching only a depth band around the half-resolution pass's surfaces
(no decoder) 1.7x, 1.0 dB under: the band (min to max depth of 3 x 3 half-resolution
pixels, +-3 coarse steps) still held 57 % of the full render's 146k samples per view."""


class UNetDecoder(nn.Module):
    """Two-level U-Net: [batch, in_channels, H, W] -> [batch, 3, H, W] residual.

    Leaky ReLUs: with plain ReLUs an 8-channel decoder sometimes trained to nothing
    (lego test path, 3 initialisations: 22.95-23.99 dB vs the full render; leaky
    24.06-24.09)."""

    def __init__(self, in_channels: int, hidden: int = 16):
        super().__init__()
        self.enc = nn.Sequential(
            nn.Conv2d(in_channels, hidden, 3, padding=1),
            nn.LeakyReLU(0.1),
            nn.Conv2d(hidden, hidden, 3, padding=1),
            nn.LeakyReLU(0.1),
        )
        self.down = nn.Sequential(
            nn.Conv2d(hidden, 2 * hidden, 3, stride=2, padding=1),
            nn.LeakyReLU(0.1),
            nn.Conv2d(2 * hidden, 2 * hidden, 3, padding=1),
            nn.LeakyReLU(0.1),
        )
        self.dec = nn.Sequential(nn.Conv2d(3 * hidden, hidden, 3, padding=1), nn.LeakyReLU(0.1))
        self.out = nn.Conv2d(hidden, 3, 3, padding=1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)  # starts as plain bilinear upsampling

    def forward(self, x: Tensor) -> Tensor:
        e = self.enc(x)
        d = self.down(e)
        u = F.interpolate(d, size=e.shape[-2:], mode="bilinear", align_corners=False)
        return self.out(self.dec(torch.cat([u, e], dim=1)))


def _upsample(x: Tensor, height: int, width: int) -> Tensor:
    return F.interpolate(x[None], size=(height, width), mode="bilinear", align_corners=False)[0]


def empty_pixels(low_opacity: Tensor, height: int, width: int, threshold: float) -> Tensor:
    """Full-resolution pixels that a low-resolution render shows empty.

    A pixel is empty when the largest low-resolution opacity over the 3 x 3 low-resolution
    pixels around the one holding its centre is below ``threshold`` (the neighbourhood
    covers the footprint of bilinear upsampling and a surface between two low-resolution
    rays).

    Args:
        low_opacity: [low_height, low_width] float32 in [0, 1].
    Returns:
        [height, width] bool.
    """
    lh, lw = low_opacity.shape
    pooled = F.max_pool2d(low_opacity[None, None], 3, stride=1, padding=1)[0, 0]
    rows = ((torch.arange(height) + 0.5) * lh / height).long().clamp_max(lh - 1)
    cols = ((torch.arange(width) + 0.5) * lw / width).long().clamp_max(lw - 1)
    return pooled[rows][:, cols] < threshold


class LightweightRenderer(nn.Module):
    """A trained field plus the U-Net decoder; :meth:`render_path` renders a sequence."""

    name = "lightweight"

    def __init__(
        self,
        model: RadianceField,
        config: LightweightConfig = LightweightConfig(),
        generator: torch.Generator | None = None,
    ):
        super().__init__()
        self.model = model
        self.config = config
        with torch.random.fork_rng(devices=[]):  # the decoder's initial weights from generator
            if generator is not None:
                torch.manual_seed(int(torch.randint(0, 2**62, (1,), generator=generator)))
            self.decoder = UNetDecoder(FEATURES + 4 * config.buffer_frames, config.hidden_channels)

    def settings(self) -> dict:
        """The renderer's name and configuration (for result files)."""
        return {"renderer": self.name, **self.config.as_dict()}

    def low_res(self, pose: Tensor, intrinsics: Intrinsics) -> tuple[Tensor, Tensor, Tensor]:
        """The low-resolution pass: ([4, H, W] rgb + opacity and [H, W] depth, both
        upsampled bilinearly to full size, and the opacity that decides which pixels are
        empty: [H / downsample, W / downsample], or [H / empty_downsample, W /
        empty_downsample] from a coarser pass first, when set)."""
        cfg = self.config
        h, w = intrinsics.height, intrinsics.width
        lh, lw = max(1, h // cfg.downsample), max(1, w // cfg.downsample)
        step_m = self.model.step_m * cfg.low_res_step_factor
        if cfg.empty_downsample is None:
            out = render_views(self.model, pose[None], intrinsics, lh, lw, step_m=step_m)
            rgb, opacity, depth = out["rgb"][0], out["opacity"][0], out["depth"][0]
            empty_opacity = opacity
        else:
            eh, ew = max(1, h // cfg.empty_downsample), max(1, w // cfg.empty_downsample)
            coarse = render_views(self.model, pose[None], intrinsics, eh, ew, step_m=step_m)
            empty_opacity = coarse["opacity"][0]
            live = ~empty_pixels(empty_opacity, lh, lw, cfg.empty_opacity)  # [lh, lw]
            low = intrinsics.resized(lh, lw)
            o, d = camera_rays(pose[None], low)
            o, d = o.reshape(-1, 3), d.reshape(-1, 3)
            idx = live.reshape(-1).nonzero()[:, 0]
            rgb = self.model.background.repeat(lh * lw, 1)  # [lh * lw, 3]
            opacity = torch.zeros(lh * lw)
            _, t_far = intersect_aabb(o, d, self.model.aabb)
            depth = torch.full((lh * lw,), float(t_far.max().clamp_min(0.0)))
            if idx.numel():
                out = self.model.render_rays(o[idx], d[idx], step_m=step_m)
                rgb[idx] = out["rgb"].clamp(0, 1)
                opacity[idx] = out["opacity"]
                depth[idx] = normalized_depth(out["depth"], out["opacity"], float(depth[0]))
            rgb, opacity, depth = (
                rgb.reshape(lh, lw, 3),
                opacity.reshape(lh, lw),
                depth.reshape(lh, lw),
            )
        feats = torch.cat([rgb.permute(2, 0, 1), opacity[None]], dim=0)
        return _upsample(feats, h, w), _upsample(depth[None], h, w)[0], empty_opacity

    def reprojections(
        self, depth: Tensor, pose: Tensor, buffer: list, intrinsics: Intrinsics
    ) -> tuple[Tensor, list]:
        """The depth the buffered frames are warped by and their reprojections.

        ``depth`` (the upsampled low-resolution depth, [H, W]) is replaced wherever the
        buffered frames' surface points land (z-buffered over all of them, with
        ``splat_depth``). Returns (depth [H, W], [(warped rgb [3, H, W], valid [H, W])]
        per buffered frame, last first)."""
        if self.config.splat_depth and buffer:
            splat = splat_depth(torch.cat([b[2] for b in buffer]), pose, intrinsics)
            depth = torch.where(torch.isinf(splat), depth, splat)
        warps = (
            [
                reproject(rgb, d, p, depth, pose, intrinsics, self.config.depth_tolerance)
                for rgb, d, _, p in reversed(buffer[-self.config.buffer_frames :])
            ]
            if self.config.buffer_frames
            else []
        )
        return depth, warps

    def decoder_input(self, feats: Tensor, warps: list) -> Tensor:
        """[FEATURES + 4 * buffer_frames, H, W]: current features, then per buffered frame
        (last first) its reprojected RGB and validity (zeros when absent)."""
        parts = [feats]
        for j in range(self.config.buffer_frames):
            if j < len(warps):
                parts += [warps[j][0], warps[j][1][None]]
            else:
                parts.append(feats.new_zeros(4, *feats.shape[1:]))
        return torch.cat(parts, dim=0)

    def unexplained(self, warps: list) -> Tensor | None:
        """[H, W] bool: pixels no buffered frame explains (invalid in every reprojection,
        or, with ``max_disagreement``, two valid reprojections that disagree); None
        without buffered frames (then every pixel is unexplained)."""
        if not warps:
            return None
        valid = [v > 0 for _, v in warps]
        out = ~torch.stack(valid).any(0)
        if self.config.max_disagreement is not None and len(warps) >= 2:
            both = valid[0] & valid[1]
            diff = (warps[0][0] - warps[1][0]).abs().amax(0)
            out |= both & (diff > self.config.max_disagreement)
        return out

    def _keyframe(self, pose: Tensor, intrinsics: Intrinsics) -> tuple:
        full = render_views(self.model, pose[None], intrinsics)
        rgb, depth = full["rgb"][0].permute(2, 0, 1), full["depth"][0]
        points = surface_points(depth, full["opacity"][0], pose, intrinsics)
        return (rgb, depth, points, pose)

    def keyframes(self, num_views: int) -> list[int]:
        """Indices of a path's keyframes (rendered in full)."""
        k = self.config.keyframe_every
        if not k:
            return []
        keys = list(range(0, num_views, k))
        if self.config.bidirectional and num_views and keys[-1] != num_views - 1:
            keys.append(num_views - 1)
        return keys

    @torch.no_grad()
    def render_frame(self, pose: Tensor, intrinsics: Intrinsics, buffer: list) -> dict:
        """One non-keyframe from the low-resolution pass and the buffered frames.

        Returns:
            {"rgb": [3, H, W], "depth": [H, W], "opacity": [H, W] (upsampled low-res),
            "empty": [H, W] bool, "rerendered": [H, W] bool}.
        """
        cfg = self.config
        h, w = intrinsics.height, intrinsics.width
        feats, depth, low_opacity = self.low_res(pose, intrinsics)
        depth, warps = self.reprojections(depth, pose, buffer, intrinsics)
        x = self.decoder_input(feats, warps)
        rgb = (feats[:3] + self.decoder(x[None])[0]).clamp(0.0, 1.0)
        empty = torch.zeros(h, w, dtype=torch.bool)
        if cfg.skip_empty:
            empty = empty_pixels(low_opacity, h, w, cfg.empty_opacity)
            rgb = torch.where(empty, self.model.background[:, None, None], rgb)
        rerendered = torch.zeros(h, w, dtype=torch.bool)
        if cfg.rerender:
            need = self.unexplained(warps)
            rerendered = ~empty if need is None else need & ~empty
            idx = rerendered.reshape(-1).nonzero()[:, 0]
            if idx.numel():
                o, d = camera_rays(pose[None], intrinsics)
                step_m = self.model.step_m * cfg.rerender_step_factor
                out = self.model.render_rays(
                    o.reshape(-1, 3)[idx], d.reshape(-1, 3)[idx], step_m=step_m
                )
                flat = rgb.reshape(3, -1).clone()
                flat[:, idx] = out["rgb"].clamp(0, 1).t()
                rgb = flat.reshape(3, h, w)
        return {
            "rgb": rgb,
            "depth": depth,
            "opacity": feats[3],
            "empty": empty,
            "rerendered": rerendered,
        }

    @torch.no_grad()
    def render_path(self, poses: Tensor, intrinsics: Intrinsics) -> dict:
        """Render a camera path frame by frame, reusing keyframes (or previous outputs).

        Args:
            poses: [num_views, 4, 4] camera-to-world, consecutive views close together.
        Returns:
            {"rgb": [num_views, height, width, 3] float32, "seconds_per_view": float
            (keyframes included), "keyframes": [int], "empty_fraction",
            "rerendered_fraction": float (of all pixels of the non-keyframes)}.
        """
        self.eval()
        cfg = self.config
        keep = max(cfg.buffer_frames, 1)
        n = poses.shape[0]
        keys = self.keyframes(n)
        rendered: dict[int, tuple] = {}
        buffer: list = []
        frames = []
        empty, rerendered, counted = 0, 0, 0
        t0 = time.perf_counter()
        for i, pose in enumerate(poses):
            if i in keys:
                if i not in rendered:
                    rendered[i] = self._keyframe(pose, intrinsics)
                rgb = rendered[i][0]
                if not cfg.bidirectional:
                    buffer = (buffer + [rendered[i]])[-keep:]
            else:
                if cfg.bidirectional:
                    prev = max(k for k in keys if k < i)
                    nxt = min(k for k in keys if k > i)
                    if nxt not in rendered:
                        rendered[nxt] = self._keyframe(poses[nxt], intrinsics)
                    buffer = [rendered[prev], rendered[nxt]]
                out = self.render_frame(pose, intrinsics, buffer)
                rgb = out["rgb"]
                empty += int(out["empty"].sum())
                rerendered += int(out["rerendered"].sum())
                counted += out["empty"].numel()
                if not keys and cfg.buffer_frames:
                    points = surface_points(out["depth"], out["opacity"], pose, intrinsics)
                    buffer = (buffer + [(rgb, out["depth"], points, pose)])[-keep:]
            last = max((k for k in keys if k <= i), default=-1)
            for k in [k for k in rendered if k < last]:  # keyframes no later frame needs
                del rendered[k]
            frames.append(rgb.permute(1, 2, 0))
        seconds = (time.perf_counter() - t0) / max(len(frames), 1)
        return {
            "rgb": torch.stack(frames),
            "seconds_per_view": seconds,
            "keyframes": keys,
            "empty_fraction": empty / max(counted, 1),
            "rerendered_fraction": rerendered / max(counted, 1),
        }


def scene_up_and_center(model: RadianceField, poses: Tensor) -> tuple[Tensor, Tensor]:
    """World up (mean of the cameras' up axes) and the scene box centre: ([3], [3])."""
    up = F.normalize(poses[:, :3, 1].float().mean(0), dim=0)
    return up, model.aabb.mean(0)


def stored_cameras(model: RadianceField, num_views: int = 64) -> tuple[Tensor, Intrinsics]:
    """Training-like cameras from what the field stores (``model.spec["camera"]``): its
    training poses when stored, else ``num_views`` cameras at the mean training distance
    from the centre, at elevations 10-60 degrees above the horizon (golden-angle spiral).

    Returns:
        (poses [num_views, 4, 4], intrinsics).
    """
    cam = model.spec.get("camera")
    if not cam:
        raise ValueError("the field stores no cameras (spec['camera']); pass a dataset")
    k = cam["intrinsics"]
    intr = Intrinsics(k["fl_x"], k["fl_y"], k["cx"], k["cy"], int(k["h"]), int(k["w"]))
    if cam.get("poses"):
        return torch.tensor(cam["poses"], dtype=torch.float32), intr
    center, up = torch.tensor(cam["center"]), F.normalize(torch.tensor(cam["up"]), dim=0)
    seed = torch.tensor([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else torch.tensor([0.0, 1.0, 0.0])
    e1 = F.normalize(seed - (seed @ up) * up, dim=0)
    e2 = torch.linalg.cross(up, e1)
    poses = []
    for i in range(num_views):
        az = i * math.pi * (3.0 - math.sqrt(5.0))
        el = math.radians(10.0 + 50.0 * (i + 0.5) / num_views)
        eye = center + cam["radius_m"] * (
            math.cos(el) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(el) * up
        )
        poses.append(look_at(eye, center, up))
    return torch.stack(poses), intr


def train_lightweight(
    model: RadianceField,
    dataset: Dataset | None = None,
    config: LightweightConfig = LightweightConfig(),
    generator: torch.Generator | None = None,
) -> tuple[LightweightRenderer, dict]:
    """Train the decoder on sequences around ``dataset``'s training poses (None: the
    cameras the field stores, :func:`stored_cameras`; no images are needed).

    Each sequence starts at a random training pose and turns about the scene's up axis
    through the box centre by about ``sequence_step_deg`` per frame (random direction).
    The buffer holds the teacher (full-resolution) renders of the keyframes (with
    ``keyframe_every = 0``: low-resolution renders of the previous frames); with
    ``bidirectional`` the keyframes before and after the target.

    Returns:
        (renderer, stats {"teacher_seconds", "train_seconds", "steps", "final_loss"}).
    """
    if generator is None:
        generator = torch.Generator().manual_seed(0)
    lw = LightweightRenderer(model, config, generator)
    if dataset is None:
        start_poses, intr = stored_cameras(model)
    else:
        start_poses, intr = dataset.poses, dataset.intrinsics
    up, center = scene_up_and_center(model, start_poses)
    L = config.buffer_frames
    inputs, targets = [], []
    t0 = time.perf_counter()
    k = config.keyframe_every
    for _ in range(config.num_sequences):
        start = start_poses[int(torch.randint(0, start_poses.shape[0], (1,), generator=generator))]
        sign = 1.0 if torch.rand(1, generator=generator).item() < 0.5 else -1.0
        # frames at 0, k, ..., (L-1) k steps (the keyframes; with k = 0 consecutive frames),
        # then the target j steps after the last, 1 <= j < k; bidirectional: keyframes at
        # 0 and k, the target between them
        gap = int(torch.randint(1, k, (1,), generator=generator)) if k > 1 else 1
        if config.bidirectional:
            offsets = [0, k, gap]
        else:
            offsets = [j * max(k, 1) for j in range(L)] + [max(k, 1) * (L - 1) + gap if L else 0]
        angles, angle, done = {}, 0.0, 0
        for off in sorted(set(offsets)):
            while done < off:
                angle += (
                    sign
                    * config.sequence_step_deg
                    * (0.5 + torch.rand(1, generator=generator).item())
                )
                done += 1
            angles[off] = angle
        poses = torch.stack(
            [rotate_pose_about(start, center, up, math.radians(angles[o])) for o in offsets]
        )
        full = render_views(model, poses, intr)
        teacher = full["rgb"].permute(0, 3, 1, 2)  # [L+1, 3, H, W]
        buffer = []
        for j in range(L):
            if k:
                d, opacity = full["depth"][j], full["opacity"][j]
            else:
                _, d, low_opacity = lw.low_res(poses[j], intr)
                opacity = _upsample(low_opacity[None], intr.height, intr.width)[0]
            buffer.append((teacher[j], d, surface_points(d, opacity, poses[j], intr), poses[j]))
        feats, depth, _ = lw.low_res(poses[L], intr)
        with torch.no_grad():
            _, warps = lw.reprojections(depth, poses[L], buffer, intr)
            inputs.append(lw.decoder_input(feats, warps))
        targets.append(teacher[L])
    teacher_seconds = time.perf_counter() - t0
    x_all, y_all = (
        torch.stack(inputs),
        torch.stack(targets),
    )  # [num_sequences, C, H, W], [.., 3, H, W]

    opt = torch.optim.Adam(lw.decoder.parameters(), lr=config.lr)
    steps, loss_value, t1 = 0, math.nan, time.perf_counter()
    bar = None
    if config.progress:
        from tqdm import tqdm

        bar = tqdm(
            total=int(config.train_seconds), unit="s", file=sys.stderr, desc="train lightweight"
        )
    lw.train()
    while time.perf_counter() - t1 < config.train_seconds:
        idx = torch.randint(0, x_all.shape[0], (config.batch_size,), generator=generator)
        x = x_all[idx].clone()
        # drop buffered frames at random so the first frames of a path are handled too
        for j in range(L):
            drop = torch.rand(config.batch_size, generator=generator) < 0.2
            x[drop, FEATURES + 4 * j : FEATURES + 4 * (j + 1)] = 0.0
        pred = x[:, :3] + lw.decoder(x)
        loss = F.mse_loss(pred, y_all[idx])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        steps += 1
        loss_value = loss.item()
        if bar is not None:
            bar.n = min(int(time.perf_counter() - t1), int(config.train_seconds))
            bar.set_postfix(step=steps, loss=f"{loss_value:.5f}", refresh=False)
            bar.refresh()
    if bar is not None:
        bar.close()
    lw.eval()
    stats = {
        "teacher_seconds": teacher_seconds,
        "train_seconds": time.perf_counter() - t1,
        "steps": steps,
        "final_loss": loss_value,
    }
    return lw, stats
