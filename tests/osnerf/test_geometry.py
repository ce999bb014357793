"""Meshes: closed, outward-facing, the right volume; PLY round trip; camera conventions."""

import numpy as np
import pytest

from osnerf.scenes import intrinsics_from_fov, look_at, pixel_rays, project, ring_positions
from osnerf.scenes.geometry import annulus, box, cylinder, disk, read_ply, write_ply


def signed_volume(mesh) -> float:
    """Divergence theorem: sum of (v0 . (v1 x v2)) / 6 over faces; > 0 when normals face out."""
    v = mesh.vertices_m.astype(np.float64)[mesh.faces]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6)


def test_box_is_closed_with_outward_faces():
    m = box((1.0, -2.0, 0.5), (0.4, 0.6, 0.8), bottom=True)
    assert signed_volume(m) == pytest.approx(0.4 * 0.6 * 0.8, rel=1e-5)
    np.testing.assert_allclose(m.bounds_m, [[0.8, -2.3, 0.5], [1.2, -1.7, 1.3]], atol=1e-6)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_cylinder_volume_and_axis(axis):
    n = 256
    m = cylinder((0.0, 0.0, 0.0), 0.5, 2.0, segments=n, axis=axis)
    polygon_area = 0.5 * n * 0.25 * np.sin(2 * np.pi / n)
    assert signed_volume(m) == pytest.approx(polygon_area * 2.0, rel=1e-4)
    ext = m.bounds_m[1] - m.bounds_m[0]
    assert ext["xyz".index(axis)] == pytest.approx(2.0, abs=1e-5)


def test_cone_volume():
    m = cylinder((0.0, 0.0, 0.0), 1.0, 3.0, segments=512, radius_top_m=0.0)
    assert signed_volume(m) == pytest.approx(np.pi * 1.0 * 3.0 / 3, rel=1e-3)


def test_annulus_continues_the_disk_facing_up():
    """The terrain ring around a plot: its inner edge is the disk's rim, every face faces +z,
    and disk plus ring cover the outer polygon exactly once."""
    n = 64
    plot, ring = disk((1.0, 2.0, 0.0), 2.6, segments=n), annulus((1.0, 2.0, 0.0), 2.6, 40.0, n)
    np.testing.assert_array_equal(ring.vertices_m[:n], plot.vertices_m[1:])
    area = 0.0
    for m in (plot, ring):
        v = m.vertices_m.astype(np.float64)[m.faces]
        normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        assert np.all(normal[:, 2] > 0) and np.allclose(normal[:, :2], 0, atol=1e-3)
        area += normal[:, 2].sum() / 2
    assert area == pytest.approx(0.5 * n * 40.0**2 * np.sin(2 * np.pi / n), rel=1e-5)
    with pytest.raises(ValueError, match="0 < inner < outer"):
        annulus((0.0, 0.0, 0.0), 2.0, 1.0)


def test_ply_round_trip(tmp_path):
    m = disk((0.5, 0.25, 0.0), 1.5, segments=12, tile_m=0.5)
    back = read_ply(write_ply(m, tmp_path / "d.ply"))
    np.testing.assert_allclose(back.vertices_m, m.vertices_m, atol=1e-6)
    np.testing.assert_array_equal(back.faces, m.faces)
    np.testing.assert_allclose(back.uv, m.uv, atol=1e-6)


def test_look_at_is_opengl_and_projects_target_to_centre():
    intr = intrinsics_from_fov(40.0, 64, 48)
    assert intr.fx == pytest.approx(32 / np.tan(np.radians(20)))
    pose = look_at((3.0, -2.0, 1.5), (0.2, 0.1, 0.3))
    r = pose[:3, :3]
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    forward = -pose[:3, 2]  # OpenGL: the camera looks along -z
    np.testing.assert_allclose(
        forward, (np.array([0.2, 0.1, 0.3]) - [3, -2, 1.5]) / np.linalg.norm([2.8, -2.1, 1.2])
    )
    assert pose[2, 1] > 0  # camera y points up in the world
    uv = project(np.array([[0.2, 0.1, 0.3], [0.2, 0.1, 1.3]]), pose, intr)
    np.testing.assert_allclose(uv[0], [32.0, 24.0], atol=1e-9)
    assert uv[1, 1] < 24.0  # a point above the target appears higher in the image (v down)


def test_pixel_rays_hit_their_pixels():
    intr = intrinsics_from_fov(50.0, 8, 6)
    pose = look_at((0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
    o, d = pixel_rays(pose, intr)
    uv = project(o + 2.0 * d, pose, intr)  # [48, 2]
    j, i = np.meshgrid(np.arange(8) + 0.5, np.arange(6) + 0.5)
    np.testing.assert_allclose(uv, np.c_[j.ravel(), i.ravel()], atol=1e-9)


def test_ring_positions_radius_and_elevation():
    p = ring_positions((1.0, 2.0, 0.5), 3.0, (20.0, 40.0), 10)
    rel = p - [1.0, 2.0, 0.5]
    np.testing.assert_allclose(np.linalg.norm(rel, axis=1), 3.0)
    elev = np.degrees(np.arcsin(rel[:, 2] / 3.0))
    assert sorted(set(np.round(elev, 6))) == [20.0, 40.0]
    with pytest.raises(ValueError, match="elevations_deg"):
        ring_positions((0, 0, 0), 1.0, (95.0,), 3)
