"""Classic image codecs of the digital baselines (Pillow): AVIF (BPG-class), WebP, JPEG.

One table, :data:`IMAGE_CODECS` (name -> :class:`ImageCodec`), read by every
``--image-codec`` flag and by the baselines.

AVIF: ``quality=q, speed=6, subsampling="4:4:4", advanced=[("tune", "psnr")]``: a BPG-class
codec (reference/codecs.md); speed 6 rather than a slower preset trades a slightly larger
file at equal quality setting for a much faster encode. ``encode_to_budget`` bisects
the integer quality to the largest file that fits a byte budget. Encodes are cached in
memory and, when ``OSNERF_CODEC_CACHE`` (or ``cache_dir``) names a folder, on disk, keyed by
(image hash, codec, quality, speed).

Wire bytes. What crosses a link is the codec's *wire* form: the file less what both ends
rebuild from parameters they share (image size and codec settings), as a real system sends
a raw bitstream, not a file. AVIF: the ISOBMFF container (ftyp, meta with iloc/iprp, the
mdat header: 275 bytes at any size), the AV1 temporal delimiter and sequence header (13
bytes) come from a template file both ends encode from a flat grey image of the same size;
only the frame OBUs are sent and the two lengths in the container (iloc extent, mdat size)
are patched back. WebP: the 20-byte RIFF/WEBP/'VP8 ' headers (pure lengths). JPEG is sent
whole (with ``optimize=True`` its Huffman tables are the image's own). :func:`encode_image`
returns wire bytes and :func:`decode_wire` decodes them; the round trip is bit-exact
(``rebuild(strip(file)) == file`` is checked on every encode).

Very low budgets. Where no file of the whole image fits (or a smaller image at a higher
quality looks better), the transmitter sends the image downscaled by a factor of
:data:`SCALES` (Pillow's Lanczos filter, :data:`RESAMPLE_FILTER`) and the receiver upscales
the decoded image with the same filter (:func:`encode_scaled_to_budget`,
:func:`decode_scaled`). The scale is control information, as the quality and the length
are: both ends know it before the bytes are decoded.
"""

from __future__ import annotations

import functools
import hashlib
import io
import math
import os
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from common import Registry, psnr, write_bytes

AVIF_SPEED = 6
SCALES = (1, 2, 4, 8, 16)
"""Downscaling factors the transmitter may send an image at (each side divided, rounded up)."""
RESAMPLE_FILTER = "lanczos"
"""Pillow's filter for the transmitter's downscale and the receiver's upscale."""
_PIL_FILTER = Image.Resampling.LANCZOS
MIN_SCALED_SIDE = 8
"""Smallest side in pixels of a downscaled image; coarser scales are not tried."""


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


# ----------------------------------------------------------------------------- AVIF container
def _boxes(data: bytes, start: int, end: int):
    """(type, start, header size, end) of each ISOBMFF box in ``data[start:end]``."""
    i = start
    while i < end:
        if i + 8 > end:
            raise ValueError("truncated box header")
        size, typ = struct.unpack(">I4s", data[i : i + 8])
        hdr = 8
        if size == 1:
            size, hdr = struct.unpack(">Q", data[i + 8 : i + 16])[0], 16
        elif size == 0:
            size = end - i
        if size < hdr or i + size > end:
            raise ValueError(f"bad size of box {typ!r}")
        yield typ.decode("latin-1"), i, hdr, i + size
        i += size


def _iloc_extent(data: bytes, body: int) -> tuple[int, int, int, int]:
    """(extent_offset, extent_length, position and size of the extent_length field) of a
    one-item, one-extent ``iloc`` box whose body starts at ``body``."""
    version = data[body]
    i = body + 4
    offset_size, length_size = data[i] >> 4, data[i] & 15
    base_size = data[i + 1] >> 4
    index_size = data[i + 1] & 15 if version in (1, 2) else 0
    i += 2
    count_bytes = 4 if version == 2 else 2
    if int.from_bytes(data[i : i + count_bytes], "big") != 1:
        raise ValueError("AVIF iloc does not hold exactly one item")
    i += 2 * count_bytes  # item_count, item_ID
    if version in (1, 2):
        if data[i + 1] & 15:
            raise ValueError("AVIF iloc construction method is not a file offset")
        i += 2
    i += 2  # data_reference_index
    base = int.from_bytes(data[i : i + base_size], "big")
    i += base_size
    if int.from_bytes(data[i : i + 2], "big") != 1:
        raise ValueError("AVIF item has more than one extent")
    i += 2 + index_size
    offset = base + int.from_bytes(data[i : i + offset_size], "big")
    i += offset_size
    return offset, int.from_bytes(data[i : i + length_size], "big"), i, length_size


