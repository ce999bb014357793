"""Triangle meshes with texture coordinates, built in numpy, written as binary PLY.

The same PLY files feed both worlds: Mitsuba's optical renders and sionna-rt's ray tracer.
All coordinates are metres in a z-up world. Texture coordinates are in metres divided by a
tile size, so a texture repeats at the same physical scale on every face.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from common import write_bytes
from osnerf.scenes.mitsuba_env import import_mitsuba


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh.

    Attributes:
        vertices_m: [num_vertices, 3] float32, metres.
        faces: [num_faces, 3] int32 vertex indices, counter-clockwise seen from outside.
        uv: [num_vertices, 2] float32 texture coordinates.
    """

    vertices_m: np.ndarray
    faces: np.ndarray
    uv: np.ndarray

    def __post_init__(self):
        v, f, uv = self.vertices_m, self.faces, self.uv
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"vertices_m must be [num_vertices, 3], got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or (f.size and (f.min() < 0 or f.max() >= len(v))):
            raise ValueError(f"faces must be [num_faces, 3] indices into {len(v)} vertices")
        if uv.shape != (len(v), 2):
            raise ValueError(f"uv must be [{len(v)}, 2], got {uv.shape}")

    @property
    def bounds_m(self) -> np.ndarray:
        """[2, 3] float64: min and max corner."""
        return np.stack([self.vertices_m.min(0), self.vertices_m.max(0)]).astype(np.float64)


def merge(meshes: list[Mesh]) -> Mesh:
    """One mesh holding all faces of ``meshes``."""
    offsets = np.cumsum([0] + [len(m.vertices_m) for m in meshes[:-1]])
    return Mesh(
        np.concatenate([m.vertices_m for m in meshes]).astype(np.float32),
        np.concatenate([m.faces + o for m, o in zip(meshes, offsets)]).astype(np.int32),
        np.concatenate([m.uv for m in meshes]).astype(np.float32),
    )


def _quad(corners: np.ndarray, tile_m: float) -> Mesh:
    """A planar quad from 4 corners (counter-clockwise from outside), UVs in metres / tile."""
    c = np.asarray(corners, np.float64)
    e_u, e_v = c[1] - c[0], c[3] - c[0]
    len_u, len_v = np.linalg.norm(e_u), np.linalg.norm(e_v)
    uv = np.array([[0, 0], [len_u, 0], [len_u, len_v], [0, len_v]]) / tile_m
    return Mesh(
        c.astype(np.float32), np.array([[0, 1, 2], [0, 2, 3]], np.int32), uv.astype(np.float32)
    )


def box(center_m, size_m, tile_m: float = 1.0, bottom: bool = False) -> Mesh:
    """An axis-aligned box; ``center_m`` is the centre of its bottom face.

    Args:
        center_m: (x, y, z) of the bottom face centre, metres.
        size_m: (size_x, size_y, size_z) metres.
        bottom: include the bottom face (hidden when the box stands on the ground).
    """
    cx, cy, z0 = (float(a) for a in center_m)
    sx, sy, sz = (float(a) / 2 for a in size_m)
    x0, x1, y0, y1, z1 = cx - sx, cx + sx, cy - sy, cy + sy, z0 + 2 * sz
    quads = [
        [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],  # -y
        [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],  # +x
        [[x1, y1, z0], [x0, y1, z0], [x0, y1, z1], [x1, y1, z1]],  # +y
        [[x0, y1, z0], [x0, y0, z0], [x0, y0, z1], [x0, y1, z1]],  # -x
        [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],  # top
    ]
    if bottom:
        quads.append([[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]])
    return merge([_quad(np.array(q), tile_m) for q in quads])


def cylinder(
    base_m,
    radius_m: float,
    height_m: float,
    segments: int = 32,
    tile_m: float = 1.0,
    radius_top_m: float | None = None,
    axis: str = "z",
    caps: bool = True,
) -> Mesh:
    """A (possibly tapered) cylinder from ``base_m`` along +``axis`` with closed caps.

    ``radius_top_m=0`` gives a cone. ``axis`` is "x", "y" or "z" ("x"/"y" for nozzles).
    """
    if axis not in ("x", "y", "z"):
        raise ValueError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    r0 = float(radius_m)
    r1 = r0 if radius_top_m is None else float(radius_top_m)
    n = int(segments)
    a = np.linspace(0.0, 2 * np.pi, n + 1)  # seam duplicated for UVs
    ring = np.stack([np.cos(a), np.sin(a)], 1)  # [n+1, 2]
    side_v = np.concatenate(
        [np.c_[ring * r0, np.zeros(n + 1)], np.c_[ring * r1, np.full(n + 1, height_m)]]
    )  # [2(n+1), 3] local, axis = local z
    circ = 2 * np.pi * max(r0, r1, 1e-6)
    side_uv = (
        np.concatenate(
            [
                np.c_[a / (2 * np.pi) * circ, np.zeros(n + 1)],
                np.c_[a / (2 * np.pi) * circ, np.full(n + 1, height_m)],
            ]
        )
        / tile_m
    )
    i = np.arange(n)
    top = i + n + 1
    side_f = np.concatenate([np.c_[i, i + 1, top + 1], np.c_[i, top + 1, top]])
    parts = [Mesh(side_v.astype(np.float32), side_f.astype(np.int32), side_uv.astype(np.float32))]
    if caps:
        for z, r, up in ((0.0, r0, False), (float(height_m), r1, True)):
            if r <= 0:
                continue
            v = np.concatenate([[[0.0, 0.0, z]], np.c_[ring[:-1] * r, np.full(n, z)]])
            uv = v[:, :2] / tile_m
            j = np.arange(n)
            f = np.c_[np.zeros(n, int), 1 + j, 1 + (j + 1) % n]
            if not up:
                f = f[:, [0, 2, 1]]
            parts.append(Mesh(v.astype(np.float32), f.astype(np.int32), uv.astype(np.float32)))
    m = merge(parts)
    v = m.vertices_m.astype(np.float64)
    if axis == "x":  # local z -> world x, local x -> world y, local y -> world z
        v = v[:, [2, 0, 1]]
    elif axis == "y":  # local z -> world y, local x -> world z, local y -> world x
        v = v[:, [1, 2, 0]]
    v = v + np.asarray(base_m, np.float64)
    return Mesh(v.astype(np.float32), m.faces, m.uv)


