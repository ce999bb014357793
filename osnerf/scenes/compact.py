"""The default scene: a fire hydrant beside a small brick building on a paved plot.

The paper's firefighter example, built from primitives (boxes, cylinders, cones, a disk)
so that it renders in tens of milliseconds per view on a CPU. A tree adds clutter. The
same meshes, with ITU materials, are the radio scene, standing on a flat terrain of
:data:`TERRAIN_RADIUS_M` that only the radio sees: the ground stations stand outside the
plot, and a drone's ground reflection toward them lands beyond it.
"""

from __future__ import annotations

import dataclasses

from osnerf.scenes import textures as tx
from osnerf.scenes.geometry import annulus, box, cylinder, disk, merge
from osnerf.scenes.spec import Part, SceneGeometry

HYDRANT_XY_M = (0.8, 0.0)
PLOT_RADIUS_M = 2.6
TINY_PLOT_RADIUS_M = 1.6
TERRAIN_RADIUS_M = 200.0
"""How far the radio world's ground reaches from the plot's centre."""


def build_firefighter() -> SceneGeometry:
    """Hydrant (about 0.9 m tall), building (1.0 x 1.6 x 1.5 m) 0.8 m from it, tree, 5.2 m plot."""
    return SceneGeometry(
        name="firefighter",
        parts=tuple(_hydrant() + _building() + _tree() + _ground()),
        ground_station_m=(8.0, -6.0, 1.5),
        sky_radiance=(1.0, 1.0, 1.0),
        scorable_objects=("hydrant", "building", "tree"),
        terrain=annulus((0.0, 0.0, 0.0), PLOT_RADIUS_M, TERRAIN_RADIUS_M),
    )


def _hydrant() -> list[Part]:
    """Base, body, bonnet and nozzles at :data:`HYDRANT_XY_M`, about 0.9 m tall."""
    hx, hy = HYDRANT_XY_M
    paint = tx.painted_metal()
    return [
        Part(
            "hydrant",
            "hydrant_base",
            cylinder((hx, hy, 0.0), 0.26, 0.08, tile_m=0.5),
            paint,
            "metal",
        ),
        Part(
            "hydrant",
            "hydrant_body",
            cylinder((hx, hy, 0.08), 0.18, 0.62, tile_m=0.7),
            paint,
            "metal",
        ),
        Part(
            "hydrant",
            "hydrant_bonnet",
            merge(
                [
                    cylinder((hx, hy, 0.7), 0.22, 0.06, tile_m=0.5),
                    cylinder((hx, hy, 0.76), 0.18, 0.14, tile_m=0.5, radius_top_m=0.06),
                ]
            ),
            tx.painted_metal(seed=11, color=(0.9, 0.75, 0.1), band=(0.75, 0.08, 0.06)),
            "metal",
        ),
        Part(
            "hydrant",
            "hydrant_nozzles",
            merge(
                [
                    cylinder((hx, hy - 0.3, 0.45), 0.07, 0.6, axis="y", tile_m=0.3),
                    cylinder((hx + 0.14, hy, 0.4), 0.09, 0.14, axis="x", tile_m=0.3),
                ]
            ),
            tx.painted_metal(seed=12, color=(0.85, 0.85, 0.85), band=(0.2, 0.2, 0.2)),
            "metal",
        ),
    ]


def _building() -> list[Part]:
    """Brick walls (1.0 x 1.6 x 1.5 m), a two-step roof and a door facing the hydrant."""
    return [
        Part(
            "building",
            "building_walls",
            box((-0.5, 0.0, 0.0), (1.0, 1.6, 1.5), tile_m=0.6),
            tx.bricks(),
            "brick",
        ),
        Part(
            "building",
            "building_roof",
            merge(
                [
                    box((-0.5, 0.0, 1.5), (1.2, 1.8, 0.08), tile_m=0.5),
                    box((-0.5, 0.0, 1.58), (0.7, 1.2, 0.25), tile_m=0.5),
                ]
            ),
            tx.roof_tiles(),
            "concrete",
        ),
        Part(
            "building",
            "building_door",
            box((0.011, 0.4, 0.0), (0.02, 0.5, 0.9), tile_m=1.0),
            tx.windows(wall=(0.35, 0.22, 0.12)),
            "wood",
        ),
    ]


def _tree() -> list[Part]:
    """A trunk and a conical crown: clutter beside the building."""
    return [
        Part(
            "tree",
            "tree_trunk",
            cylinder((0.6, 1.5, 0.0), 0.08, 0.7, tile_m=0.4),
            tx.bark(),
            "wood",
        ),
        Part(
            "tree",
            "tree_crown",
            cylinder((0.6, 1.5, 0.55), 0.45, 1.0, radius_top_m=0.0, tile_m=0.6),
            tx.foliage(),
            "wood",
        ),
    ]


def _ground() -> list[Part]:
    """The paved plot, a disk 5.2 m across."""
    return [
        Part(
            "ground",
            "ground_paving",
            disk((0.0, 0.0, 0.0), PLOT_RADIUS_M, tile_m=1.0),
            tx.pavement(),
            "concrete",
        ),
    ]


SHED_CENTER_M = (4.5, -4.3, 0.0)
SHED_SIZE_M = (0.6, 0.9, 3.0)


def build_firefighter_shadow() -> SceneGeometry:
    """The firefighter plot with a tall shed (``shed``) between the ground station and the
    drone positions on the hydrant's -y side: their radio paths are blocked while their
    cameras still see the hydrant (the shed stands behind them, outside the ring)."""
    base = build_firefighter()
    shed = Part(
        "shed",
        "shed_walls",
        box(SHED_CENTER_M, SHED_SIZE_M, tile_m=0.6),
        tx.windows(seed=13, wall=(0.55, 0.55, 0.6)),
        "concrete",
    )
    return dataclasses.replace(base, name="firefighter_shadow", parts=(*base.parts, shed))


def build_tiny() -> SceneGeometry:
    """A minimal test scene: a box (the "crate"), a cylinder (the "post") and a "cable" hidden
    inside the crate (an object no camera can see)."""
    return SceneGeometry(
        name="tiny",
        parts=(
            Part(
                "crate",
                "crate",
                box((-0.5, 0.0, 0.0), (0.6, 0.6, 0.6), tile_m=0.3),
                tx.bricks(),
                "brick",
            ),
            Part(
                "post",
                "post",
                cylinder((0.5, 0.0, 0.0), 0.15, 0.8, tile_m=0.4),
                tx.painted_metal(),
                "metal",
            ),
            Part(
                "cable",
                "cable",
                box((-0.5, 0.0, 0.1), (0.2, 0.2, 0.2), tile_m=0.3),
                tx.bark(),
                "metal",
            ),
            Part(
                "ground",
                "ground",
                disk((0.0, 0.0, 0.0), TINY_PLOT_RADIUS_M, tile_m=0.8),
                tx.pavement(),
                "concrete",
            ),
        ),
        ground_station_m=(5.0, 3.0, 1.5),
        scorable_objects=("crate", "post", "cable"),
        terrain=annulus((0.0, 0.0, 0.0), TINY_PLOT_RADIUS_M, TERRAIN_RADIUS_M),
    )
