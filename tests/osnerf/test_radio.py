"""The radio side of a scene: each drone position's ray-traced channel to the ground station."""

import numpy as np
import pytest

from osnerf.scenes import RenderConfig, build_scene_dataset, drone_channels, load_scene_views

TINY = RenderConfig(resolution_px=16, num_train_views=4, num_test_views=1, spp=4, mask_spp=1)
C = 299_792_458.0


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
    # each position has its own channel: the responses are not all the same
    assert np.ptp(ch.path_gain_db) > 0.01
    # a second call for the same positions is served by the cache and equal
    again = drone_channels(folder, views.meta, pos, num_subcarriers=16, subcarrier_spacing_hz=30e3)
    np.testing.assert_array_equal(again.h, ch.h)
