"""Ray-traced results are reproducible: the same seed gives the same paths and responses on a
rerun, also after the CIR cache is cleared (sionna-rt's deterministic path solver)."""

import numpy as np
import pytest

from phy.raytrace import RayTracer, RayTracingConfig, clear_cache

pytestmark = pytest.mark.raytracing

RX = (0.0, 0.0, 1.5)
POSITIONS = [[20.0, 0.0, 30.0], [-40.0, 10.0, 30.0], [0.0, 0.0, 2.0]]
FREQS = (np.arange(64) - 32) * 15e3
CFG = RayTracingConfig(max_depth=2, samples_per_src=10_000, max_num_paths_per_src=10_000, seed=7)


def _trace(cfg: RayTracingConfig):
    clear_cache()
    tracer = RayTracer("simple_street_canyon", RX, 3.5e9, cfg)
    cir = tracer.cir(POSITIONS)
    h, outage = tracer.cfr(POSITIONS, FREQS)
    assert tracer.num_traced == len(POSITIONS)  # traced anew, not read from the cache
    return cir, h.numpy(), outage.numpy()


def test_the_same_seed_gives_identical_cirs_and_cfrs_after_clearing_the_cache():
    assert CFG.deterministic  # the default
    first = _trace(CFG)
    assert first[0].valid.sum() >= 6  # multipath: several paths per position
    for _ in range(3):
        cir, h, outage = _trace(CFG)
        for field in ("a", "tau_s", "valid", "los"):
            np.testing.assert_array_equal(getattr(cir, field), getattr(first[0], field))
        np.testing.assert_array_equal(h, first[1])
        np.testing.assert_array_equal(outage, first[2])


def test_deterministic_must_be_a_bool():
    with pytest.raises(ValueError, match="deterministic must be True or False"):
        RayTracingConfig(deterministic="yes")
