"""Ray-traced channels: a sionna-rt scene, a drone (transmitter) and a ground station.

``import phy.raytrace`` is cheap; sionna.rt (and Dr.Jit's LLVM check) loads on first use.
"""

from phy.raytrace.channel import GAIN_NORMALIZATIONS, PerPositionChannel, RayTracedChannel
from phy.raytrace.mobility import (
    RETRACE_WAVELENGTHS,
    MovingCIR,
    MovingTransmitter,
    max_doppler_hz,
)
from phy.raytrace.radiomap import RadioMap, RadioMapConfig, radio_map
from phy.raytrace.scene import builtin_scenes, load_scene
from phy.raytrace.stats import RayStats, cir_stats
from phy.raytrace.tracer import (
    RayCIR,
    RayTracer,
    RayTracingConfig,
    check_positions,
    clear_cache,
)

__all__ = [
    "RETRACE_WAVELENGTHS",
    "MovingCIR",
    "MovingTransmitter",
    "max_doppler_hz",
    "GAIN_NORMALIZATIONS",
    "RadioMap",
    "RadioMapConfig",
    "RayCIR",
    "RayStats",
    "PerPositionChannel",
    "RayTracedChannel",
    "RayTracer",
    "RayTracingConfig",
    "builtin_scenes",
    "check_positions",
    "cir_stats",
    "clear_cache",
    "load_scene",
    "radio_map",
]
