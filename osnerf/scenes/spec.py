"""What a built-in scene is: named objects made of textured meshes, and where the radio ends are."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from osnerf.scenes.geometry import Mesh

#: ITU radio materials sionna-rt knows (``itu-radio-material`` types) that our parts use.
RADIO_MATERIALS = ("concrete", "brick", "metal", "wood", "marble", "glass", "medium_dry_ground")

#: ITU material of a scene's terrain (:attr:`SceneGeometry.terrain`).
TERRAIN_MATERIAL = "medium_dry_ground"


@dataclass(frozen=True, eq=False)
class Part:
    """One textured mesh of an object.

    Attributes:
        object_name: the named object it belongs to ("hydrant").
        name: unique part id within the scene ("hydrant_body").
        mesh: the geometry (metres, z up).
        texture: [height, width, 3] float32 albedo in [0, 1] (repeats).
        radio_material: ITU material of the same surface for the ray tracer.
    """

    object_name: str
    name: str
    mesh: Mesh
    texture: np.ndarray
    radio_material: str = "concrete"

    def __post_init__(self):
        if self.radio_material not in RADIO_MATERIALS:
            raise ValueError(
                f"radio_material must be one of {RADIO_MATERIALS}, got {self.radio_material!r}"
            )
        t = self.texture
        if t.ndim != 3 or t.shape[2] != 3 or t.dtype != np.float32:
            raise ValueError(
                f"texture of {self.name} must be [height, width, 3] float32, got {t.shape} "
                f"{t.dtype}"
            )


@dataclass(frozen=True, eq=False)
class SceneGeometry:
    """A built scene: parts grouped into named objects, plus the radio side.

    Attributes:
        name: registry name.
        parts: every textured mesh.
        ground_station_m: (x, y, z) of the ground station's antenna, metres.
        sky_radiance: uniform environment radiance (linear RGB); the render's background.
        radio_scene: a sionna-rt scene (built-in name or file) for the radio world, or None
            to build one from ``parts`` with their ITU materials (the same meshes) and
            ``terrain``.
        scorable_objects: objects a user may demand (the ground is not one).
        terrain: flat ground around the rendered plot that only the radio world has
            (:data:`TERRAIN_MATERIAL`), or None. The cameras see the plot against the sky;
            the radio sees the ground beyond it, where a drone's ground reflection toward
            a ground station outside the plot lands.
    """

    name: str
    parts: tuple[Part, ...]
    ground_station_m: tuple[float, float, float]
    sky_radiance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    radio_scene: str | None = None
    scorable_objects: tuple[str, ...] = ()
    terrain: Mesh | None = None

    @property
    def objects(self) -> tuple[str, ...]:
        """Object names in first-appearance order."""
        return tuple(dict.fromkeys(p.object_name for p in self.parts))

    def object_bounds_m(self, name: str) -> np.ndarray:
        """[2, 3] min/max corner of object ``name``."""
        parts = [p for p in self.parts if p.object_name == name]
        if not parts:
            raise KeyError(
                f"unknown object {name!r} in scene {self.name!r}; known: {', '.join(self.objects)}"
            )
        b = np.stack([p.mesh.bounds_m for p in parts])
        return np.stack([b[:, 0].min(0), b[:, 1].max(0)])

    @property
    def bounds_m(self) -> np.ndarray:
        """[2, 3] min/max corner of the whole scene."""
        b = np.stack([p.mesh.bounds_m for p in self.parts])
        return np.stack([b[:, 0].min(0), b[:, 1].max(0)])


@dataclass(frozen=True)
class SceneInfo:
    """A registry entry: what ``osnerf scenes`` lists, and how to build the scene.

    Attributes:
        name: registry key.
        description: one line.
        objects: demandable object names (known without building the scene).
        default_demand: object names used when the user gives no ``--demand``.
        build: () -> SceneGeometry (may read sionna-rt's bundled meshes; never downloads).
        elevations_deg: drone ring elevations above the demanded object.
        fov_deg: horizontal field of view of the drone cameras.
        min_radius_m: the drone ring is never closer than this to the object's centre.
        carrier_frequency_hz: radio carrier of the drone-to-ground-station link.
    """

    name: str
    description: str
    objects: tuple[str, ...]
    default_demand: tuple[str, ...]
    build: Callable[[], SceneGeometry] = field(repr=False)
    elevations_deg: tuple[float, ...] = (20.0, 40.0)
    fov_deg: float = 40.0
    min_radius_m: float = 2.0
    carrier_frequency_hz: float = 3.5e9
