"""OFDM: resource grid, modulation/demodulation, channel estimation, equalisation."""

from phy.ofdm.equalization import EQUALIZERS, equalize, post_equalization_snr
from phy.ofdm.estimation import INTERPOLATIONS, interpolation_matrix, ls_channel_estimate
from phy.ofdm.lmmse import LMMSEEstimator
from phy.ofdm.modulator import ofdm_demodulate, ofdm_modulate
from phy.ofdm.resource_grid import ResourceGrid, extract_data, map_to_grid

__all__ = [
    "EQUALIZERS",
    "INTERPOLATIONS",
    "LMMSEEstimator",
    "ResourceGrid",
    "equalize",
    "extract_data",
    "interpolation_matrix",
    "ls_channel_estimate",
    "map_to_grid",
    "ofdm_demodulate",
    "ofdm_modulate",
    "post_equalization_snr",
]
