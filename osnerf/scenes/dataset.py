"""Render a scene into a cached nerfstudio ``transforms.json`` folder, and load it back.

Folder layout (``cache_dir/scenes/<scene>-<key>/``)::

    transforms.json          all frames, each with "split": "train" | "test"
    transforms_train.json    the same frames split Blender-style
    transforms_test.json
    images/v_000.png         RGB, 8 bit
    masks/<object>/v_000.png visible object mask (anti-aliased), 8 bit
    meshes/<part>.ply        the geometry both worlds share
    radio/scene.xml          the sionna-rt version of the same meshes (ITU materials)
    radio/terrain.ply        the ground around the plot that only the radio world has

Besides nerfstudio's fields (``fl_x, fl_y, cx, cy, w, h, camera_angle_x``, frames with
``file_path`` and ``transform_matrix``), the file carries ``aabb`` (scene bounds),
``background`` (RGB), ``ground_station_m``, and per frame ``drone_position_m``,
``object_masks``, ``visible_fraction`` and ``pixel_fraction`` per object.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from common import bound, check_bounds, read_image, write_png
from osnerf.provenance import write_json_atomic
from osnerf.scenes.cameras import Intrinsics, intrinsics_from_fov, look_at, ring_positions
from osnerf.scenes.radio import write_radio_scene
from osnerf.scenes.registry import get_scene
from osnerf.scenes.render import MitsubaRenderer, background_rgb, write_meshes
from osnerf.scenes.spec import SceneGeometry

FORMAT_VERSION = 2
"""Part of the cache key: bumped whenever what a folder holds changes (2: the radio scene's
terrain, and munich's ground station on a rooftop mast), so an older folder is rebuilt."""


RADIUS_SCALE_RANGE = (1.0, 10.0)
"""Allowed :attr:`RenderConfig.radius_scale` (``osnerf run --ring-scale``, ``osnerf radiomap
--ring-scale``)."""


@dataclass(frozen=True)
class RenderConfig:
    """How a scene is photographed.

    Attributes:
        resolution_px: image width and height in pixels (16..512).
        num_train_views: drone views a team captures (the candidates to send), 2..512.
        num_test_views: held-out views for scoring (never sent), 1..256.
        spp: Mitsuba samples per pixel for RGB (1..1024).
        mask_spp: rays per pixel for the exact masks (1..64).
        radius_scale: drone ring radius / the radius that just fits the target in view
            (:data:`RADIUS_SCALE_RANGE`).
    """

    resolution_px: int = field(default=80, metadata=bound(16, 512, "px", integer=True))
    num_train_views: int = field(default=24, metadata=bound(2, 512, integer=True))
    num_test_views: int = field(default=8, metadata=bound(1, 256, integer=True))
    spp: int = field(default=32, metadata=bound(1, 1024, integer=True))
    mask_spp: int = field(default=4, metadata=bound(1, 64, integer=True))
    radius_scale: float = field(default=1.25, metadata=bound(*RADIUS_SCALE_RANGE))

    def __post_init__(self):
        check_bounds(self)


@dataclass
class SceneViews:
    """A rendered scene in memory.

    Attributes:
        folder: the transforms.json folder.
        images: [num_views, height, width, 3] float32 in [0, 1].
        poses: [num_views, 4, 4] float64 camera-to-world (OpenGL).
        intrinsics: the shared pinhole camera.
        split: [num_views] "train" | "test".
        masks: object -> [num_views, height, width] float32 visible masks.
        visible_fraction: object -> [num_views] float (visible / silhouette area; 0 if out of view).
        pixel_fraction: object -> [num_views] float (visible area / image area).
        drone_positions_m: [num_views, 3].
        meta: the transforms.json dict.
    """

    folder: Path
    images: np.ndarray
    poses: np.ndarray
    intrinsics: Intrinsics
    split: np.ndarray
    masks: dict[str, np.ndarray]
    visible_fraction: dict[str, np.ndarray]
    pixel_fraction: dict[str, np.ndarray]
    drone_positions_m: np.ndarray
    meta: dict = field(repr=False, default_factory=dict)

    @property
    def objects(self) -> tuple[str, ...]:
        return tuple(self.meta["objects"])

    @property
    def background(self) -> np.ndarray:
        return np.asarray(self.meta["background"], np.float32)

    def indices(self, split: str) -> np.ndarray:
        return np.flatnonzero(self.split == split)


def default_cache_dir() -> Path:
    """``$OSNERF_CACHE`` or ``$XDG_CACHE_HOME/osnerf`` (``~/.cache/osnerf``)."""
    env = os.environ.get("OSNERF_CACHE")
    if env:
        return Path(env)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "osnerf"


def check_demand(scene: str, demand) -> tuple[str, ...]:
    """Validate object names against the scene; KeyError listing the valid ones."""
    info = get_scene(scene)
    names = tuple(demand)
    if not names:
        raise ValueError(
            f"demand must name at least one object of scene {scene!r}: {', '.join(info.objects)}"
        )
    for n in names:
        if n not in info.objects:
            raise KeyError(
                f"unknown object {n!r} in scene {scene!r}; known objects: {', '.join(info.objects)}"
            )
    return names


def trajectory(
    geometry: SceneGeometry,
    target: tuple[str, ...],
    fov_deg: float,
    elevations_deg,
    min_radius_m: float,
    config: RenderConfig,
):
    """Drone rings around the target objects: (train positions, test positions, centre, radius).

    The centre is the middle of the union of the targets' bounding boxes; the radius is
    the larger of ``min_radius_m`` and ``radius_scale`` times the distance at which the
    bounding sphere just fits the field of view.
    """
    b = np.stack([geometry.object_bounds_m(t) for t in target])
    lo, hi = b[:, 0].min(0), b[:, 1].max(0)
    centre = (lo + hi) / 2
    r_obj = float(np.linalg.norm(hi - lo) / 2)
    radius = max(min_radius_m, config.radius_scale * r_obj / np.tan(np.radians(fov_deg) / 2))
    train = ring_positions(centre, radius, elevations_deg, config.num_train_views)
    mid = [(a + b_) / 2 for a, b_ in zip(elevations_deg[:-1], elevations_deg[1:])] or list(
        elevations_deg
    )
    test = ring_positions(
        centre,
        radius,
        mid,
        config.num_test_views,
        azimuth_offset_deg=180.0 / config.num_test_views + 7.0,
    )
    return train, test, centre, radius


def dataset_key(scene: str, target: tuple[str, ...], config: RenderConfig) -> str:
    """Cache key: the scene, the trajectory target and the render config."""
    blob = json.dumps(
        {"scene": scene, "target": list(target), "config": asdict(config), "v": FORMAT_VERSION},
        sort_keys=True,
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:12]


def _png(path: Path, arr: np.ndarray) -> str:
    write_png(path, np.round(np.clip(arr, 0, 1) * 255).astype(np.uint8))
    return str(path)


def build_scene_dataset(
    scene: str,
    target=None,
    config: RenderConfig | None = None,
    cache_dir: Path | None = None,
    progress: bool = True,
) -> Path:
    """Render (or reuse from the cache) the drone views of ``scene`` around ``target``.

    Args:
        scene: registry name.
        target: object names the drone ring circles (default: the scene's default demand).
        config: render settings.
        cache_dir: where rendered scenes live (default :func:`default_cache_dir`).
    Returns:
        The dataset folder (holding transforms.json).
    """
    info = get_scene(scene)
    target = check_demand(scene, target or info.default_demand)
    config = config or RenderConfig()
    root = (
        Path(cache_dir or default_cache_dir())
        / "scenes"
        / f"{scene}-{dataset_key(scene, target, config)}"
    )
    if (root / "transforms.json").exists():
        return root

    t0 = time.perf_counter()
    tmp = root.with_name(root.name + f".partial-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    geometry = info.build()
    mesh_paths = write_meshes(geometry, tmp / "meshes")
    write_radio_scene(geometry, mesh_paths, tmp / "radio")
    intr = intrinsics_from_fov(info.fov_deg, config.resolution_px, config.resolution_px)
    train, test, centre, radius = trajectory(
        geometry, target, info.fov_deg, info.elevations_deg, info.min_radius_m, config
    )
    renderer = MitsubaRenderer(geometry, mesh_paths, intr, spp=config.spp)
    positions = [("train", p) for p in train] + [("test", p) for p in test]
    if progress:
        from tqdm import tqdm

        positions = tqdm(positions, desc=f"render {scene}", file=sys.stderr, leave=False)
    frames = [
        _render_frame(renderer, geometry, k, split, pos, centre, config.mask_spp, tmp)
        for k, (split, pos) in enumerate(positions)
    ]
    meta = {
        "scene": scene,
        "format_version": FORMAT_VERSION,
        "objects": list(geometry.objects),
        "scorable_objects": list(geometry.scorable_objects),
        "trajectory_target": list(target),
        "trajectory_center_m": centre.tolist(),
        "trajectory_radius_m": float(radius),
        **_camera_and_scene_fields(geometry, intr, info),
        "render_config": asdict(config),
        "render_seconds": time.perf_counter() - t0,
        "frames": frames,
    }
    _write_transforms(tmp, meta)
    if root.exists():  # another process finished first
        shutil.rmtree(tmp, ignore_errors=True)
    else:
        tmp.rename(root)
    return root


def _render_frame(renderer, geometry, k: int, split: str, pos, centre, mask_spp: int, tmp: Path):
    """Render view ``k`` from drone position ``pos`` looking at ``centre``; write its image
    and object masks under ``tmp``. Returns its ``transforms.json`` frame."""
    pose = look_at(pos, centre)
    view = renderer.render(pose, seed=k, mask_spp=mask_spp)
    name = f"v_{k:03d}"
    _png(tmp / "images" / f"{name}.png", view.rgb)
    frame = {
        "file_path": f"images/{name}.png",
        "transform_matrix": pose.tolist(),
        "split": split,
        "drone_position_m": [float(x) for x in pos],
        "object_masks": {},
        "visible_fraction": {},
        "pixel_fraction": {},
    }
    for obj in geometry.objects:
        _png(tmp / "masks" / obj / f"{name}.png", view.masks[obj])
        frame["object_masks"][obj] = f"masks/{obj}/{name}.png"
        sil = float(view.silhouettes[obj].sum())
        frame["visible_fraction"][obj] = float(view.masks[obj].sum() / sil) if sil > 0 else 0.0
        frame["pixel_fraction"][obj] = float(view.masks[obj].mean())
    return frame


def _camera_and_scene_fields(geometry: SceneGeometry, intr: Intrinsics, info) -> dict:
    """The pinhole camera (nerfstudio's fields), the bounds (``aabb`` padded by 5 % of the
    largest side), the background, the ground station and the radio scene."""
    b = geometry.bounds_m
    pad = 0.05 * (b[1] - b[0]).max()
    return {
        "camera_model": "PINHOLE",
        "fl_x": intr.fx,
        "fl_y": intr.fy,
        "cx": intr.cx,
        "cy": intr.cy,
        "w": intr.width,
        "h": intr.height,
        "camera_angle_x": float(np.radians(info.fov_deg)),
        "aabb": [(b[0] - pad).tolist(), (b[1] + pad).tolist()],
        "object_aabb": {o: geometry.object_bounds_m(o).tolist() for o in geometry.objects},
        "background": background_rgb(geometry).tolist(),
        "ground_station_m": list(geometry.ground_station_m),
        "carrier_frequency_hz": info.carrier_frequency_hz,
        "radio_scene": geometry.radio_scene or "radio/scene.xml",
    }


def _write_transforms(folder: Path, meta: dict) -> None:
    """``transforms.json`` (every frame) and ``transforms_{train,test}.json`` (Blender-style)."""
    for split in ("train", "test"):
        write_json_atomic(
            folder / f"transforms_{split}.json",
            {**meta, "frames": [f for f in meta["frames"] if f["split"] == split]},
        )
    write_json_atomic(folder / "transforms.json", meta)


def _read_gray(path: Path) -> np.ndarray:
    return read_image(path, channels=1)[..., 0]


def load_scene_views(folder: Path) -> SceneViews:
    """Load a folder written by :func:`build_scene_dataset`."""
    folder = Path(folder)
    path = folder / "transforms.json"
    if not path.exists():
        raise FileNotFoundError(f"no transforms.json in {folder}")
    meta = json.loads(path.read_text())
    frames = meta["frames"]
    images = np.stack([read_image(folder / f["file_path"]) for f in frames])
    objs = meta["objects"]
    return SceneViews(
        folder=folder,
        images=images,
        poses=np.asarray([f["transform_matrix"] for f in frames], np.float64),
        intrinsics=Intrinsics(
            meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"], height=meta["h"], width=meta["w"]
        ),
        split=np.asarray([f["split"] for f in frames]),
        masks={
            o: np.stack([_read_gray(folder / f["object_masks"][o]) for f in frames]) for o in objs
        },
        visible_fraction={o: np.asarray([f["visible_fraction"][o] for f in frames]) for o in objs},
        pixel_fraction={o: np.asarray([f["pixel_fraction"][o] for f in frames]) for o in objs},
        drone_positions_m=np.asarray([f["drone_position_m"] for f in frames], np.float64),
        meta=meta,
    )
