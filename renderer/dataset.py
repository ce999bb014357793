"""Multi-view datasets in nerfstudio's / Blender's ``transforms.json`` convention.

Accepted layouts of a dataset folder ``root``:

* ``transforms_{split}.json`` (Blender: ``transforms_train.json``, ``transforms_test.json``...);
* ``transforms.json`` whose frames carry a ``"split"`` field, or with top-level
  ``"{split}_filenames"`` lists (nerfstudio); without either, every 8th frame (0, 8, ...)
  is the ``test``/``val`` split and the rest ``train``; ``split="all"`` takes every frame.

Fields read: intrinsics ``fl_x, fl_y, cx, cy, w, h`` (``fl_y`` defaults to ``fl_x``, ``cx, cy``
to the image centre) or Blender's ``camera_angle_x`` (and optional ``camera_angle_y``);
``frames[].file_path`` (relative to the json file, extension optional: .png, .jpg, .jpeg
are tried), ``frames[].transform_matrix`` (camera-to-world, OpenGL axes), optional
``frames[].mask_path`` (white = object, black = ignore); optional top-level ``aabb``
``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` (metres) and ``background`` ``[r, g, b]`` in [0, 1].
RGBA images are composited on the background; their alpha is the mask when no
``mask_path`` is given.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import Tensor

from common import IMAGE_SUFFIXES, read_image, write_text
from renderer.cameras import Intrinsics, pose_problem

SPLITS = ("train", "val", "test", "all")
HOLDOUT_EVERY = 8


@dataclass(frozen=True)
class Dataset:
    """Views of one scene at one resolution."""

    images: Tensor
    """[num_views, height, width, 3] float32 in [0, 1], composited on ``background``."""
    poses: Tensor
    """[num_views, 4, 4] float32 camera-to-world (OpenGL: x right, y up, looking along -z)."""
    intrinsics: Intrinsics
    """Shared pinhole intrinsics at this resolution."""
    background: tuple[float, float, float]
    """Background colour (RGB in [0, 1]) the images are composited on."""
    aabb: Tensor
    """[2, 3] float32 scene bounds (min corner, max corner), metres."""
    masks: Tensor | None = None
    """[num_views, height, width] float32 in [0, 1] (1 = object), or None."""
    names: tuple[str, ...] = ()
    """The frames' ``file_path`` entries."""
    composited: bool = False
    """The images already show only the object on ``background`` (the masks are their
    RGBA alpha): object-only training uses them as they are."""

    @property
    def num_views(self) -> int:
        return int(self.images.shape[0])

    @property
    def height(self) -> int:
        return int(self.images.shape[1])

    @property
    def width(self) -> int:
        return int(self.images.shape[2])

    def subset(self, indices) -> Dataset:
        """The views at ``indices`` (a list, range or int64 tensor)."""
        idx = torch.as_tensor(list(indices), dtype=torch.long)
        return replace(
            self,
            images=self.images[idx],
            poses=self.poses[idx],
            masks=None if self.masks is None else self.masks[idx],
            names=tuple(self.names[i] for i in idx.tolist()) if self.names else (),
        )


def _find_transforms(root: Path, split: str) -> tuple[Path, str | None]:
    """The json to read and the split to filter by inside it (None: the file is the split)."""
    per_split = root / f"transforms_{split}.json"
    if split != "all" and per_split.is_file():
        return per_split, None
    single = root / "transforms.json"
    if single.is_file():
        return single, split
    if split == "all":
        raise FileNotFoundError(f"{single}: not found (split='all' needs transforms.json)")
    raise FileNotFoundError(f"{root}: neither transforms_{split}.json nor transforms.json found")


def _select_frames(meta: dict, frames: list, split: str | None, path: Path) -> list:
    if split is None or split == "all":
        return frames
    if any("split" in f for f in frames):
        return [f for f in frames if f.get("split") == split]
    key = f"{split}_filenames"
    if key in meta:
        wanted = {str(Path(p)) for p in meta[key]}
        return [f for f in frames if str(Path(f.get("file_path", ""))) in wanted]
    holdout = split in ("test", "val")
    return [f for i, f in enumerate(frames) if (i % HOLDOUT_EVERY == 0) == holdout]


MAX_CAMERA_DISTANCE = 1e6
"""Farthest camera position from the origin that the scene bounds stay finite for."""