def disk(center_m, radius_m: float, segments: int = 64, tile_m: float = 1.0) -> Mesh:
    """A horizontal disk facing +z (the ground)."""
    n = int(segments)
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    v = np.concatenate(
        [[[0.0, 0.0, 0.0]], np.c_[np.cos(a) * radius_m, np.sin(a) * radius_m, np.zeros(n)]]
    )
    v = v + np.asarray(center_m, np.float64)
    j = np.arange(n)
    f = np.c_[np.zeros(n, int), 1 + j, 1 + (j + 1) % n]
    return Mesh(v.astype(np.float32), f.astype(np.int32), (v[:, :2] / tile_m).astype(np.float32))


def annulus(
    center_m, inner_radius_m: float, outer_radius_m: float, segments: int = 64, tile_m: float = 1.0
) -> Mesh:
    """A horizontal ring facing +z around a :func:`disk` of ``inner_radius_m``.

    Its inner edge has the disk's vertices (same ``segments``, same angles), so the two
    together are one flat surface without gap or overlap.
    """
    if not 0 < inner_radius_m < outer_radius_m:
        raise ValueError(
            f"annulus radii must satisfy 0 < inner < outer, got {inner_radius_m}, {outer_radius_m}"
        )
    n = int(segments)
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ring = np.c_[np.cos(a), np.sin(a), np.zeros(n)]
    v = np.concatenate([ring * inner_radius_m, ring * outer_radius_m])
    v = v + np.asarray(center_m, np.float64)
    j = np.arange(n)
    k = (j + 1) % n
    f = np.concatenate([np.c_[j, n + j, n + k], np.c_[j, n + k, k]])
    return Mesh(v.astype(np.float32), f.astype(np.int32), (v[:, :2] / tile_m).astype(np.float32))


def planar_uv(vertices_m: np.ndarray, tile_m: float) -> np.ndarray:
    """Planar texture coordinates for meshes without UVs: u along x+y, v along z (walls).

    Args:
        vertices_m: [num_vertices, 3].
    Returns:
        [num_vertices, 2] float32.
    """
    v = np.asarray(vertices_m, np.float64)
    return (
        np.c_[(v[:, 0] + v[:, 1]) / np.sqrt(2.0), v[:, 2] + 0.5 * (v[:, 0] - v[:, 1])] / tile_m
    ).astype(np.float32)


_PLY_VERTEX = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("u", "<f4"), ("v", "<f4")])
_PLY_FACE = np.dtype([("n", "u1"), ("i", "<i4", (3,))])


def write_ply(mesh: Mesh, path: str | Path) -> Path:
    """Write ``mesh`` as binary little-endian PLY (x, y, z, u, v; triangle faces)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    vert = np.empty(len(mesh.vertices_m), _PLY_VERTEX)
    for k, name in enumerate("xyz"):
        vert[name] = mesh.vertices_m[:, k]
    vert["u"], vert["v"] = mesh.uv[:, 0], mesh.uv[:, 1]
    face = np.empty(len(mesh.faces), _PLY_FACE)
    face["n"] = 3
    face["i"] = mesh.faces
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(vert)}\n"
        + "".join(f"property float {n}\n" for n in "xyzuv")
        + f"element face {len(face)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    return write_bytes(path, header.encode("ascii") + vert.tobytes() + face.tobytes())


def read_ply(path: str | Path) -> Mesh:
    """Read a triangle PLY (any format Mitsuba reads) into a :class:`Mesh` via Mitsuba.

    Meshes without texture coordinates get :func:`planar_uv` with a 1 m tile.
    """
    mi = import_mitsuba()
    with mi.util.scoped_set_variant("scalar_rgb"):
        shape = mi.load_dict({"type": "ply", "filename": str(path), "face_normals": True})
        params = mi.traverse(shape)
        v = np.asarray(params["vertex_positions"], np.float32).reshape(-1, 3)
        f = np.asarray(params["faces"], np.int64).reshape(-1, 3).astype(np.int32)
        uv_raw = (
            np.asarray(params["vertex_texcoords"], np.float32)
            if "vertex_texcoords" in params
            else None
        )
    uv = (
        uv_raw.reshape(-1, 2)
        if uv_raw is not None and uv_raw.size == 2 * len(v)
        else planar_uv(v, 1.0)
    )
    return Mesh(v, f, uv)
