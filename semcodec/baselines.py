"""The schemes a JSCC is judged against, and the JSCC itself, on one interface.

Every ``transmit_*`` takes images [batch, 3, height, width] float32 in [0, 1] and returns a
:class:`TransmitResult` (received images of the same shape + stats).

* digital: image codec (AVIF by default) at the byte budget the MCS allows in
  ``num_symbols`` (``phy.digital.payload_capacity_bits``), then phy.digital's CRC + 5G LDPC
  + QAM through the same link. ``mcs="envelope"`` picks the best MCS per image and SNR
  (see :func:`transmit_digital`); a fixed MCS name shows the cliff. A lost image (any
  payload codeword failing its CRC, or a budget too small for the codec's lowest quality)
  is received as mid-grey (0.5 everywhere): the receiver has nothing better to show.
* ideal: the codec at capacity, ``num_symbols * log2(1 + snr)`` bits, error free.
* analog: uncoded pixels; each image's values standardised (mean and std sent as side
  information), paired into complex symbols, LMMSE-scaled at the receiver.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor
from torch.nn import functional as F

from phy import noise_var_to_snr_db
from semcodec.codec import Codec, check_images
from semcodec.image_codecs import IMAGE_CODECS, decode_wire, encode_to_budget

LOST_IMAGE_VALUE = 0.5
ENVELOPE = "envelope"


@dataclass
class TransmitResult:
    """Received images [batch, 3, height, width] float32 and stats (sums over the batch, and lists per image)."""

    images: Tensor
    stats: dict = field(default_factory=dict)

    def __iter__(self):  # (images, stats) = result
        return iter((self.images, self.stats))


def _run_link(link, x: Tensor, snr_db, generator):
    """(x_hat, noise_var [batch, num_symbols]) from a phy link or a bare phy channel."""
    out = link(x, snr_db, generator=generator)
    if hasattr(out, "x_hat"):
        return out.x_hat, out.noise_var
    nv = out.noise_var.reshape(-1, 1).expand(x.shape).to(torch.float32)
    return out.equalized("mmse"), nv


def receiver_snr_db(noise_var: Tensor) -> Tensor:
    """[batch] SNR in dB that a receiver infers from the link's per-symbol noise variance."""
    nv = noise_var.reshape(noise_var.shape[0], -1).mean(dim=1).clamp(1e-6, 1e3)
    return noise_var_to_snr_db(nv).clamp(-30.0, 60.0)


def transmit_jscc(
    codec: Codec,
    images: Tensor,
    link,
    snr_db,
    cbr: float,
    mask=None,
    generator: torch.Generator | None = None,
    demand_weights=None,
    rx_codec: Codec | None = None,
) -> TransmitResult:
    """Images through the JSCC and the link; the decoder is told the SNR the link reports.

    Args:
        link: ``phy.FlatLink``/``phy.OFDMLink`` (or a bare ``phy`` channel).
        snr_db: float or [batch], the link's Es/N0 (also the encoder's SNR input).
        rx_codec: the receiver's codec (default the transmitter's); hashes must match.
    """
    x = check_images(images)
    enc = codec.encode(x, snr_db, cbr, mask=mask, demand_weights=demand_weights)
    with torch.no_grad():
        x_hat, nv = _run_link(link, enc.symbols, snr_db, generator)
    rx = rx_codec or codec
    y = rx.decode(x_hat, enc.meta, receiver_snr_db(nv), expected_sha256=codec.sha256)
    n = x.shape[0]
    return TransmitResult(
        y,
        {
            "num_symbols": enc.meta.num_symbols * n,
            "cbr": enc.meta.cbr,
            "side_info_bits": enc.meta.side_info_bits() * n,
            "failed_codewords": 0,
        },
    )


def _grey(shape) -> Tensor:
    return torch.full(shape, LOST_IMAGE_VALUE)


def _decode_or_grey(data: bytes | None, shape, image_codec: str) -> tuple[Tensor, bool]:
    """Wire bytes -> ([3, H, W] image, True), or (mid-grey, False) when undecodable."""
    if data is None:
        return _grey(shape), False
    try:
        a = decode_wire(data, image_codec, shape[1], shape[2])
    except ValueError:
        return _grey(shape), False
    return torch.from_numpy(a.astype(np.float32) / 255.0).permute(2, 0, 1), True


def _check_codec(image_codec: str) -> str:
    if image_codec not in IMAGE_CODECS:
        raise KeyError(f"unknown image codec {image_codec!r}; known: {sorted(IMAGE_CODECS)}")
    return image_codec


