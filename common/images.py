"""The one image loader: any image file as float32 in [0, 1], the way a viewer shows it.

* 8-bit and 16-bit samples (``uint16 / 65535``), grayscale (replicated to RGB), palette
  (expanded), alpha (dropped for RGB, kept for RGBA);
* the EXIF orientation applied (a phone photo stored sideways comes out upright);
* errors name the file: a missing, corrupt or unsupported file is a ``ValueError``
  ("<path>: not a readable image ...").

Decoding is OpenCV's (``IMREAD_UNCHANGED`` keeps 16 bits and alpha), with Pillow for the
formats OpenCV does not read and for the EXIF tag.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from common.errors import InputError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".webp", ".bmp", ".tif", ".tiff")
"""Files the project reads as images (case-insensitive), in every command."""

_LUMA = np.array([0.299, 0.587, 0.114], np.float32)  # ITU-R BT.601, as Pillow's "L"


def _orient(a: np.ndarray, orientation: int) -> np.ndarray:
    """Apply EXIF orientation 1..8 to [height, width, channels] (as PIL.ImageOps.exif_transpose)."""
    if orientation == 2:
        return a[:, ::-1]
    if orientation == 3:
        return a[::-1, ::-1]
    if orientation == 4:
        return a[::-1]
    if orientation == 5:
        return a.transpose(1, 0, 2)
    if orientation == 6:
        return np.rot90(a, k=-1)
    if orientation == 7:
        return a.transpose(1, 0, 2)[::-1, ::-1]
    if orientation == 8:
        return np.rot90(a, k=1)
    return a


def _decode(path: Path) -> tuple[np.ndarray, int]:
    """[height, width, channels] samples as stored (RGB(A) order), and the EXIF orientation."""
    import cv2
    from PIL import Image, UnidentifiedImageError

    orientation = 1
    try:
        with Image.open(path) as im:
            orientation = int(im.getexif().get(0x0112, 1) or 1)
            fallback = None
            a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED | cv2.IMREAD_IGNORE_ORIENTATION)
            if a is None or a.dtype not in (np.uint8, np.uint16):
                im.load()
                fallback = im.convert(
                    "RGBA" if "A" in im.getbands() or "transparency" in im.info else "RGB"
                )
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as e:
        raise ValueError(
            f"{path}: not a readable image ({type(e).__name__}); replace or remove it"
        ) from None
    if fallback is not None:
        return np.asarray(fallback), orientation
    assert a is not None  # cv2 decoded it, or fallback is set above
    if a.ndim == 2:
        a = a[..., None]
    elif a.shape[2] == 3:
        a = a[..., ::-1]
    elif a.shape[2] == 4:
        a = a[..., [2, 1, 0, 3]]
    return a, orientation


def read_image(path: str | os.PathLike, channels: int | None = 3) -> np.ndarray:
    """Read an image file as the project's float image.

    Args:
        path: any file in :data:`IMAGE_SUFFIXES` (others that Pillow reads work too).
        channels: 3 for RGB (alpha dropped, gray replicated), 4 for RGBA (alpha 1.0 where the
            file has none), 1 for luminance (BT.601 weights of RGB; a gray file as stored),
            None for RGBA when the file has alpha and RGB when it has not.
    Returns:
        [height, width, channels] float32 in [0, 1], upright per the EXIF orientation.
    Raises:
        ValueError: naming the file when it is not a readable image.
    """
    if channels not in (None, 1, 3, 4):
        raise ValueError(f"channels must be None, 1, 3 or 4, got {channels!r}")
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: not a readable image (no such file)")
    a, orientation = _decode(path)
    scale = 65535.0 if a.dtype == np.uint16 else 255.0
    img = a.astype(np.float32) / scale
    gray, alpha = img.shape[2] in (1, 2), img.shape[2] in (2, 4)
    color = img[..., :1] if gray else img[..., :3]
    if channels is None:
        channels = 4 if alpha else 3
    if channels == 1:
        out = color if gray else (color @ _LUMA)[..., None]
    else:
        out = np.repeat(color, 3, axis=2) if gray else color
        if channels == 4:
            a_ch = img[..., -1:] if alpha else np.ones_like(out[..., :1])
            out = np.concatenate([out, a_ch], axis=2)
    return np.ascontiguousarray(_orient(out, orientation))


def to_chw(images: np.ndarray):
    """Images as the codecs and fields take them: ``[..., height, width, channels]`` (this
    module's layout) -> a contiguous ``[..., channels, height, width]`` torch tensor of the
    same dtype and values."""
    import torch

    return torch.from_numpy(np.ascontiguousarray(images)).movedim(-1, -3).contiguous()


def to_hwc(images) -> np.ndarray:
    """The inverse of :func:`to_chw`: a ``[..., channels, height, width]`` tensor -> a
    contiguous ``[..., height, width, channels]`` numpy array of the same dtype and values."""
    return np.ascontiguousarray(images.detach().movedim(-3, -1).cpu().numpy())


def list_images(path: str | os.PathLike, what: str = "images") -> list[Path]:
    """The image files that ``path`` names: itself when it is an image file, else the files of
    :data:`IMAGE_SUFFIXES` in that folder, sorted by name (not recursive).

    Raises:
        FileNotFoundError: "<what> <path>: ..." when nothing is there, the file is not an image
            file, or the folder holds none.
    """
    p = Path(path)
    kinds = ", ".join(IMAGE_SUFFIXES)
    if p.is_file():
        if p.suffix.lower() not in IMAGE_SUFFIXES:
            raise FileNotFoundError(f"{what} {str(p)!r} is not an image file ({kinds})")
        return [p]
    if not p.is_dir():
        raise FileNotFoundError(f"{what} {str(p)!r}: no such file or folder")
    files = sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES and f.is_file())
    if not files:
        raise FileNotFoundError(f"{what} {str(p)!r}: no image files ({kinds}) in this folder")
    return files


def load_square_images(
    path: str | os.PathLike,
    size: int,
    max_images: int,
    what: str = "images",
    size_flag: str = "size",
) -> tuple[list[str], np.ndarray]:
    """The first ``max_images`` images of ``path`` (:func:`list_images`), centre-cropped to a
    square and resized to ``size`` (Lanczos, per channel in float): (names,
    [batch, 3, size, size] float32 in [0, 1]).

    An image whose square crop is smaller than ``size`` is refused, never upscaled.

    Raises:
        InputError: an unreadable image, or one smaller than ``size`` (naming ``what`` and
            ``size_flag``).
        FileNotFoundError: from :func:`list_images`.
    """
    from PIL import Image

    files = list_images(path, what)[:max_images]
    out = []
    for f in files:
        try:
            a = read_image(f)
        except ValueError as e:
            raise InputError(f"{what}: {e}") from None
        h, w = a.shape[:2]
        s = min(h, w)
        if s < size:
            raise InputError(
                f"{what}: {f.name} is {w}x{h} px, smaller than {size_flag} {size}: it would be "
                f"upscaled; give a larger image or a smaller {size_flag}"
            )
        top, left = (h - s) // 2, (w - s) // 2
        crop = a[top : top + s, left : left + s]
        chans = [
            np.asarray(
                Image.fromarray(crop[..., c], "F").resize((size, size), Image.Resampling.LANCZOS)
            )
            for c in range(3)
        ]
        out.append(np.clip(np.stack(chans), 0.0, 1.0).astype(np.float32))
    return [f.name for f in files], np.stack(out)