def _resolve_image(base: Path, file_path: str, json_path: Path, index: int, field: str) -> Path:
    p = base / file_path
    if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file():
        return p
    for s in IMAGE_SUFFIXES:
        for q in (p.with_name(p.name + s), p.with_suffix(s)):
            if q.is_file():
                return q
    raise FileNotFoundError(f"{json_path}: frames[{index}].{field}: image {p} not found")


def _resize(img: np.ndarray, height: int, width: int) -> np.ndarray:
    if img.shape[0] == height and img.shape[1] == width:
        return img
    out = cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA)
    return out if out.ndim == img.ndim else out[..., None]


def _number(meta: dict, key: str, path: Path, default=None) -> float:
    """``meta[key]`` as a finite float; ValueError naming the file and field otherwise."""
    value = meta.get(key, default)
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{path}: field {key!r} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise ValueError(f"{path}: field {key!r} must be finite, got {value!r}")
    return out


def _focal(meta: dict, key: str, side: float, path: Path) -> float:
    """The focal length from a field of view ``meta[key]`` in radians, in (0, pi)."""
    angle = _number(meta, key, path)
    if not 0.0 < angle < math.pi:
        raise ValueError(
            f"{path}: field {key!r} must be a field of view in (0, pi) radians, got {angle!r}"
        )
    return 0.5 * side / math.tan(0.5 * angle)


def _intrinsics(meta: dict, width: int, height: int, path: Path) -> Intrinsics:
    w = _number(meta, "w", path, width)
    h = _number(meta, "h", path, height)
    if "fl_x" in meta:
        fx = _number(meta, "fl_x", path)
        fy = _number(meta, "fl_y", path, fx)
    elif "camera_angle_x" in meta:
        fx = _focal(meta, "camera_angle_x", w, path)
        fy = _focal(meta, "camera_angle_y", h, path) if "camera_angle_y" in meta else fx
    else:
        raise ValueError(
            f"{path}: no intrinsics: needs 'fl_x' (with fl_y, cx, cy, w, h) or 'camera_angle_x'"
        )
    if not (math.isfinite(fx) and math.isfinite(fy) and fx > 0 and fy > 0):
        raise ValueError(
            f"{path}: focal length fl_x/fl_y/camera_angle_x gives {fx}, {fy}; must be finite and > "
            "0"
        )
    cx = _number(meta, "cx", path, w / 2.0)
    cy = _number(meta, "cy", path, h / 2.0)
    if (int(round(w)), int(round(h))) != (width, height):
        raise ValueError(
            f"{path}: fields w, h = {int(w)}x{int(h)} differ from the images' {width}x{height}"
        )
    return Intrinsics(fx, fy, cx, cy, height, width)


def default_aabb(poses: Tensor, intrinsics: Intrinsics) -> Tensor:
    """Bounds fitted from inward-looking cameras.

    The centre is the point closest (least squares) to every camera's optical axis; the
    half-size is the mean camera distance to it times tan(half horizontal field of view),
    the half-width in view at that distance. Cameras that do not converge (e.g. parallel)
    fall back to the camera centroid with the cameras' spread as half-size.

    Args:
        poses: [num_views, 4, 4].
    Returns:
        [2, 3] float32.
    """
    p = poses.double()
    centres = p[:, :3, 3]
    axes = -p[:, :3, 2]
    axes = axes / axes.norm(dim=-1, keepdim=True)
    proj = torch.eye(3, dtype=torch.float64) - axes[:, :, None] * axes[:, None, :]  # [n, 3, 3]
    a = proj.sum(0)
    b = (proj @ centres[:, :, None]).sum(0)[:, 0]
    if torch.linalg.matrix_rank(a).item() == 3:
        centre = torch.linalg.solve(a, b)
        dist = (centres - centre).norm(dim=-1).mean().item()
        half = dist * (0.5 * intrinsics.width / intrinsics.fx)
        in_front = ((centre - centres) * axes).sum(-1).mean().item() > 0
    else:
        in_front = False
    if not in_front:
        centre = centres.mean(0)
        half = max((centres - centre).norm(dim=-1).max().item(), 1.0)
    return torch.stack([centre - half, centre + half]).float()


def _aabb(meta: dict, path: Path) -> Tensor | None:
    if "aabb" not in meta:
        return None
    try:
        a = torch.tensor(meta["aabb"], dtype=torch.float32)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{path}: field 'aabb' must be [[xmin,ymin,zmin],[xmax,ymax,zmax]]") from e
    if a.shape != (2, 3) or not torch.isfinite(a).all() or not (a[1] > a[0]).all():
        raise ValueError(
            f"{path}: field 'aabb' must be [[xmin,ymin,zmin],[xmax,ymax,zmax]] finite with max > "
            f"min, got {meta['aabb']}"
        )
    return a