def _check_num_symbols(num_symbols) -> int:
    if int(num_symbols) != num_symbols or int(num_symbols) < 1:
        raise ValueError(f"num_symbols must be a positive integer, got {num_symbols!r}")
    return int(num_symbols)


def transmit_ideal(
    images: Tensor, snr_db: float, num_symbols: int, image_codec: str = "avif"
) -> TransmitResult:
    """The codec at the capacity rate ``num_symbols * log2(1 + snr)`` bits, no errors."""
    x = check_images(images)
    n = _check_num_symbols(num_symbols)
    _check_codec(image_codec)
    bits = int(math.floor(n * math.log2(1.0 + 10.0 ** (float(snr_db) / 10.0))))
    out, qualities, sizes = [], [], []
    for img in x:
        data, q = encode_to_budget(img, bits // 8, image_codec)
        rec, _ = _decode_or_grey(data, img.shape, image_codec)
        out.append(rec)
        qualities.append(q)
        sizes.append(0 if data is None else len(data))
    return TransmitResult(
        torch.stack(out),
        {
            "budget_bits": bits,
            "bits": 8 * sum(sizes),
            "num_symbols": n * len(x),
            "quality": qualities,
            "lost_images": sum(q is None for q in qualities),
            "failed_codewords": 0,
        },
    )


def _is_awgn_link(link) -> bool:
    ch = getattr(link, "channel", None)
    return type(ch).__name__ == "AWGN"


@functools.lru_cache(maxsize=256)
def _calibrated_mcs_index(num_symbols: int, snr_db: float, seed: int) -> int:
    """AWGN: index of the highest MCS (in MCS_TABLE order) whose random-payload block of this
    length decodes at this SNR (bottom-up, stopping at the first failure); -1 if none."""
    import phy
    from phy.digital import MCS_TABLE, payload_capacity_bits, transmit_bytes

    link = phy.FlatLink(phy.make_channel("awgn"), csi="perfect", equalizer="zf")
    best = -1
    rng = np.random.default_rng(seed)
    for i, name in enumerate(MCS_TABLE):
        nbytes = payload_capacity_bits(num_symbols, name) // 8
        if nbytes <= 0:
            continue
        payload = rng.integers(0, 256, nbytes, dtype=np.uint8).tobytes()
        r = transmit_bytes(
            payload,
            name,
            link,
            snr_db,
            generator=torch.Generator().manual_seed(seed + i),
            num_symbols=num_symbols,
        )
        if not r.ok:
            break
        best = i
    return best


def _send_digital(img: Tensor, mcs: str, link, snr_db, n: int, image_codec: str, seed: int):
    """One image at one MCS. Returns (received [3,H,W], ok, info)."""
    from phy.digital import payload_capacity_bits, transmit_bytes

    budget = payload_capacity_bits(n, mcs) // 8
    data, q = encode_to_budget(img, budget, image_codec)
    if data is None:
        return (
            _grey(img.shape),
            False,
            {"mcs": mcs, "quality": None, "bits": 0, "failed_codewords": 0},
        )
    r = transmit_bytes(
        data, mcs, link, snr_db, generator=torch.Generator().manual_seed(seed), num_symbols=n
    )
    rec, ok = _decode_or_grey(r.payload if r.ok else None, img.shape, image_codec)
    failed = (
        len([c for c in r.failed_codewords if c < r.num_payload_codewords])
        if r.num_payload_codewords
        else len(r.failed_codewords)
    )
    return (
        rec,
        ok,
        {
            "mcs": mcs,
            "quality": q,
            "bits": 8 * len(data),
            "failed_codewords": failed,
            "num_codewords": r.num_codewords,
        },
    )


def transmit_digital(
    images: Tensor,
    link,
    snr_db: float,
    num_symbols: int,
    mcs: str = ENVELOPE,
    image_codec: str = "avif",
    generator: torch.Generator | None = None,
) -> TransmitResult:
    """Image codec + CRC + 5G LDPC + QAM through ``link`` in ``num_symbols`` symbols per image.

    ``mcs="envelope"``: the best MCS per image, i.e. the highest-rate MCS whose block decodes
    (a higher rate always means a larger file, so a better image). Over AWGN the starting
    MCS comes from a calibration block of random payload at the same length and SNR (the
    highest MCS that decodes, bottom-up); if the image fails at it the next lower MCS is
    tried, down to the lowest. Over other links (fading) each image searches upward from the
    lowest MCS with the same channel realisation for every attempt (an oracle MCS choice).

    Args:
        link: ``phy.FlatLink`` / ``phy.OFDMLink`` (equalizer "zf" recommended for QAM LLRs).
        mcs: ``"envelope"`` or a name in ``phy.digital.MCS_TABLE``.
        image_codec: ``"avif"``, ``"webp"`` or ``"jpeg"``.
    Returns:
        TransmitResult; stats: bits, num_symbols, failed_codewords, lost_images, mcs and
        quality per image.
    """
    from phy.digital import MCS_TABLE, get_mcs

    x = check_images(images)
    n = _check_num_symbols(num_symbols)
    _check_codec(image_codec)
    names = list(MCS_TABLE)
    if mcs != ENVELOPE:
        get_mcs(mcs)
    gen = generator or torch.Generator().manual_seed(0)
    out, infos = [], []
    for img in x:
        seed = int(torch.randint(0, 2**62, (1,), generator=gen))
        if mcs != ENVELOPE:
            rec, ok, info = _send_digital(img, mcs, link, snr_db, n, image_codec, seed)
        elif _is_awgn_link(link):
            start = _calibrated_mcs_index(n, float(snr_db), 12345)
            rec, ok, info = (
                _grey(img.shape),
                False,
                {"mcs": None, "quality": None, "bits": 0, "failed_codewords": 0},
            )
            for i in range(start, -1, -1):
                r2, ok2, info2 = _send_digital(img, names[i], link, snr_db, n, image_codec, seed)
                info2["failed_codewords"] += info["failed_codewords"]
                rec, ok, info = r2, ok2, info2
                if ok:
                    break
        else:
            rec, ok, info = (
                _grey(img.shape),
                False,
                {"mcs": None, "quality": None, "bits": 0, "failed_codewords": 0},
            )
            for name in names:
                r2, ok2, info2 = _send_digital(img, name, link, snr_db, n, image_codec, seed)
                if not ok2:
                    info["failed_codewords"] += info2["failed_codewords"]
                    break
                info2["failed_codewords"] += info["failed_codewords"]
                rec, ok, info = r2, ok2, info2
        info["ok"] = ok
        out.append(rec)
        infos.append(info)
    stats = {
        "bits": sum(i["bits"] for i in infos),
        "num_symbols": n * len(x),
        "failed_codewords": sum(i["failed_codewords"] for i in infos),
        "lost_images": sum(not i["ok"] for i in infos),
        "mcs": [i["mcs"] for i in infos],
        "quality": [i["quality"] for i in infos],
    }
    return TransmitResult(torch.stack(out), stats)


def transmit_analog(
    images: Tensor,
    link,
    snr_db,
    num_symbols: int | None = None,
    generator: torch.Generator | None = None,
) -> TransmitResult:
    """Uncoded pixels: two real values per complex symbol, LMMSE at the receiver.

    Args:
        num_symbols: symbols per image; None = all pixels (CBR 1/2). Fewer: the image is
            area-downsampled to fit and bilinearly upsampled at the receiver.
    """
    x = check_images(images)
    b, _, h, w = x.shape
    src = x
    if num_symbols is not None:
        n = _check_num_symbols(num_symbols)
        scale = min(1.0, math.sqrt(2 * n / (3 * h * w)))
        hs, ws = max(1, int(h * scale)), max(1, int(w * scale))
        while 3 * hs * ws > 2 * n and hs > 1:
            hs -= 1
        src = F.interpolate(x, size=(hs, ws), mode="area") if (hs, ws) != (h, w) else x
    flat = src.reshape(b, -1)
    if flat.shape[1] % 2:
        flat = F.pad(flat, (0, 1), value=float(flat.mean()))
    mean = flat.mean(dim=1, keepdim=True)
    std = flat.std(dim=1, keepdim=True, unbiased=False).clamp_min(1e-6)
    s = (flat - mean) / std  # unit variance per real value
    sym = torch.view_as_complex(
        (s * math.sqrt(0.5)).reshape(b, -1, 2).contiguous()
    )  # mean |x|^2 = 1
    with torch.no_grad():
        x_hat, nv = _run_link(link, sym, snr_db, generator)
    est = (
        x_hat / (1.0 + nv) * math.sqrt(2.0)
    )  # LMMSE for a unit-power source, back to unit variance
    v = torch.view_as_real(est.to(torch.complex64)).reshape(b, -1)[:, : src[0].numel()] * std + mean
    rec = v.reshape(src.shape)
    if rec.shape[-2:] != (h, w):
        rec = F.interpolate(rec, size=(h, w), mode="bilinear", align_corners=False)
    return TransmitResult(rec.clamp(0, 1), {"num_symbols": sym.shape[1] * b, "failed_codewords": 0})
