"""OFDM: resource grid, modulation/demodulation, channel estimation, equalisation."""

from phy.ofdm.equalization import EQUALIZERS, equalize, post_equalization_snr

__all__ = ["EQUALIZERS", "equalize", "post_equalization_snr"]
