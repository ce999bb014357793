"""Classic image codecs of the digital baselines (Pillow): AVIF (BPG-class), WebP, JPEG.

AVIF: ``quality=q, speed=6, subsampling="4:4:4", advanced=[("tune", "psnr")]``: within
about 1 % of BPG's rate on Kodak at speed 4 (reference/codecs.md); we use speed 6, about 7x
faster to encode and about 2 % larger at equal quality setting. ``encode_to_budget`` bisects
the integer quality to the largest file that fits a byte budget. Encodes are cached in
memory and, when ``OSNERF_CODEC_CACHE`` (or ``cache_dir``) names a folder, on disk, keyed by
(image hash, codec, quality, speed).
"""

from __future__ import annotations

import functools
import hashlib
import io
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image

AVIF_SPEED = 6


def _avif(img: Image.Image, q: int) -> bytes:
    b = io.BytesIO()
    img.save(
        b,
        format="AVIF",
        quality=q,
        speed=AVIF_SPEED,
        subsampling="4:4:4",
        advanced=[("tune", "psnr")],
    )
    return b.getvalue()


def _webp(img: Image.Image, q: int) -> bytes:
    b = io.BytesIO()
    img.save(b, format="WEBP", quality=q, method=4)
    return b.getvalue()


def _jpeg(img: Image.Image, q: int) -> bytes:
    b = io.BytesIO()
    img.save(b, format="JPEG", quality=q, subsampling=0, optimize=True)
    return b.getvalue()


# name -> (encoder(PIL image, quality) -> bytes, lowest quality, highest quality)
IMAGE_CODECS: dict[str, tuple[Callable[[Image.Image, int], bytes], int, int]] = {
    "avif": (_avif, 0, 100),
    "webp": (_webp, 0, 100),
    "jpeg": (_jpeg, 1, 95),
}


def read_image_file(path) -> Image.Image:
    """Open and fully decode an image file.

    Raises:
        ValueError: naming the file when it is not a readable image (corrupt, truncated,
            another kind of file), so a command reports bad input (exit 2), not a crash.
    """
    from PIL import UnidentifiedImageError

    try:
        with Image.open(path) as im:
            im.load()
            return im.copy()
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as e:
        raise ValueError(
            f"{path}: not a readable image ({type(e).__name__}); replace or remove it"
        ) from None


def _get(codec: str):
    try:
        return IMAGE_CODECS[codec]
    except (KeyError, TypeError):
        raise KeyError(f"unknown image codec {codec!r}; known: {sorted(IMAGE_CODECS)}") from None


def to_uint8(image) -> np.ndarray:
    """[3, H, W] float in [0, 1] (tensor or array) or [H, W, 3] uint8 -> [H, W, 3] uint8."""
    a = np.asarray(image.detach().cpu() if hasattr(image, "detach") else image)
    if a.dtype != np.uint8:
        a = np.round(np.clip(a.transpose(1, 2, 0), 0, 1) * 255).astype(np.uint8)
    return np.ascontiguousarray(a)


def _cache_dir(cache_dir) -> Path | None:
    d = cache_dir or os.environ.get("OSNERF_CODEC_CACHE")
    return Path(d) if d else None


@functools.lru_cache(maxsize=4096)
def _encode_cached(
    key: str, codec: str, quality: int, raw: bytes, shape: tuple, cache_dir: str | None
) -> bytes:
    path = None
    if cache_dir:
        path = (
            Path(cache_dir)
            / f"{key}-{codec}-q{quality}-s{AVIF_SPEED if codec == 'avif' else 0}.bin"
        )
        if path.exists():
            return path.read_bytes()
    enc, _, _ = _get(codec)
    data = enc(Image.fromarray(np.frombuffer(raw, np.uint8).reshape(shape)), quality)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(data)
        tmp.replace(path)
    return data


def encode_image(image, codec: str, quality: int, cache_dir=None) -> bytes:
    """Encode one image ([3, H, W] float in [0, 1] or [H, W, 3] uint8) at a quality setting."""
    _, lo, hi = _get(codec)
    if not lo <= int(quality) <= hi:
        raise ValueError(f"quality for {codec} must be in [{lo}, {hi}], got {quality}")
    a = to_uint8(image)
    raw = a.tobytes()
    key = hashlib.sha256(raw + str(a.shape).encode()).hexdigest()[:24]
    d = _cache_dir(cache_dir)
    return _encode_cached(key, codec, int(quality), raw, a.shape, str(d) if d else None)


def decode_image(data: bytes) -> np.ndarray:
    """Bytes of any codec here -> [H, W, 3] uint8. Raises ValueError on undecodable data."""
    try:
        img = Image.open(io.BytesIO(data))
        img.load()
    except Exception as e:  # noqa: BLE001 - any decoder failure means a lost image
        raise ValueError(f"undecodable image data ({type(e).__name__})") from None
    return np.asarray(img.convert("RGB"))


def encode_to_budget(
    image, max_bytes: int, codec: str = "avif", cache_dir=None
) -> tuple[bytes | None, int | None]:
    """The highest-quality encoding that fits ``max_bytes`` (bisection on the quality).

    Returns:
        (bytes, quality), or (None, None) when even the lowest quality does not fit.
    """
    _, lo, hi = _get(codec)
    if max_bytes <= 0 or len(encode_image(image, codec, lo, cache_dir)) > max_bytes:
        return None, None
    if len(encode_image(image, codec, hi, cache_dir)) <= max_bytes:
        return encode_image(image, codec, hi, cache_dir), hi
    a, b = lo, hi  # size(a) fits, size(b) does not
    while b - a > 1:
        mid = (a + b) // 2
        if len(encode_image(image, codec, mid, cache_dir)) <= max_bytes:
            a = mid
        else:
            b = mid
    return encode_image(image, codec, a, cache_dir), a
