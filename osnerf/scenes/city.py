"""A city scene from sionna-rt's Munich: the Frauenkirche and its neighbours, textured.

The optical world takes the Frauenkirche's meshes and every building within
``NEIGHBOUR_RADIUS_M`` of it from sionna-rt's bundled ``munich`` scene (``merge_shapes=False``
keeps buildings apart), gives them planar texture coordinates (the meshes have none) and
brick / facade / metal textures, and stands them on a paved disk. The radio world is the
full built-in ``munich`` scene itself, so each drone position's channel sees the real city.
The ground station stands on a mast of :data:`MAST_M` on the roof of the building at its
place (the roof's height is traced from the scene), in the open air above the city.
"""

from __future__ import annotations

import numpy as np

import phy
from osnerf.scenes import textures as tx
from osnerf.scenes.geometry import Mesh, disk, merge, planar_uv
from osnerf.scenes.spec import Part, SceneGeometry

LANDMARK = "Frauenkirche"
NEIGHBOUR_RADIUS_M = 90.0
GROUND_RADIUS_M = 160.0
TILE_M = 6.0
GROUND_STATION_OFFSET_M = (140.0, -60.0)
"""Where the ground station stands, from the Frauenkirche's centre (x, y)."""
MAST_M = 4.0


def _mesh_of(obj) -> Mesh:
    """Vertices and faces of a sionna-rt SceneObject (its Mitsuba mesh), with planar UVs."""
    import mitsuba as mi

    params = mi.traverse(obj.mi_mesh)
    v = np.asarray(params["vertex_positions"], np.float32).reshape(-1, 3)
    f = np.asarray(params["faces"], np.int64).reshape(-1, 3).astype(np.int32)
    return Mesh(v, f, planar_uv(v, TILE_M))


def _surface_height_m(scene, x: float, y: float) -> float:
    """Height of the highest surface of a sionna-rt scene at (x, y): a ray cast straight down."""
    import mitsuba as mi

    top = 1000.0
    si = scene.mi_scene.ray_intersect(mi.Ray3f(mi.Point3f(x, y, top), mi.Vector3f(0.0, 0.0, -1.0)))
    return top - float(si.t.numpy()[0]) if bool(si.is_valid().numpy()[0]) else 0.0


def build_munich() -> SceneGeometry:
    """The Frauenkirche (object ``frauenkirche``), nearby buildings (``neighbours``), ground."""
    phy.require_llvm()  # before sionna.rt: a clear error instead of a Dr.Jit crash
    import sionna.rt as rt

    scene = rt.load_scene(rt.scene.munich, merge_shapes=False)
    objs = scene.objects
    landmark = [n for n in objs if n.startswith(LANDMARK)]
    meshes = {n: _mesh_of(objs[n]) for n in landmark}
    b = np.stack([m.bounds_m for m in meshes.values()])
    lo, hi = b[:, 0].min(0), b[:, 1].max(0)
    centre = (lo + hi) / 2
    parts = [
        Part(
            "frauenkirche",
            f"frauenkirche_{n.split('-itu_')[-1]}",
            m,
            tx.bricks() if "marble" in n else tx.roof_tiles(),
            "marble" if "marble" in n else "metal",
        )
        for n, m in meshes.items()
    ]
    walls, roofs = [], []
    for n, o in objs.items():
        if n in landmark or n == "ground":
            continue
        bb = o.mi_mesh.bbox()
        c = (np.asarray(list(bb.min)) + np.asarray(list(bb.max))) / 2
        if np.linalg.norm((c - centre)[:2]) < NEIGHBOUR_RADIUS_M:
            (walls if n.endswith("marble") else roofs).append(_mesh_of(o))
    if walls:
        parts.append(Part("neighbours", "neighbours_walls", merge(walls), tx.windows(), "marble"))
    if roofs:
        parts.append(
            Part("neighbours", "neighbours_roofs", merge(roofs), tx.roof_tiles(seed=9), "metal")
        )
    parts.append(
        Part(
            "ground",
            "ground",
            disk((centre[0], centre[1], 0.0), GROUND_RADIUS_M, tile_m=8.0),
            tx.pavement(),
            "concrete",
        )
    )
    gx, gy = (float(c + o) for c, o in zip(centre[:2], GROUND_STATION_OFFSET_M))
    return SceneGeometry(
        name="munich",
        parts=tuple(parts),
        ground_station_m=(gx, gy, _surface_height_m(scene, gx, gy) + MAST_M),
        radio_scene="munich",
        scorable_objects=("frauenkirche", "neighbours"),
    )
