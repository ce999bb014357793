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

The decoder is trained by distillation: on short camera sequences around the training
views (keyframes, then a frame 1..K-1 steps later) its target is the full-resolution
volume rendering of the same field. The features are the field's rendered colour and
opacity; a learned feature field (extra channels trained with the decoder) is not
implemented.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from renderer.cameras import Intrinsics
from renderer.dataset import Dataset
from renderer.model import RadianceField, render_views
from renderer.reprojection import reproject, rotate_pose_about, splat_depth, surface_points

FEATURES = 4  # rgb + opacity


@dataclass(frozen=True)
class LightweightConfig:
    """How the lightweight renderer renders and trains."""

    downsample: int = 4
    """Low-resolution factor per axis (volume rendering at height/downsample), >= 1."""
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
    progress: bool = True
    """Progress bar on stderr."""

    def __post_init__(self):
        for name in ("downsample", "hidden_channels", "num_sequences", "batch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("buffer_frames", "keyframe_every"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not self.low_res_step_factor >= 1:
            raise ValueError(f"low_res_step_factor must be >= 1, got {self.low_res_step_factor}")
        for name in ("train_seconds", "sequence_step_deg", "lr", "depth_tolerance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")

    def as_dict(self) -> dict:
        return asdict(self)


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


class LightweightRenderer(nn.Module):
    """A trained field plus the U-Net decoder; :meth:`render_path` renders a sequence."""

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

    def low_res(self, pose: Tensor, intrinsics: Intrinsics) -> tuple[Tensor, Tensor]:
        """Low-res features upsampled to full size: ([4, H, W] rgb+opacity, [H, W] depth)."""
        h, w = intrinsics.height, intrinsics.width
        lh, lw = max(1, h // self.config.downsample), max(1, w // self.config.downsample)
        step_m = self.model.step_m * self.config.low_res_step_factor
        out = render_views(self.model, pose[None], intrinsics, lh, lw, step_m=step_m)
        feats = torch.cat([out["rgb"][0].permute(2, 0, 1), out["opacity"][0][None]], dim=0)
        return _upsample(feats, h, w), _upsample(out["depth"][0][None], h, w)[0]

    def decoder_input(
        self, feats: Tensor, depth: Tensor, pose: Tensor, buffer: list, intrinsics: Intrinsics
    ) -> Tensor:
        """[FEATURES + 4 * buffer_frames, H, W]: current features, then per buffered frame
        (most recent first) its reprojected RGB and validity (zeros when absent)."""
        if self.config.splat_depth and buffer:
            splat = splat_depth(buffer[-1][2], pose, intrinsics)
            depth = torch.where(torch.isinf(splat), depth, splat)
        parts = [feats]
        for j in range(self.config.buffer_frames):
            if j < len(buffer):
                rgb, d, _, p = buffer[-1 - j]
                warped, valid = reproject(
                    rgb, d, p, depth, pose, intrinsics, self.config.depth_tolerance
                )
                parts += [warped, valid[None]]
            else:
                parts.append(feats.new_zeros(4, *feats.shape[1:]))
        return torch.cat(parts, dim=0)

    @torch.no_grad()
    def render_path(self, poses: Tensor, intrinsics: Intrinsics) -> dict:
        """Render a camera path frame by frame, reusing the previous outputs.

        Args:
            poses: [num_views, 4, 4] camera-to-world, consecutive views close together.
        Returns:
            {"rgb": [num_views, height, width, 3] float32, "seconds_per_view": float}.
        """
        self.eval()
        k, keep = self.config.keyframe_every, max(self.config.buffer_frames, 1)
        buffer: list = []
        frames = []
        t0 = time.perf_counter()
        for i, pose in enumerate(poses):
            if k and i % k == 0:  # keyframe: the full volume rendering
                full = render_views(self.model, pose[None], intrinsics)
                rgb, depth = full["rgb"][0].permute(2, 0, 1), full["depth"][0]
                points = surface_points(depth, full["opacity"][0], pose, intrinsics)
                buffer = (buffer + [(rgb, depth, points, pose)])[-keep:]
            else:
                feats, depth = self.low_res(pose, intrinsics)
                x = self.decoder_input(feats, depth, pose, buffer, intrinsics)
                rgb = (feats[:3] + self.decoder(x[None])[0]).clamp(0.0, 1.0)
                if not k:
                    points = surface_points(depth, feats[3], pose, intrinsics)
                    buffer = (buffer + [(rgb, depth, points, pose)])[-keep:]
            frames.append(rgb.permute(1, 2, 0))
        seconds = (time.perf_counter() - t0) / max(len(frames), 1)
        return {"rgb": torch.stack(frames), "seconds_per_view": seconds}


def scene_up_and_center(model: RadianceField, poses: Tensor) -> tuple[Tensor, Tensor]:
    """World up (mean of the cameras' up axes) and the scene box centre: ([3], [3])."""
    up = F.normalize(poses[:, :3, 1].float().mean(0), dim=0)
    return up, model.aabb.mean(0)


def train_lightweight(
    model: RadianceField,
    dataset: Dataset,
    config: LightweightConfig = LightweightConfig(),
    generator: torch.Generator | None = None,
) -> tuple[LightweightRenderer, dict]:
    """Train the decoder on sequences around ``dataset``'s training poses.

    Each sequence starts at a random training pose and turns about the scene's up axis
    through the box centre by about ``sequence_step_deg`` per frame (random direction).
    The buffer holds the teacher (full-resolution) renders of the previous frames.

    Returns:
        (renderer, stats {"teacher_seconds", "train_seconds", "steps", "final_loss"}).
    """
    if generator is None:
        generator = torch.Generator().manual_seed(0)
    lw = LightweightRenderer(model, config, generator)
    intr = dataset.intrinsics
    up, center = scene_up_and_center(model, dataset.poses)
    L = config.buffer_frames
    inputs, targets = [], []
    t0 = time.perf_counter()
    k = config.keyframe_every
    for _ in range(config.num_sequences):
        start = dataset.poses[int(torch.randint(0, dataset.num_views, (1,), generator=generator))]
        sign = 1.0 if torch.rand(1, generator=generator).item() < 0.5 else -1.0
        # frames at 0, k, ..., (L-1) k steps (the keyframes; with k = 0 consecutive frames),
        # then the target j steps after the last, 1 <= j < k
        gap = int(torch.randint(1, k, (1,), generator=generator)) if k > 1 else 1
        offsets = [j * max(k, 1) for j in range(L)] + [max(k, 1) * (L - 1) + gap if L else 0]
        poses, angle, done = [], 0.0, 0
        for off in offsets:
            while done < off:
                angle += (
                    sign
                    * config.sequence_step_deg
                    * (0.5 + torch.rand(1, generator=generator).item())
                )
                done += 1
            poses.append(rotate_pose_about(start, center, up, math.radians(angle)))
        poses = torch.stack(poses)
        full = render_views(model, poses, intr)
        teacher = full["rgb"].permute(0, 3, 1, 2)  # [L+1, 3, H, W]
        buffer = []
        for j in range(L):
            if k:
                d, opacity = full["depth"][j], full["opacity"][j]
            else:
                f, d = lw.low_res(poses[j], intr)
                opacity = f[3]
            buffer.append((teacher[j], d, surface_points(d, opacity, poses[j], intr), poses[j]))
        feats, depth = lw.low_res(poses[L], intr)
        with torch.no_grad():
            inputs.append(lw.decoder_input(feats, depth, poses[L], buffer, intr))
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
