"""The radio side of a scene: each drone position's ray-traced channel to the ground station."""

import numpy as np
import pytest

from osnerf.scenes import (
    RenderConfig,
    build_scene_dataset,
    drone_channels,
    get_scene,
    load_scene_views,
    write_radio_scene,
)

TINY = RenderConfig(resolution_px=16, num_train_views=4, num_test_views=1, spp=4, mask_spp=1)
C = 299_792_458.0
FC = get_scene("tiny").carrier_frequency_hz


@pytest.mark.raytracing
def test_ray_traced_channel_per_drone_position(tmp_path):
    folder = build_scene_dataset("tiny", ("post",), TINY, cache_dir=tmp_path, progress=False)
    views = load_scene_views(folder)
    pos = views.drone_positions_m
    ch = drone_channels(folder, views.meta, pos, num_subcarriers=16, subcarrier_spacing_hz=30e3)
    assert ch.h.shape == (len(pos), 16) and ch.h.dtype == np.complex64
    assert (
        np.all(np.isfinite(ch.h)) and not ch.outage.any()
    )  # open plot: every drone reaches the station
    # line of sight over a small plot: the path gain is free-space loss give or take the
    # ground and wall reflections (at most +6 dB for a coherent double, a few dB of fading)
    d = np.linalg.norm(pos - np.asarray(views.meta["ground_station_m"]), axis=1)
    fspl_db = 20 * np.log10(4 * np.pi * d * views.meta["carrier_frequency_hz"] / C)
    assert np.all(ch.path_gain_db > -fspl_db - 15) and np.all(ch.path_gain_db < -fspl_db + 6.5)
    assert all(ch.stats["los"])
    # above the ground: at least the line of sight and its ground reflection, some delay spread
    assert min(ch.stats["num_paths"]) >= 2 and min(ch.stats["rms_delay_spread_s"]) > 0
    # each position has its own channel: the responses are not all the same
    assert np.ptp(ch.path_gain_db) > 0.01
    # a second call for the same positions is served by the cache and equal
    again = drone_channels(folder, views.meta, pos, num_subcarriers=16, subcarrier_spacing_hz=30e3)
    np.testing.assert_array_equal(again.h, ch.h)


def _radio_scene(name: str, folder):
    """A built-in scene's geometry and its radio scene written under ``folder`` (no render)."""
    from osnerf.scenes.render import write_meshes

    geometry = get_scene(name).build()
    mesh_paths = write_meshes(geometry, folder / "meshes")
    return geometry, write_radio_scene(geometry, mesh_paths, folder / "radio")


def _fresnel_tm(grazing_rad: float, freq_hz: float) -> complex:
    """Reflection coefficient of a vertically polarised wave off ITU-R P.2040 medium dry
    ground (a half-space), grazing angle ``grazing_rad``."""
    f_ghz = freq_hz / 1e9
    eps = 15.0 * f_ghz**-0.1 - 1j * 0.035 * f_ghz**1.63 / (2 * np.pi * freq_hz * 8.854e-12)
    s, c = np.sin(grazing_rad), np.cos(grazing_rad)
    root = np.sqrt(eps - c**2)
    return (eps * s - root) / (eps * s + root)


@pytest.mark.raytracing
def test_ground_reflection_beyond_the_plot_is_the_two_ray_one(tmp_path):
    """tiny: a drone h1 above the ground, a station h2 above it d away (the reflection point
    lies beyond the rendered plot): a second path at the two-ray excess delay, weaker than
    the line of sight by the ground's Fresnel coefficient and the longer way."""
    import phy.raytrace as prt

    geometry, xml = _radio_scene("tiny", tmp_path)
    gs = np.asarray(geometry.ground_station_m)
    drone = np.array([0.0, -1.2, 4.0])
    tracer = prt.RayTracer(
        str(xml), tuple(gs), FC, prt.RayTracingConfig(max_depth=1, refraction=False)
    )
    c = tracer.cir(drone)
    assert c.los.all() and c.valid.sum() >= 2
    d = np.linalg.norm((drone - gs)[:2])
    h1, h2 = drone[2], gs[2]
    los, refl = np.hypot(d, h1 - h2), np.hypot(d, h1 + h2)
    tau = c.tau_s[0][c.valid[0]]
    a = c.a[0][c.valid[0]]
    k = int(np.argmin(np.abs(tau - (refl - los) / C)))
    np.testing.assert_allclose(tau[k], (refl - los) / C, rtol=1e-3)
    assert tau[k] > 0 and np.argmin(tau) != k
    ratio_db = 20 * np.log10(np.abs(a[k]) / np.abs(a[np.argmin(tau)]))
    grazing = np.arctan2(h1 + h2, d)
    want_db = 20 * np.log10(np.abs(_fresnel_tm(grazing, FC)) * los / refl)
    assert abs(ratio_db - want_db) < 1.0, (ratio_db, want_db)
    # the reflection point is on the terrain, not on the rendered plot
    point = drone[:2] + (gs[:2] - drone[:2]) * h1 / (h1 + h2)
    assert np.linalg.norm(point) > geometry.object_bounds_m("ground")[1][0]


@pytest.mark.raytracing
@pytest.mark.parametrize("name", ["tiny", "firefighter", "munich"])
def test_ground_station_is_in_the_open(name, tmp_path):
    """A ray straight up from every built-in scene's ground station reaches the sky: the
    station is not inside a building (where every path would have to go through walls)."""
    import mitsuba as mi

    import phy.raytrace as prt

    geometry = get_scene(name).build()
    scene = geometry.radio_scene or str(_radio_scene(name, tmp_path)[1])
    mis = prt.load_scene(scene).mi_scene
    gs = mi.Point3f(*map(float, geometry.ground_station_m))
    for direction in ((0.0, 0.0, 1.0), (0.3, 0.0, 0.95), (0.0, -0.3, 0.95)):
        si = mis.ray_intersect(mi.Ray3f(gs, mi.Vector3f(*direction)))
        assert not bool(si.is_valid().numpy()[0]), (name, direction, float(si.t.numpy()[0]))
