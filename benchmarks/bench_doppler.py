"""Uncoded BER of the OFDM link over moving drones' ray-traced channels, against speed.

Drones at 8 positions 30-60 m up around a ground station in sionna-rt's street canyon, at
2.4 GHz, each flying level in a direction drawn once (seeded) while it sends; the channel
of each position is normalised to unit mean power and evolves with every path's Doppler
shift (re-traced every few wavelengths). The link is ``phy.OFDMLink`` on the default
``phy.ResourceGrid()`` (the grid of the tdl/cdl links: 64 subcarriers at 15 kHz, pilots on
OFDM symbols 2 and 11 of each 14-symbol slot), uncoded 64-QAM (its corner points cross a
decision boundary at a few degrees of phase error) at fixed SNRs, with three receivers:
perfect CSI (the bound), LS pilots with linear interpolation in time (held before the
first and after the last pilot symbol of a slot), and sionna's LMMSE filter (TDL-A
frequency covariance at 100 ns, Jakes time covariance at the drone's speed). A denser
pilot grid (a pilot symbol every 3) shows how much of the floor is the pilots'.
Each transmission is 20 slots (about 23 ms), starting at the position. Three SNRs: an
error floor is a BER that stops falling as the SNR rises.
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np
import torch

import phy
from phy.ofdm import LMMSEEstimator
from phy.raytrace import RayTracedChannel, RayTracer, RayTracingConfig, max_doppler_hz

SCENE, RX, FC = "simple_street_canyon", (0.0, 0.0, 1.5), 2.4e9
SPEEDS_M_S = (0.0, 15.0, 30.0)
SNRS_DB = (25.0, 35.0, 45.0)
MODULATION = "64qam"
NUM_POSITIONS = 8
SLOTS_PER_TRANSMISSION = 20
TRANSMISSIONS_PER_POSITION = 6
SEED = 0
GRIDS = {
    "sparse": phy.ResourceGrid(),
    "dense": phy.ResourceGrid(pilot_ofdm_symbols=(0, 3, 6, 9, 12)),
}


def _positions(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """[NUM_POSITIONS, 3] drone positions and [NUM_POSITIONS, 3] unit flight directions."""
    ang = np.linspace(0, 2 * np.pi, NUM_POSITIONS, endpoint=False) + 0.3
    z = 30.0 + 30.0 * (np.arange(NUM_POSITIONS) % 2)
    pos = np.stack([40.0 * np.cos(ang), 40.0 * np.sin(ang), z], axis=1)
    heading = rng.uniform(0, 2 * np.pi, NUM_POSITIONS)
    return pos, np.stack([np.cos(heading), np.sin(heading), np.zeros(NUM_POSITIONS)], axis=1)


def _ber(link, generator: torch.Generator, grid: phy.ResourceGrid, snr_db: float):
    """(bit errors, bits) of TRANSMISSIONS_PER_POSITION transmissions through ``link``."""
    n = SLOTS_PER_TRANSMISSION * grid.num_data_symbols
    bits = TRANSMISSIONS_PER_POSITION * n * phy.bits_per_symbol(MODULATION)
    r = phy.simulate_uncoded(MODULATION, link, snr_db, bits, generator, chunk_symbols=n)
    return r.num_errors, r.num_bits


@functools.cache
def _lmmse(grid_name: str, speed: float) -> LMMSEEstimator:
    return LMMSEEstimator(GRIDS[grid_name], speed, FC, 100e-9)


def _links(tracer, position, velocity, speed):
    """(name, grid, link) of every receiver for one moving drone."""
    for gname, grid in GRIDS.items():
        ch = RayTracedChannel(
            tracer=tracer,
            tx_positions_m=position,
            tx_velocities_m_s=velocity,
            subcarrier_frequencies_hz=grid.subcarrier_frequencies_hz,
            ofdm_symbol_duration_s=grid.symbol_length / grid.sample_rate_hz,
        )
        lmmse = _lmmse(gname, speed)
        for csi in ("perfect", "ls", "lmmse") if gname == "sparse" else ("ls", "lmmse"):
            link = phy.OFDMLink(grid, ch, csi=csi, equalizer="zf", estimator=lmmse)
            yield f"{gname}_{csi}", grid, link, ch


def run(out_dir: Path) -> dict:
    torch.set_num_threads(1)
    tracer = RayTracer(SCENE, RX, FC, RayTracingConfig(max_depth=2))
    pos, heading = _positions(np.random.default_rng(SEED))
    rows = []
    for speed in SPEEDS_M_S:
        t0 = time.perf_counter()
        counts: dict[tuple[str, float], list[int]] = {}
        spreads = []
        for k in range(NUM_POSITIONS):
            for name, grid, link, ch in _links(tracer, pos[k], speed * heading[k], speed):
                if name == "sparse_perfect":
                    spreads.append(float(ch.stats.rms_doppler_spread_hz[0]))
                for snr in SNRS_DB:
                    gen = torch.Generator().manual_seed(SEED + 1000 * k)
                    e, n = _ber(link, gen, grid, snr)
                    c = counts.setdefault((name, snr), [0, 0])
                    c[0], c[1] = c[0] + e, c[1] + n
        for snr in SNRS_DB:
            row = {"speed_m_s": speed, "max_doppler_hz": max_doppler_hz(speed, FC), "snr_db": snr}
            row.update({f"ber_{name}": e / n for (name, s), (e, n) in counts.items() if s == snr})
            row["bits_per_point"] = counts[("sparse_ls", snr)][1]
            row["median_rms_doppler_spread_hz"] = float(np.median(spreads))
            print(row)
            rows.append(row)
        print(f"speed {speed}: {time.perf_counter() - t0:.1f} s")
    return {
        "scene": SCENE,
        "carrier_frequency_hz": FC,
        "snrs_db": list(SNRS_DB),
        "modulation": MODULATION,
        "positions_m": pos.tolist(),
        "flight_directions": heading.tolist(),
        "grids": {
            name: {
                "fft_size": g.fft_size,
                "subcarrier_spacing_hz": g.subcarrier_spacing_hz,
                "ofdm_symbol_duration_s": g.symbol_length / g.sample_rate_hz,
                "num_ofdm_symbols_per_slot": g.num_ofdm_symbols,
                "pilot_ofdm_symbols": list(g.pilot_ofdm_symbols),
                "max_pilot_spacing_s": float(
                    np.diff(g.pilot_ofdm_symbols).max() * g.symbol_length / g.sample_rate_hz
                ),
            }
            for name, g in GRIDS.items()
        },
        "interpolation": "ls: linear in frequency, then linear in time between the pilot "
        "symbols of a slot, held before the first and after the last; lmmse: sionna "
        "LMMSEChannelEstimator, order f-t, TDL-A 100 ns frequency covariance, Jakes time "
        "covariance at the speed",
        "slots_per_transmission": SLOTS_PER_TRANSMISSION,
        "rows": rows,
    }
