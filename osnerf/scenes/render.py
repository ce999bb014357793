"""Optical renders of a scene with Mitsuba: RGB views, exact poses, exact object masks.

Masks are not the AOV shape index (averaged by the pixel filter, and not an index into
``scene.shapes()``): each pixel casts ``mask_spp`` jittered camera rays, every ray's first
hit is compared with the object's shapes, and the mask is the fraction of rays that hit the
object (anti-aliased, occlusion-aware). The *silhouette* is the same against the object
alone (no occluders); visible fraction = visible mask area / silhouette area.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

import phy
from osnerf.scenes.cameras import MITSUBA_FROM_GL, Intrinsics, pixel_rays
from osnerf.scenes.geometry import write_ply
from osnerf.scenes.mitsuba_env import RGB_VARIANT
from osnerf.scenes.spec import SceneGeometry

VARIANT = RGB_VARIANT
GAMMA = 2.2


@dataclass
class ViewRender:
    """One rendered view.

    Attributes:
        rgb: [height, width, 3] float32 in [0, 1] (display gamma 2.2), background = sky.
        masks: object name -> [height, width] float32 in [0, 1], visible (occlusion-aware).
        silhouettes: object name -> [height, width] float32, the object alone.
    """

    rgb: np.ndarray
    masks: dict[str, np.ndarray]
    silhouettes: dict[str, np.ndarray]


def write_meshes(geometry: SceneGeometry, folder: Path) -> dict[str, Path]:
    """Write every part as ``folder/<part>.ply``; returns part name -> path."""
    return {p.name: write_ply(p.mesh, Path(folder) / f"{p.name}.ply") for p in geometry.parts}


def background_rgb(geometry: SceneGeometry) -> np.ndarray:
    """[3] float32: what a pixel seeing only sky shows (after clipping and gamma)."""
    return (np.clip(np.asarray(geometry.sky_radiance, np.float64), 0, 1) ** (1 / GAMMA)).astype(
        np.float32
    )


class MitsubaRenderer:
    """Holds one Mitsuba scene and moves its camera (built once: compiling is the slow part)."""

    def __init__(
        self, geometry: SceneGeometry, mesh_paths: dict[str, Path], intr: Intrinsics, spp: int = 32
    ):
        phy.require_llvm()  # points Dr.Jit at a usable LLVM before mitsuba loads
        import mitsuba as mi

        if (
            mi.variant() is None
        ):  # scoped_set_variant cannot restore "no variant"; sionna-rt's is safe
            mi.set_variant("llvm_ad_mono_polarized", VARIANT)
        self.mi = mi
        self.geometry, self.intr, self.spp = geometry, intr, int(spp)
        fov = float(np.degrees(2 * np.arctan(intr.width / 2 / intr.fx)))
        with mi.util.scoped_set_variant(VARIANT):
            shapes = {}
            for p in geometry.parts:
                shapes[p.name] = {
                    "type": "ply",
                    "filename": str(mesh_paths[p.name]),
                    "face_normals": True,
                    "bsdf": {
                        "type": "twosided",
                        "bsdf": {
                            "type": "diffuse",
                            "reflectance": {
                                "type": "bitmap",
                                "bitmap": mi.Bitmap(p.texture),
                                "raw": True,
                                "filter_type": "bilinear",
                            },
                        },
                    },
                }
            scene = {
                "type": "scene",
                "integrator": {"type": "path", "max_depth": 3},
                "sky": {
                    "type": "constant",
                    "radiance": {"type": "rgb", "value": list(geometry.sky_radiance)},
                },
                "sun": {
                    "type": "directional",
                    "direction": [-0.4, 0.3, -0.85],
                    "irradiance": {"type": "rgb", "value": [1.6, 1.5, 1.35]},
                },
                "sensor": {
                    "type": "perspective",
                    "fov": fov,
                    "fov_axis": "x",
                    "to_world": mi.ScalarTransform4f(np.eye(4)),
                    "film": {
                        "type": "hdrfilm",
                        "width": intr.width,
                        "height": intr.height,
                        "rfilter": {"type": "box"},
                        "pixel_format": "rgb",
                    },
                    "sampler": {"type": "independent", "sample_count": self.spp},
                },
                **shapes,
            }
            self.scene = mi.load_dict(scene)
            self.params = mi.traverse(self.scene)
            # one scene per object (its parts only) for silhouettes
            self.alone = {}
            for obj in geometry.objects:
                d = {"type": "scene"}
                d.update(
                    {
                        k: {kk: vv for kk, vv in v.items() if kk != "bsdf"}
                        for k, v in shapes.items()
                        if k in {p.name for p in geometry.parts if p.object_name == obj}
                    }
                )
                self.alone[obj] = mi.load_dict(d)
            self.part_shapes = {s.id(): s for s in self.scene.shapes()}

    def _hits(self, scene, origins: np.ndarray, dirs: np.ndarray, parts: dict[str, list[str]]):
        """Which object each ray hits first: name -> [num_rays] bool."""
        mi = self.mi
        import drjit as dr

        ray = mi.Ray3f(
            mi.Point3f(*[o for o in origins.T.astype(np.float32)]),
            mi.Vector3f(*[d for d in dirs.T.astype(np.float32)]),
        )
        si = scene.ray_intersect(ray)
        by_id = {s.id(): s for s in scene.shapes()}
        out = {}
        for obj, names in parts.items():
            hit = dr.zeros(mi.Bool, len(origins))
            for n in names:
                if n in by_id:
                    hit = hit | (si.shape == mi.ShapePtr(by_id[n]))
            out[obj] = np.asarray(hit & si.is_valid(), bool)
        return out

    def render(self, pose: np.ndarray, seed: int, mask_spp: int = 4) -> ViewRender:
        """Render one camera pose (OpenGL camera-to-world [4, 4])."""
        mi = self.mi
        h, w = self.intr.height, self.intr.width
        with mi.util.scoped_set_variant(VARIANT):
            self.params["sensor.to_world"] = mi.ScalarTransform4f(pose @ MITSUBA_FROM_GL)
            self.params.update()
            lin = np.asarray(
                mi.render(self.scene, self.params, spp=self.spp, seed=int(seed)), np.float32
            )
            rgb = np.clip(lin[..., :3], 0, 1) ** (1 / GAMMA)
            gen = np.random.default_rng(int(seed) + 7919)
            o, d = pixel_rays(pose, self.intr, mask_spp, generator=gen)
            parts = {
                obj: [p.name for p in self.geometry.parts if p.object_name == obj]
                for obj in self.geometry.objects
            }
            vis = self._hits(self.scene, o, d, parts)
            masks = {
                k: v.reshape(h, w, mask_spp).mean(-1).astype(np.float32) for k, v in vis.items()
            }
            sil = {}
            for obj in self.geometry.objects:
                hit = self._hits(self.alone[obj], o, d, {obj: parts[obj]})[obj]
                sil[obj] = hit.reshape(h, w, mask_spp).mean(-1).astype(np.float32)
        return ViewRender(rgb.astype(np.float32), masks, sil)