@dataclass(frozen=True)
class _AvifLayout:
    head_len: int  # bytes before the first frame OBU (container + TD + sequence header)
    payload_start: int  # start of the mdat payload
    length_at: int  # iloc extent_length field: position, size
    length_size: int


def _avif_layout(data: bytes) -> _AvifLayout:
    top = {t: (s, h, e) for t, s, h, e in _boxes(data, 0, len(data))}
    if set(top) != {"ftyp", "meta", "mdat"}:
        raise ValueError(f"unexpected AVIF top-level boxes {sorted(top)}")
    ms, mh, me = top["meta"]
    ilocs = [s + h for t, s, h, _ in _boxes(data, ms + mh + 4, me) if t == "iloc"]
    if len(ilocs) != 1:
        raise ValueError("AVIF meta box holds no single iloc box")
    offset, length, at, size = _iloc_extent(data, ilocs[0])
    ds, dh, de = top["mdat"]
    if dh != 8 or offset != ds + dh or length != de - offset or de != len(data):
        raise ValueError("AVIF item data is not the whole mdat at the end of the file")
    i = offset
    while i < de and (data[i] >> 3) & 15 in (1, 2):  # sequence header, temporal delimiter
        if not (data[i] >> 1) & 1 or (data[i] >> 2) & 1:
            raise ValueError("AV1 OBU without a size field (or with an extension header)")
        j, n, shift = i + 1, 0, 0
        while True:
            n |= (data[j] & 0x7F) << shift
            shift += 7
            j += 1
            if not data[j - 1] & 0x80:
                break
        i = j + n
    return _AvifLayout(i, offset, at, size)


@functools.lru_cache(maxsize=64)
def _avif_template(height: int, width: int) -> tuple[bytes, _AvifLayout]:
    """The file of a flat grey image of this size at quality 0 and its layout."""
    data = _avif(Image.new("RGB", (width, height), (128, 128, 128)), 0)
    return data, _avif_layout(data)


def _avif_rebuild(wire: bytes, height: int, width: int) -> bytes:
    tpl, lay = _avif_template(height, width)
    head = bytearray(tpl[: lay.head_len])
    payload_len = lay.head_len - lay.payload_start + len(wire)
    if payload_len >= 1 << (8 * lay.length_size) or payload_len + 8 >= 1 << 32:
        raise ValueError("AVIF payload too long for the template's length fields")
    head[lay.length_at : lay.length_at + lay.length_size] = payload_len.to_bytes(
        lay.length_size, "big"
    )
    head[lay.payload_start - 8 : lay.payload_start - 4] = (payload_len + 8).to_bytes(4, "big")
    return bytes(head) + bytes(wire)


def _avif_strip(data: bytes, height: int, width: int) -> bytes:
    _, lay = _avif_template(height, width)
    return data[lay.head_len :]


# ----------------------------------------------------------------------------- WebP container
_WEBP_HEAD = 20  # "RIFF" size "WEBP" "VP8 " size


def _webp_strip(data: bytes, height: int, width: int) -> bytes:
    if data[:4] != b"RIFF" or data[8:16] != b"WEBPVP8 ":
        raise ValueError("not a simple lossy WebP file (RIFF/WEBP/'VP8 ')")
    n = int.from_bytes(data[16:20], "little")
    return data[_WEBP_HEAD : _WEBP_HEAD + n]


