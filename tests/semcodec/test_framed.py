"""semcodec's framed schemes (what `osnerf ota` sends): the digital one cuts an image's codec
bytes into frames with a CRC each; a lost frame loses the image, which shows mid-grey."""

import numpy as np
import pytest
import torch

from semcodec import LINK_SCHEMES, LOST_IMAGE_VALUE
from semcodec.digital import encode_image
from semcodec.links import FramedSettings, ReceivedBlock, frame_payload_bytes

SPF = 256


def _image(size: int = 32) -> np.ndarray:
    """[1, 3, size, size] float32: smooth gradients (the codec's bytes span several frames)."""
    y, x = np.mgrid[0:size, 0:size] / (size - 1)
    return np.stack([x, y, 0.5 * (x + y)])[None].astype(np.float32)


def _clean(block: np.ndarray, detected: list[bool]) -> ReceivedBlock:
    """The block as sent, near-noiseless; frames not detected are erased (0, huge noise)."""
    x = block.copy()
    nv = np.full(len(x), 1e-3, np.float32)
    for i, ok in enumerate(detected):
        if not ok:
            x[i * SPF : (i + 1) * SPF] = 0
            nv[i * SPF : (i + 1) * SPF] = 1e3
    return ReceivedBlock(x, nv, detected, 30.0)


def decode_image_as_sent(data: bytes) -> np.ndarray:
    from semcodec.digital.image_codecs import decode_wire

    return decode_wire(data, "avif", 32, 32).astype(np.float32).transpose(2, 0, 1) / 255.0


def test_every_over_the_air_scheme_has_a_framed_pair():
    air = [k for k, v in LINK_SCHEMES.items() if v.over_the_air]
    assert sorted(air) == ["digital", "jscc", "softcast"]
    assert all(LINK_SCHEMES[k].framed is not None for k in air)


def test_digital_frames_each_carry_a_crc_and_a_lost_one_loses_the_image():
    images = _image()
    settings = FramedSettings(snr_db=20.0, symbols_per_frame=SPF, quality=60)
    framed = LINK_SCHEMES["digital"].framed
    blocks, sizes = framed.transmit(images, settings)
    data = encode_image(images[0], "avif", 60)
    per_frame = frame_payload_bytes(SPF, "qpsk-1/2")
    num_frames = -(-len(data) // per_frame)
    assert num_frames >= 2 and len(blocks[0]) == num_frames * SPF
    assert sizes == [[min(per_frame, len(data) - i) for i in range(0, len(data), per_frame)]]

    (ok,) = framed.receive([_clean(blocks[0], [True] * num_frames)], sizes, images, settings)
    assert ok.stats == {"decoded": True, "bytes": len(data), "frames_crc_failed": 0}
    assert ok.frames_crc_ok == [True] * num_frames
    np.testing.assert_array_equal(ok.image, decode_image_as_sent(data))
    assert ok.psnr > 25

    detected = [True] * num_frames
    detected[1] = False
    (lost,) = framed.receive([_clean(blocks[0], detected)], sizes, images, settings)
    assert lost.frames_crc_ok[1] is False and lost.stats["frames_crc_failed"] == 1
    assert not lost.stats["decoded"] and np.all(lost.image == LOST_IMAGE_VALUE)


def test_a_frame_too_short_for_any_payload_is_refused():
    with pytest.raises(ValueError, match="holds no payload"):
        LINK_SCHEMES["digital"].framed.transmit(
            _image(), FramedSettings(snr_db=20.0, symbols_per_frame=8)
        )
    with pytest.raises(ValueError, match="symbols_per_frame must be an integer >= 1"):
        FramedSettings(snr_db=0.0, symbols_per_frame=0)


def test_jscc_receiver_without_any_frame_decodes_at_0_db(tiny_codec):
    images = _image()
    settings = FramedSettings(snr_db=5.0, symbols_per_frame=SPF, codec=tiny_codec)
    framed = LINK_SCHEMES["jscc"].framed
    blocks, encoded = framed.transmit(images, settings)
    n = len(blocks[0])
    erased = ReceivedBlock(np.zeros(n, np.complex64), np.full(n, 1e3, np.float32), [False], None)
    (rec,) = framed.receive([erased], encoded, images, settings)
    snr_in = float(np.clip(0.0, *tiny_codec.snr_range_db))  # no frame: no measured SNR
    x, nv = torch.zeros(1, n, dtype=torch.complex64), torch.full((1, n), 1e3)
    expected = tiny_codec.decode(x, encoded[0].meta, snr_in, noise_var=nv)
    torch.testing.assert_close(torch.from_numpy(rec.image), expected[0])
    assert rec.stats["decoded"] and rec.frames_crc_ok == [None]
