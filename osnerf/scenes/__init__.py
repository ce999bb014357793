"""Built-in scenes for both worlds: Mitsuba renders of drone views and sionna-rt channels.

Public API:
    SCENES, get_scene(name) -> SceneInfo, DEFAULT_SCENE
    RenderConfig, RADIUS_SCALE_RANGE, build_scene_dataset(scene, target, config, cache_dir) -> Path,
    load_scene_views(folder) -> SceneViews, check_demand(scene, demand)
    drone_channels(folder, meta, positions_m, ...) -> DroneChannels (via phy.raytrace)
"""

from osnerf.scenes.cameras import (
    Intrinsics,
    intrinsics_from_fov,
    look_at,
    pixel_rays,
    project,
    ring_positions,
)
from osnerf.scenes.dataset import (
    RADIUS_SCALE_RANGE,
    RenderConfig,
    SceneViews,
    build_scene_dataset,
    check_demand,
    default_cache_dir,
    load_scene_views,
)
from osnerf.scenes.radio import (
    DroneChannels,
    drone_channels,
    flight_velocities,
    write_radio_scene,
)
from osnerf.scenes.registry import DEFAULT_SCENE, SCENES, get_scene
from osnerf.scenes.spec import Part, SceneGeometry, SceneInfo

__all__ = [
    "DEFAULT_SCENE",
    "RADIUS_SCALE_RANGE",
    "SCENES",
    "DroneChannels",
    "Intrinsics",
    "intrinsics_from_fov",
    "Part",
    "RenderConfig",
    "SceneGeometry",
    "SceneInfo",
    "SceneViews",
    "build_scene_dataset",
    "check_demand",
    "default_cache_dir",
    "drone_channels",
    "flight_velocities",
    "get_scene",
    "load_scene_views",
    "look_at",
    "pixel_rays",
    "project",
    "ring_positions",
    "write_radio_scene",
]