def load_dataset(
    root,
    split: str = "train",
    resolution: int | None = 100,
    background: tuple[float, float, float] | None = None,
    aabb=None,
) -> Dataset:
    """Load one split of a ``transforms.json`` dataset, downscaled with area interpolation.

    Args:
        root: dataset folder.
        split: "train", "val", "test" or "all".
        resolution: output width in pixels (height keeps the aspect ratio); None = as stored.
        background: RGB in [0, 1] for RGBA compositing; default: the file's ``background``
            field, else white (Blender's convention).
        aabb: [2, 3] scene bounds overriding the file's ``aabb``; default: the file's, else
            :func:`default_aabb` of the poses.
    Returns:
        :class:`Dataset`.
    Raises:
        FileNotFoundError / ValueError naming the file and field at fault.
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    if resolution is not None and resolution < 1:
        raise ValueError(f"resolution must be >= 1 pixel or None, got {resolution}")
    path, meta, frames = _read_transforms(Path(root), split)
    if background is None:
        background = tuple(float(c) for c in meta.get("background", (1.0, 1.0, 1.0)))
    if len(background) != 3 or not all(0.0 <= c <= 1.0 for c in background):
        raise ValueError(f"background must be 3 values in [0, 1], got {background}")
    bg = np.asarray(background, dtype=np.float32)

    images, masks, poses, names, alpha_masks = [], [], [], [], []
    stored_size = None
    out_h = out_w = None
    for i, f in enumerate(frames):
        pose = _frame_pose(f, i, path)
        img_path = _resolve_image(path.parent, f["file_path"], path, i, "file_path")
        img = read_image(img_path, channels=None)  # RGBA when the file has alpha
        size = img.shape[:2]
        if stored_size is None:
            stored_size = size
            out_h, out_w = _output_size(size, resolution)
        elif size != stored_size:
            raise ValueError(
                f"{path}: frames[{i}].file_path {img_path.name} is {size[1]}x{size[0]}, "
                f"other images are {stored_size[1]}x{stored_size[0]}"
            )
        img, mask = _frame_image(img, f, i, path, bg, (out_h, out_w))
        images.append(np.clip(img, 0.0, 1.0))
        alpha_masks.append(mask is not None and "mask_path" not in f)
        masks.append(mask)
        poses.append(pose)
        names.append(str(f["file_path"]))

    if any(m is None for m in masks) and not all(m is None for m in masks):
        masks = [np.ones((out_h, out_w), np.float32) if m is None else m for m in masks]
    intr = _intrinsics(meta, stored_size[1], stored_size[0], path).resized(out_h, out_w)
    poses_t = torch.from_numpy(np.stack(poses)).float()
    return Dataset(
        images=torch.from_numpy(np.stack(images)).float(),
        poses=poses_t,
        intrinsics=intr,
        background=tuple(float(c) for c in background),
        aabb=_scene_bounds(aabb, meta, path, poses_t, intr),
        masks=None if masks[0] is None else torch.from_numpy(np.stack(masks)).float(),
        names=tuple(names),
        composited=all(alpha_masks),
    )


def _read_transforms(root: Path, split: str) -> tuple[Path, dict, list]:
    """The transforms file of ``split`` under ``root``: (its path, its JSON object, the
    split's frames, at least one)."""
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: dataset folder not found")
    path, split_filter = _find_transforms(root, split)
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from e
    if not isinstance(meta, dict):
        raise ValueError(
            f"{path}: must hold a JSON object with 'frames', got a {type(meta).__name__}"
        )
    frames = meta.get("frames")
    if not isinstance(frames, list) or not frames:
        raise ValueError(f"{path}: field 'frames' must be a non-empty list")
    frames = _select_frames(meta, frames, split_filter, path)
    if not frames:
        raise ValueError(f"{path}: no frames in split {split!r}")
    return path, meta, frames


def _frame_pose(frame: dict, i: int, path: Path) -> np.ndarray:
    """Frame ``i``'s camera-to-world matrix, checked: [4, 4] float64 (a 3 x 4 one gets its
    last row), a rotation, the camera within :data:`MAX_CAMERA_DISTANCE` of the origin."""
    for field in ("file_path", "transform_matrix"):
        if field not in frame:
            raise ValueError(f"{path}: frames[{i}] has no field '{field}'")
    try:
        pose = np.asarray(frame["transform_matrix"], dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{path}: frames[{i}].transform_matrix is not a 4x4 matrix") from e
    problem = pose_problem(pose) if pose.ndim == 2 else f"has shape {pose.shape}"
    if problem:
        raise ValueError(f"{path}: frames[{i}].transform_matrix {problem}")
    far = float(np.abs(pose[:3, 3]).max())
    if far > MAX_CAMERA_DISTANCE:
        raise ValueError(
            f"{path}: frames[{i}].transform_matrix puts the camera {far:g} from the origin; "
            f"positions must be within {MAX_CAMERA_DISTANCE:g} (scene units)"
        )
    if pose.shape == (3, 4):
        pose = np.vstack([pose, [0.0, 0.0, 0.0, 1.0]])
    return pose


def _output_size(size: tuple[int, int], resolution: int | None) -> tuple[int, int]:
    """(height, width) of the loaded images: ``resolution`` wide with the stored aspect
    ratio, or the stored ``size`` when ``resolution`` is None."""
    if resolution is None:
        return size
    return max(1, int(round(size[0] * resolution / size[1]))), int(resolution)


def _frame_image(img: np.ndarray, frame: dict, i: int, path: Path, bg: np.ndarray, out_size):
    """Frame ``i``'s stored image [h, w, 3 or 4] -> (RGB [height, width, 3] at ``out_size``,
    its mask [height, width] or None): RGBA composited on ``bg`` with its alpha as the mask;
    a ``mask_path`` overrides that mask."""
    out_h, out_w = out_size
    stored_size = img.shape[:2]
    mask = None
    if img.shape[2] == 4:
        # composite at the stored resolution, then downsample: resizing straight RGBA
        # first averages the (often black) colour of transparent pixels into the edges
        # (lego at 100 px: its edge pixels came out darker than the images' own
        # downsampled composite)
        alpha = img[..., 3:]
        img = img[..., :3] * alpha + bg * (1.0 - alpha)
        mask = _resize(alpha, out_h, out_w)[..., 0]
    img = _resize(img, out_h, out_w)
    if "mask_path" in frame:
        mpath = _resolve_image(path.parent, frame["mask_path"], path, i, "mask_path")
        m = read_image(mpath, channels=1)
        if m.shape[:2] != stored_size:
            raise ValueError(
                f"{path}: frames[{i}].mask_path {mpath.name} is {m.shape[1]}x{m.shape[0]}, "
                f"its image is {stored_size[1]}x{stored_size[0]}"
            )
        mask = _resize(m, out_h, out_w)[..., 0]
    return img, mask


def _scene_bounds(aabb, meta: dict, path: Path, poses: Tensor, intr: Intrinsics) -> Tensor:
    """[2, 3] float32 bounds: the caller's ``aabb``, else the file's, else
    :func:`default_aabb` of the poses."""
    if aabb is None:
        aabb_t = _aabb(meta, path)
        return default_aabb(poses, intr) if aabb_t is None else aabb_t
    aabb_t = torch.as_tensor(aabb, dtype=torch.float32).reshape(2, 3)
    if not (aabb_t[1] > aabb_t[0]).all():
        raise ValueError(f"aabb must have max > min on every axis, got {aabb_t.tolist()}")
    return aabb_t


def write_transforms(
    path,
    poses: Tensor,
    intrinsics: Intrinsics,
    file_paths: list[str],
    aabb: Tensor | None = None,
    extra: dict | None = None,
) -> Path:
    """Write a nerfstudio ``transforms.json`` (intrinsics as fl_x, fl_y, cx, cy, w, h).

    Args:
        poses: [num_views, 4, 4] camera-to-world.
        file_paths: one relative image path per view.
    """
    if len(file_paths) != poses.shape[0]:
        raise ValueError(f"file_paths has {len(file_paths)} entries for {poses.shape[0]} poses")
    meta = dict(intrinsics.as_dict())
    if aabb is not None:
        meta["aabb"] = torch.as_tensor(aabb).tolist()
    meta.update(extra or {})
    meta["frames"] = [
        {"file_path": fp, "transform_matrix": poses[i].double().tolist()}
        for i, fp in enumerate(file_paths)
    ]
    path = Path(path)
    return write_text(path, json.dumps(meta, indent=2))
