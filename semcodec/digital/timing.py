"""What the digital link costs in time per image: AVIF's search for the file that fits, and the
LDPC chain's encoding and decoding of it (:func:`digital_timing`)."""

from __future__ import annotations

import torch
from torch import Tensor

from common import median_seconds
from phy.digital import decode_symbols, encode_bytes, payload_capacity_bits
from semcodec.digital import image_codecs
from semcodec.digital.calibration import load_calibration


def digital_timing(image: Tensor, snr_db: float, num_symbols: int, repeats: int = 5) -> dict:
    """Median wall times (current torch threads) of ``digital``'s steps for one image at the
    MCS the calibration table plans for AWGN at ``snr_db``.

    Args:
        image: [1, 3, height, width] float32 in [0, 1].
        num_symbols: the image's symbol budget.
    Returns:
        {"mcs", "num_symbols", "avif_encode_seconds" (the search over quality and scale for
        the best file that fits, every encode fresh: no cache), "payload_bytes",
        "ldpc_encode_seconds", "ldpc_decode_seconds" (CRC + rate matching + belief
        propagation on the file's codewords at ``snr_db``)}.
    """
    img = image[0]
    smallest = image_codecs.smallest_files(img, "avif")
    mcs, _ = load_calibration().choose_mcs(
        "awgn", snr_db, num_symbols, img.shape[1] * img.shape[2], "avif", smallest
    )
    budget = payload_capacity_bits(num_symbols, mcs) // 8
    fresh = image_codecs._encode_cached.cache_clear  # time the encodes, not the cache

    def avif():
        return image_codecs.encode_scaled_to_budget(img, budget, "avif")

    out = {"mcs": mcs, "num_symbols": int(num_symbols)}
    out["avif_encode_seconds"] = median_seconds(avif, repeats, before=fresh)
    data, _, _ = avif()
    if data is None:
        return out | {"note": "no AVIF file fits the budget"}
    sym = encode_bytes(data, mcs, num_symbols)
    noise_var = 10 ** (-snr_db / 10)
    g = torch.Generator().manual_seed(0)
    noise = torch.complex(torch.randn(sym.shape, generator=g), torch.randn(sym.shape, generator=g))
    rx = sym + noise * (noise_var / 2) ** 0.5
    out["payload_bytes"] = len(data)
    out["ldpc_encode_seconds"] = median_seconds(
        lambda: encode_bytes(data, mcs, num_symbols), repeats
    )
    out["ldpc_decode_seconds"] = median_seconds(
        lambda: decode_symbols(rx, noise_var, mcs, len(data)), repeats
    )
    return out
