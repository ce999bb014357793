"""Image codecs: one table, wire bytes without containers, bit-exact round trips."""

import numpy as np
import pytest
from PIL import Image
from smooth_images import smooth_image

from common import psnr
from semcodec.digital import IMAGE_CODECS
from semcodec.digital.image_codecs import (
    decode_image,
    decode_scaled,
    decode_wire,
    downscale,
    encode_image,
    encode_scaled_to_budget,
    get_image_codec,
    scaled_size,
    smallest_files,
    usable_scales,
)


def test_unknown_codec_lists_the_known_ones():
    with pytest.raises(KeyError, match="known: .*avif.*jpeg.*webp"):
        get_image_codec("bpg")


@pytest.mark.parametrize("codec", ["avif", "webp", "jpeg"])
@pytest.mark.parametrize("size", [(80, 80), (47, 61)])
def test_wire_bytes_round_trip_bit_exact(codec, size):
    """Stripping the container and rebuilding it from the size gives the very file back."""
    x = smooth_image(6, *size)[0]
    pixels = Image.fromarray((x.permute(1, 2, 0).numpy() * 255).round().astype(np.uint8))
    lo, hi = IMAGE_CODECS[codec].quality_range
    for q in (lo, 40, hi):
        wire = encode_image(x, codec, q)
        file = IMAGE_CODECS[codec].encoder(pixels, q)
        assert IMAGE_CODECS[codec].rebuild(wire, *size) == file
        assert (decode_wire(wire, codec, *size) == decode_image(file)).all()
        overhead = len(file) - len(wire)
        if codec == "avif":  # ISOBMFF container (275 bytes) + AV1 sequence header and TD
            assert overhead >= 275
        else:
            assert overhead in {"webp": (20, 21), "jpeg": (0,)}[codec]


@pytest.mark.parametrize("scale", [2, 4])
def test_a_downscaled_image_round_trips_at_its_scale(scale):
    """Sent at a scale, the wire bytes decode to the downscaled image (sides rounded up) and
    the receiver's upscale with the same Lanczos filter gives the full size back."""
    x = smooth_image(7, 64, 44)[0]
    small = downscale(x, scale)
    assert small.shape == (-(-64 // scale), -(-44 // scale), 3) == (*scaled_size(64, 44, scale), 3)
    wire = encode_image(small, "avif", 100)
    assert (
        decode_wire(wire, "avif", *small.shape[:2])
        == decode_image(IMAGE_CODECS["avif"].rebuild(wire, *small.shape[:2]))
    ).all()
    full = decode_scaled(wire, "avif", 64, 44, scale)
    expect = Image.fromarray(decode_wire(wire, "avif", *small.shape[:2])).resize(
        (44, 64), Image.Resampling.LANCZOS
    )
    assert full.shape == (64, 44, 3) and (full == np.asarray(expect)).all()
    # a smooth image loses little to the round trip
    assert psnr(full / 255.0, x.permute(1, 2, 0).numpy()) > 30
    with pytest.raises(ValueError, match="scale must be one of"):
        scaled_size(64, 44, 3)


def test_below_the_smallest_full_size_file_a_downscaled_image_is_sent():
    """Budgets under the image's smallest full-size file pick a coarser scale; a generous one
    keeps the full image; the choice is the best PSNR the transmitter finds."""
    x = smooth_image(8, 128, 128)[0]
    smallest = smallest_files(x, "avif")
    assert list(smallest) == [1, 2, 4, 8, 16] and smallest[1] > smallest[4]
    data, q, scale = encode_scaled_to_budget(x, smallest[1] - 1, "avif")
    assert scale > 1 and len(data) < smallest[1]
    data, q, scale = encode_scaled_to_budget(x, 20 * smallest[1], "avif")
    assert scale == 1
    assert encode_scaled_to_budget(x, min(smallest.values()) - 1, "avif") == (None, None, None)
    assert usable_scales(20, 300) == (1, 2)  # coarser ones would leave a side under 8 px