def _webp_rebuild(wire: bytes, height: int, width: int) -> bytes:
    pad = len(wire) % 2
    riff = 4 + 8 + len(wire) + pad
    return (
        b"RIFF"
        + riff.to_bytes(4, "little")
        + b"WEBPVP8 "
        + len(wire).to_bytes(4, "little")
        + bytes(wire)
        + b"\0" * pad
    )


def _whole(data: bytes, height: int, width: int) -> bytes:
    return data


# ----------------------------------------------------------------------------- the table
@dataclass(frozen=True)
class ImageCodec:
    """One image codec of the digital baselines.

    Attributes:
        name: registry key.
        encoder: ``(PIL RGB image, quality) -> file bytes``.
        quality_range: (lowest, highest) integer quality.
        strip: ``(file, height, width) -> wire bytes`` (what crosses the link).
        rebuild: ``(wire, height, width) -> file bytes`` (the receiver's side).
    """

    name: str
    encoder: Callable[[Image.Image, int], bytes]
    quality_range: tuple[int, int]
    strip: Callable[[bytes, int, int], bytes] = _whole
    rebuild: Callable[[bytes, int, int], bytes] = _whole


IMAGE_CODECS = Registry[ImageCodec](
    "image codec",
    {
        "avif": ImageCodec("avif", _avif, (0, 100), _avif_strip, _avif_rebuild),
        "webp": ImageCodec("webp", _webp, (0, 100), _webp_strip, _webp_rebuild),
        "jpeg": ImageCodec("jpeg", _jpeg, (1, 95)),
    },
)
"""name -> :class:`ImageCodec`; unknown names raise KeyError listing the known ones."""


def get_image_codec(codec: str) -> ImageCodec:
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
    """Wire bytes of one encode (files cached on disk; stripping checked bit-exact)."""
    c = get_image_codec(codec)
    path = None
    data = None
    if cache_dir:
        path = (
            Path(cache_dir)
            / f"{key}-{codec}-q{quality}-s{AVIF_SPEED if codec == 'avif' else 0}.bin"
        )
        if path.exists():
            data = path.read_bytes()
    if data is None:
        data = c.encoder(Image.fromarray(np.frombuffer(raw, np.uint8).reshape(shape)), quality)
        if path is not None:
            write_bytes(path, data)
    h, w = shape[:2]
    wire = c.strip(data, h, w)
    if c.rebuild(wire, h, w) != data:
        raise RuntimeError(
            f"{codec} file of a {w}x{h} image at quality {quality} does not match the "
            "container template both ends share; cannot send it without its container"
        )
    return wire


def encode_image(image, codec: str, quality: int, cache_dir=None) -> bytes:
    """Encode one image ([3, H, W] float in [0, 1] or [H, W, 3] uint8) at a quality setting.

    Returns:
        the codec's wire bytes (container stripped; :func:`decode_wire` decodes them).
    """
    lo, hi = get_image_codec(codec).quality_range
    if not lo <= int(quality) <= hi:
        raise ValueError(f"quality for {codec} must be in [{lo}, {hi}], got {quality}")
    a = to_uint8(image)
    raw = a.tobytes()
    key = hashlib.sha256(raw + str(a.shape).encode()).hexdigest()[:24]
    d = _cache_dir(cache_dir)
    return _encode_cached(key, codec, int(quality), raw, a.shape, str(d) if d else None)


def decode_image(data: bytes) -> np.ndarray:
    """A whole file of any codec here -> [H, W, 3] uint8. Raises ValueError on undecodable data."""
    try:
        img = Image.open(io.BytesIO(data))
        img.load()
    except Exception as e:  # noqa: BLE001 - any decoder failure means a lost image
        raise ValueError(f"undecodable image data ({type(e).__name__})") from None
    return np.asarray(img.convert("RGB"))


