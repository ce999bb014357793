"""The one registry of built-in scenes."""

from __future__ import annotations

from common import Registry
from osnerf.scenes.city import build_munich
from osnerf.scenes.compact import build_firefighter, build_firefighter_shadow, build_tiny
from osnerf.scenes.spec import SceneInfo

SCENES = Registry[SceneInfo]("scene")


def register(info: SceneInfo) -> SceneInfo:
    """Add a scene to :data:`SCENES` under its name (names are unique)."""
    return SCENES.register(info.name, info)


def get_scene(name: str) -> SceneInfo:
    """The registry entry of ``name``; KeyError listing the known scenes otherwise."""
    return SCENES[name]


DEFAULT_SCENE = "firefighter"

register(
    SceneInfo(
        name="firefighter",
        description=(
            "fire hydrant beside a small brick building, a tree, paved plot (Mitsuba primitives)"
        ),
        objects=("hydrant", "building", "tree"),
        default_demand=("hydrant",),
        build=build_firefighter,
        elevations_deg=(20.0, 40.0),
        fov_deg=40.0,
        min_radius_m=2.5,
    )
)
register(
    SceneInfo(
        name="firefighter_shadow",
        description="the firefighter plot with a tall shed that blocks the radio paths of the "
        "drones on the hydrant's -y side (their cameras still see it)",
        objects=("hydrant", "building", "tree", "shed"),
        default_demand=("hydrant",),
        build=build_firefighter_shadow,
        elevations_deg=(20.0, 40.0),
        fov_deg=40.0,
        min_radius_m=2.5,
    )
)
register(
    SceneInfo(
        name="tiny",
        description="a crate and a post on a small disk, a cable hidden in the crate (for tests)",
        objects=("crate", "post", "cable"),
        default_demand=("post",),
        build=build_tiny,
        elevations_deg=(25.0, 45.0),
        fov_deg=45.0,
        min_radius_m=1.6,
    )
)
register(
    SceneInfo(
        name="munich",
        description=(
            "the Frauenkirche and its neighbours from sionna-rt's Munich, textured via planar "
            "UVs; channels ray-traced in the full city"
        ),
        objects=("frauenkirche", "neighbours"),
        default_demand=("frauenkirche",),
        build=build_munich,
        elevations_deg=(25.0, 45.0),
        fov_deg=40.0,
        min_radius_m=150.0,
    )
)
