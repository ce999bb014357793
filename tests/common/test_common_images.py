"""The one image loader: bit depths, palette, alpha, grayscale, EXIF orientation."""

import numpy as np
import pytest
from PIL import Image, ImageOps

from common import read_image


def test_16_bit_grayscale_keeps_its_values(tmp_path):
    a = np.array([[0, 1000, 65535], [30000, 40000, 50000]], np.uint16)
    Image.fromarray(a).save(tmp_path / "g16.png")
    assert Image.open(tmp_path / "g16.png").mode.startswith("I")
    img = read_image(tmp_path / "g16.png")
    assert img.shape == (2, 3, 3) and img.dtype == np.float32
    np.testing.assert_allclose(img[..., 0], a / 65535.0, atol=1e-7)
    assert np.array_equal(img[..., 0], img[..., 2])  # gray replicated, never clipped to white


def test_16_bit_rgb_keeps_its_values(tmp_path):
    import cv2

    rgb = np.array([[[1, 2000, 65535], [300, 40000, 7]]], np.uint16)
    cv2.imwrite(str(tmp_path / "c16.png"), rgb[..., ::-1])
    np.testing.assert_allclose(read_image(tmp_path / "c16.png"), rgb / 65535.0, atol=1e-7)


def test_palette_alpha_and_gray_8_bit(tmp_path):
    rng = np.random.default_rng(1)
    rgba = rng.integers(0, 256, (4, 5, 4), dtype=np.uint8)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "a.png")
    np.testing.assert_allclose(read_image(tmp_path / "a.png"), rgba[..., :3] / 255.0, atol=1e-7)
    np.testing.assert_allclose(read_image(tmp_path / "a.png", 4), rgba / 255.0, atol=1e-7)
    pal = Image.fromarray(rgba[..., :3], "RGB").convert("P", palette=Image.Palette.ADAPTIVE)
    pal.save(tmp_path / "p.png")
    want = np.asarray(pal.convert("RGB"), np.float32) / 255.0
    np.testing.assert_allclose(read_image(tmp_path / "p.png"), want, atol=1e-7)
    gray = rng.integers(0, 256, (3, 4), dtype=np.uint8)
    Image.fromarray(gray, "L").save(tmp_path / "l.png")
    np.testing.assert_allclose(read_image(tmp_path / "l.png", 1)[..., 0], gray / 255.0, atol=1e-7)


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_matches_pillow(tmp_path, orientation):
    rng = np.random.default_rng(orientation)
    im = Image.fromarray(rng.integers(0, 256, (6, 10, 3), dtype=np.uint8))
    exif = Image.Exif()
    exif[0x0112] = orientation
    im.save(tmp_path / "o.png", exif=exif)
    want = np.asarray(ImageOps.exif_transpose(Image.open(tmp_path / "o.png")).convert("RGB"))
    got = np.round(read_image(tmp_path / "o.png") * 255).astype(np.uint8)
    assert got.shape == want.shape and np.array_equal(got, want)


def test_a_corrupt_file_is_named(tmp_path):
    (tmp_path / "bad.png").write_bytes(b"\x89PNG not really")
    with pytest.raises(ValueError, match="bad.png: not a readable image"):
        read_image(tmp_path / "bad.png")


def test_to_chw_and_back_moves_only_the_channel_axis():
    import torch

    from common import to_chw, to_hwc

    rng = np.random.default_rng(0)
    hwc = rng.random((2, 5, 7, 3), dtype=np.float32)
    chw = to_chw(hwc)
    assert chw.shape == (2, 3, 5, 7) and chw.dtype == torch.float32 and chw.is_contiguous()
    assert chw[1, 2, 4, 6] == hwc[1, 4, 6, 2] and chw[0, 0, 3, 1] == hwc[0, 3, 1, 0]
    back = to_hwc(chw)
    assert back.flags.c_contiguous and np.array_equal(back, hwc)
    one = (rng.random((4, 6, 3)) * 255).astype(np.uint8)  # one image, any dtype
    assert to_chw(one).shape == (3, 4, 6) and to_chw(one).dtype == torch.uint8
    assert np.array_equal(to_hwc(to_chw(one)), one)
    assert np.array_equal(to_hwc(chw[:, :, ::2].transpose(-1, -2)), hwc[:, ::2].swapaxes(1, 2))