def decode_wire(data: bytes, codec: str, height: int, width: int) -> np.ndarray:
    """Wire bytes of :func:`encode_image` -> [height, width, 3] uint8; the receiver rebuilds
    the container from the size and the codec settings. Raises ValueError on undecodable data
    or a decoded size other than ``height`` x ``width``."""
    c = get_image_codec(codec)
    try:
        file = c.rebuild(bytes(data), int(height), int(width))
    except (ValueError, OverflowError) as e:
        raise ValueError(f"cannot rebuild the {codec} container ({e})") from None
    a = decode_image(file)
    if a.shape[:2] != (height, width):
        raise ValueError(f"decoded {a.shape[1]}x{a.shape[0]} px, expected {width}x{height}")
    return a


def encode_to_budget(
    image, max_bytes: int, codec: str = "avif", cache_dir=None
) -> tuple[bytes | None, int | None]:
    """The highest-quality encoding whose wire bytes fit ``max_bytes`` (bisection on quality).

    Returns:
        (wire bytes, quality), or (None, None) when even the lowest quality does not fit.
    """
    lo, hi = get_image_codec(codec).quality_range
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


# ----------------------------------------------------------------------------- scales
def scaled_size(height: int, width: int, scale: int) -> tuple[int, int]:
    """(height, width) of an image downscaled by ``scale`` (each side divided, rounded up)."""
    if scale not in SCALES:
        raise ValueError(f"scale must be one of {SCALES}, got {scale!r}")
    return -(-int(height) // scale), -(-int(width) // scale)


def downscale(image, scale: int) -> np.ndarray:
    """[H, W, 3] uint8 of ``image`` (as :func:`to_uint8` takes it) downscaled by ``scale``."""
    a = to_uint8(image)
    h, w = scaled_size(*a.shape[:2], scale)
    if (h, w) == a.shape[:2]:
        return a
    return np.asarray(Image.fromarray(a).resize((w, h), _PIL_FILTER))


def decode_scaled(data: bytes, codec: str, height: int, width: int, scale: int = 1) -> np.ndarray:
    """Wire bytes of an image sent at ``scale`` -> [height, width, 3] uint8: decoded at the
    scaled size, then upscaled with :data:`RESAMPLE_FILTER`. ValueError as :func:`decode_wire`."""
    h, w = scaled_size(height, width, scale)
    a = decode_wire(data, codec, h, w)
    if (h, w) == (height, width):
        return a
    return np.asarray(Image.fromarray(a).resize((int(width), int(height)), _PIL_FILTER))


def usable_scales(height: int, width: int) -> tuple[int, ...]:
    """The :data:`SCALES` whose downscaled image keeps both sides >= :data:`MIN_SCALED_SIDE`
    (always 1)."""
    return tuple(
        s for s in SCALES if s == 1 or min(scaled_size(height, width, s)) >= MIN_SCALED_SIDE
    )


def smallest_files(image, codec: str, cache_dir=None) -> dict[int, int]:
    """scale -> wire bytes of the image at the codec's lowest quality, per usable scale."""
    a = to_uint8(image)
    lo = get_image_codec(codec).quality_range[0]
    return {
        s: len(encode_image(downscale(a, s), codec, lo, cache_dir))
        for s in usable_scales(*a.shape[:2])
    }


def encode_scaled_to_budget(
    image, max_bytes: int, codec: str = "avif", cache_dir=None
) -> tuple[bytes | None, int | None, int | None]:
    """The best file of the image that fits ``max_bytes``, over scale and quality.

    Per scale of :func:`usable_scales`, from 1 up, the highest quality that fits
    (:func:`encode_to_budget`); the transmitter decodes and upscales each candidate and keeps
    the one of highest PSNR against its image, stopping at the first scale that does worse
    than the best so far (a coarser one would lose more detail still).

    Returns:
        (wire bytes, quality, scale), or (None, None, None) when nothing fits.
    """
    a = to_uint8(image)
    h, w = a.shape[:2]
    ref = a.astype(np.float64) / 255.0
    best = (None, None, None)
    best_psnr = -math.inf
    for s in usable_scales(h, w):
        data, q = encode_to_budget(downscale(a, s), max_bytes, codec, cache_dir)
        if data is None:
            continue
        p = psnr(decode_scaled(data, codec, h, w, s).astype(np.float64) / 255.0, ref)
        if p <= best_psnr:
            break
        best, best_psnr = (data, q, s), p
    return best
