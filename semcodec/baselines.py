"""The schemes a JSCC is judged against, and the JSCC itself, on one interface.

Every ``transmit_*`` takes images [batch, 3, height, width] float32 in [0, 1] and returns a
:class:`TransmitResult` (received images of the same shape + stats).

* digital: image codec (AVIF by default, wire bytes: container stripped) at the byte
  budget the MCS allows in ``num_symbols`` (``phy.digital.payload_capacity_bits``), then
  phy.digital's CRC + 5G LDPC + QAM through the same link. ``mcs="auto"`` (honest: the
  MCS from a shipped calibration table, no CSI at the transmitter), ``"genie"`` (a bound:
  the best MCS for this very draw) or a fixed MCS name (the cliff); see
  :func:`transmit_digital`. A lost image (any payload codeword failing its CRC, or a
  budget too small for the codec's lowest quality at every scale) is received as mid-grey
  (0.5 everywhere): the receiver has nothing better to show.
* ideal: the codec at capacity, ``num_symbols * log2(1 + snr)`` bits, error free.

Both send the best file of the image that fits the budget over quality and scale
(:func:`semcodec.image_codecs.encode_scaled_to_budget`: below some budget a downscaled image,
upscaled at the receiver); each image's scale is in the stats.
* analog: uncoded pixels; each image's values standardised (mean and std sent as side
  information), paired into complex symbols, LMMSE-scaled at the receiver.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor
from torch.nn import functional as F

from common import psnr
from phy import Channel, FlatLink, power_normalize
from semcodec.box_focus import decode_received, encode_with_focus
from semcodec.codec import Codec, Encoded, check_images
from semcodec.image_codecs import (
    IMAGE_CODECS,
    RESAMPLE_FILTER,
    decode_scaled,
    encode_scaled_to_budget,
    smallest_files,
)

LOST_IMAGE_VALUE = 0.5


@dataclass
class TransmitResult:
    """Received images [batch, 3, height, width] float32 and stats (sums over the batch, and lists per image)."""

    images: Tensor
    stats: dict = field(default_factory=dict)

    def __iter__(self):  # (images, stats) = result
        return iter((self.images, self.stats))


def _run_link(link, x: Tensor, snr_db, generator):
    """(unbiased x_hat, noise_var [batch, num_symbols]) from a phy link or a bare phy channel
    (which gets a one-tap ZF receiver with perfect CSI)."""
    if isinstance(link, Channel):
        link = FlatLink(link, csi="perfect", equalizer="zf")
    out = link(x, snr_db, generator=generator)
    return out.x_hat, out.noise_var


REFINE_STEPS = 50
"""Adam steps of :func:`refine_symbols` by default (each step runs the decoder forward and
backward once per image)."""
REFINE_LR = 0.03
"""Adam step of :func:`refine_symbols`, relative to the symbols' RMS per real dimension."""


def refine_symbols(
    codec: Codec,
    images: Tensor,
    encoded: Encoded,
    link,
    snr_db,
    steps: int = REFINE_STEPS,
    lr: float = REFINE_LR,
    generator: torch.Generator | None = None,
    decoder_snr_db=None,
    pixel_weights: Tensor | None = None,
) -> Encoded:
    """Transmitter-side refinement of the JSCC's symbols for this very image.

    The encoder is amortised: one network for every image. The transmitter can do better for
    the image it holds, because it knows the decoder (the shared knowledge base), the
    channel's kind (its fading distribution) and the average SNR; it does not know the draw
    the image will meet. Starting from ``encoded``, ``steps`` Adam steps on the symbols
    (before power normalisation) lower the MSE of the decoded image over draws of ``link``
    from the transmitter's own ``generator``: a stochastic descent on the expected
    distortion, with the same power per image as the encoder's symbols. The receiver and the
    side information are unchanged (``meta`` is kept); the cost is ``steps`` decoder passes,
    forward and backward, at the transmitter. This is the amortisation gap closed at
    inference (stochastic latent refinement in learned compression).

    Args:
        encoded: ``codec.encode(images, ...)`` (whole images or focus mode).
        link: what the transmitter simulates: a ``phy`` link or bare channel, as for
            :func:`transmit_jscc`. Its draws come from ``generator``, never the real link's.
        snr_db: the average SNR the simulated link runs at.
        steps: Adam steps, >= 0 (0 returns ``encoded``).
        decoder_snr_db: the SNR the receiver's decoder is told (default ``snr_db``).
        pixel_weights: optional [batch, 1, height, width] weights of the squared error (the
            demanded objects above the rest); default uniform.
    Returns:
        :class:`Encoded` with the refined unit-power symbols and the same ``meta``.
    """
    if steps < 0:
        raise ValueError(f"steps must be >= 0, got {steps}")
    if steps and not hasattr(codec, "decode_differentiable"):
        raise ValueError(f"codec {codec.name} cannot refine symbols (no decode_differentiable)")
    if not lr > 0:
        raise ValueError(f"lr must be > 0, got {lr}")
    if steps == 0:
        return encoded
    x = check_images(images)
    b = x.shape[0]
    snr = codec._snr(snr_db, b)
    dec_snr = snr if decoder_snr_db is None else codec._snr(decoder_snr_db, b)
    meta = encoded.meta
    v = torch.view_as_real(encoded.symbols.to(torch.complex64)).clone()  # [b, n, 2]
    scale = float(v.pow(2).mean().sqrt())
    v.requires_grad_(True)
    opt = torch.optim.Adam([v], lr=lr * scale)
    with torch.enable_grad():
        for _ in range(steps):
            sym = power_normalize(torch.view_as_complex(v))
            x_hat, nv = _run_link(link, sym, snr, generator)
            y = codec.decode_differentiable(x_hat, meta, dec_snr, nv)
            err = (y - x) ** 2 if pixel_weights is None else (y - x) ** 2 * pixel_weights
            (v.grad,) = torch.autograd.grad(err.mean(), [v])  # the weights stay as they are
            opt.step()
    sym = power_normalize(torch.view_as_complex(v.detach()))
    return Encoded(sym.to(torch.complex64), meta)


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
    encoded: Encoded | None = None,
) -> TransmitResult:
    """Images through a semantic codec (any :class:`semcodec.SemanticCodec`) and the link.
    The decoder gets the link's unbiased estimates with their per-symbol noise variance and
    the average SNR (the contract's convention). With a ``mask`` and a codec without
    ``supports_focus``, the objects' box is sent at the same symbol budget
    (:func:`semcodec.encode_with_focus`).

    Args:
        link: ``phy.FlatLink``/``phy.OFDMLink`` with ``equalizer="zf"`` (or a bare ``phy``
            channel: perfect-CSI ZF).
        snr_db: float or [batch], the average Es/N0 (the encoder's and decoder's SNR input).
        rx_codec: the receiver's codec (default the transmitter's); hashes must match.
        encoded: ``codec.encode(images, snr_db, cbr, mask, demand_weights)`` when the caller
            has it already (several draws of one image), else computed here.
    """
    x = check_images(images)
    enc = encoded or encode_with_focus(codec, x, snr_db, cbr, mask, demand_weights)
    with torch.no_grad():
        x_hat, nv = _run_link(link, enc.symbols, snr_db, generator)
    rx = rx_codec or codec
    y = decode_received(rx, x_hat, enc.meta, snr_db, expected_sha256=codec.sha256, noise_var=nv)
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


def decode_or_grey(
    data: bytes | None, shape, image_codec: str, scale: int = 1
) -> tuple[Tensor, bool]:
    """Wire bytes of an image sent at ``scale`` -> ([3, H, W] float32 image, True), or
    (mid-grey, False) when they are None (nothing arrived) or undecodable."""
    if data is None:
        return _grey(shape), False
    try:
        a = decode_scaled(data, image_codec, shape[1], shape[2], scale)
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
    """The codec at the capacity rate ``num_symbols * log2(1 + snr)`` bits, no errors (the
    best file over quality and scale)."""
    x = check_images(images)
    n = _check_num_symbols(num_symbols)
    _check_codec(image_codec)
    bits = int(math.floor(n * math.log2(1.0 + 10.0 ** (float(snr_db) / 10.0))))
    out, qualities, sizes, scales = [], [], [], []
    for img in x:
        data, q, scale = encode_scaled_to_budget(img, bits // 8, image_codec)
        rec, _ = decode_or_grey(data, img.shape, image_codec, scale or 1)
        out.append(rec)
        qualities.append(q)
        scales.append(scale)
        sizes.append(0 if data is None else len(data))
    return TransmitResult(
        torch.stack(out),
        {
            "budget_bits": bits,
            "bits": 8 * sum(sizes),
            "num_symbols": n * len(x),
            "quality": qualities,
            "scale": scales,
            "resample_filter": RESAMPLE_FILTER,
            "lost_images": sum(q is None for q in qualities),
            "failed_codewords": 0,
        },
    )


AUTO = "auto"
GENIE = "genie"
ENVELOPE = "envelope"  # the old name of the genie (an oracle, kept for old configs)
MCS_MODES = (AUTO, GENIE)


def _lost(img: Tensor, mcs, why: str, failed: int = 0) -> tuple[Tensor, bool, dict]:
    info = {
        "mcs": mcs,
        "quality": None,
        "scale": None,
        "bits": 0,
        "failed_codewords": failed,
        "lost": why,
    }
    return _grey(img.shape), False, info


def _send_digital(img: Tensor, mcs: str, link, snr_db, n: int, image_codec: str, seed: int):
    """One image at one MCS, one shot. Returns (received [3,H,W], ok, info); ``info["lost"]``
    is None, ``"budget"`` (nothing fitted) or ``"channel"`` (a payload codeword failed)."""
    from phy.digital import payload_capacity_bits, transmit_bytes

    budget = payload_capacity_bits(n, mcs) // 8
    data, q, scale = encode_scaled_to_budget(img, budget, image_codec)
    if data is None:
        return _lost(img, mcs, "budget")
    r = transmit_bytes(
        data, mcs, link, snr_db, generator=torch.Generator().manual_seed(seed), num_symbols=n
    )
    rec, ok = decode_or_grey(r.payload if r.ok else None, img.shape, image_codec, scale)
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
            "scale": scale,
            "bits": 8 * len(data),
            "failed_codewords": failed,
            "num_codewords": r.num_codewords,
            "lost": None if ok else "channel",
        },
    )


def _genie(img, start: int, names, link, snr_db, n, image_codec, seed):
    """The oracle: with this draw's fade and noise (the same seed for every try), the best
    image over the MCSs that decode, searching from ``start`` (up while they decode, else
    down until one does). Same draw as honest at ``start`` -> never below it."""
    tries = {}

    def attempt(i):
        if i not in tries:
            tries[i] = _send_digital(img, names[i], link, snr_db, n, image_codec, seed)
        return tries[i]

    if attempt(start)[1]:
        i = start + 1
        while i < len(names) and attempt(i)[1]:
            i += 1
    else:
        i = start - 1
        while i >= 0 and not attempt(i)[1]:
            i -= 1
    good = [(k, t) for k, t in tries.items() if t[1]]
    failed = sum(t[2]["failed_codewords"] for t in tries.values())
    if not good:
        why = "budget" if all(t[2]["lost"] == "budget" for t in tries.values()) else "channel"
        rec, ok, info = _lost(img, None, why, failed)
    else:
        _, (rec, ok, info) = max(good, key=lambda kt: (psnr(kt[1][0], img), kt[0]))
        info = {**info, "failed_codewords": failed}
    info["tries"] = len(tries)
    return rec, ok, info


def transmit_digital(
    images: Tensor,
    link,
    snr_db: float,
    num_symbols: int,
    mcs: str = AUTO,
    image_codec: str = "avif",
    generator: torch.Generator | None = None,
    channel: str | None = None,
) -> TransmitResult:
    """Image codec + CRC + 5G LDPC + QAM through ``link`` in ``num_symbols`` symbols per image.

    ``mcs``:

    * ``"auto"`` (the honest link, ``digital``): no CSI at the transmitter. The MCS comes
      from the shipped calibration table (:mod:`semcodec.digital_calibration`) given the
      channel kind, the average ``snr_db``, ``num_symbols``, the image size and the sizes of
      the image's lowest-quality file at each scale: the MCS of highest expected PSNR over
      the channel's fading distribution. One shot: a failed codeword loses the image (an
      outage).
    * ``"genie"`` (``digital_genie``, a bound; ``"envelope"`` is its old name): knows this
      draw's fade and noise; the best image over every MCS that decodes on the same draw,
      searched from the honest choice, so it is never below ``"auto"`` on the same draws.
    * a name in ``phy.digital.MCS_TABLE``: that MCS always (shows the cliff).

    The codec's wire bytes are sent (container stripped, :mod:`semcodec.image_codecs`): the
    file of highest PSNR over quality and scale that fits the MCS's payload (a downscaled
    image where that is better, upscaled at the receiver). A lost image is mid-grey:
    ``"budget"`` when no file fits, ``"channel"`` when a payload codeword failed.

    Args:
        images: [batch, 3, height, width] float32 in [0, 1].
        link: ``phy.FlatLink`` / ``phy.OFDMLink`` with ``equalizer="zf"``.
        snr_db: average Es/N0 in dB (what the transmitter knows).
        num_symbols: channel symbols per image.
        image_codec: a name of ``semcodec.IMAGE_CODECS``.
        generator: the draws; each image takes one seed from it (the same seed for every
            try of the genie, so the same fade and noise).
        channel: ``phy.CHANNELS`` name of the link's channel for ``"auto"`` (and the genie's
            starting point) (default: told from ``link``; see ``phy.channel_kind``). Needed
            for links whose channel type does not tell (``raytraced`` per-position links); a
            genie without it searches from the lowest MCS.
    Returns:
        TransmitResult; stats: bits, num_symbols, failed_codewords, lost_images,
        views_lost {"budget", "channel"}, mcs / quality / scale / expected_psnr per image,
        resample_filter,
        mcs_choice ("auto", "genie (bound)" or "fixed"), calibration (how the channel is
        calibrated).
    """
    x = check_images(images)
    n = _check_num_symbols(num_symbols)
    _check_codec(image_codec)
    mode = _mcs_mode(mcs)
    kind = _calibrated_channel(mode, link, channel)
    table = calibration = None
    if kind is not None:
        from semcodec.digital_calibration import load_calibration

        table = load_calibration()
        calibration = table.source(kind)
    gen = generator or torch.Generator().manual_seed(0)
    out, infos = [], []
    for img in x:
        seed = int(torch.randint(0, 2**62, (1,), generator=gen))
        rec, ok, info = _send_image(img, mode, kind, table, link, snr_db, n, image_codec, seed)
        info["ok"] = ok
        out.append(rec)
        infos.append(info)
    stats = _digital_stats(infos, n * len(x), mode)
    if kind is not None:
        stats["channel"] = kind
        stats["calibration"] = calibration
        stats["expected_psnr"] = [i["expected_psnr"] for i in infos]
    if mode == GENIE:
        stats["tries"] = sum(i["tries"] for i in infos)
    return TransmitResult(torch.stack(out), stats)


def _send_image(img, mode, kind, table, link, snr_db, n: int, image_codec: str, seed: int):
    """One image at the MCS that ``mode`` gives it: a fixed one; ``"auto"``'s choice from the
    calibration ``table`` for channel ``kind``; or the genie's search from that choice (from
    the lowest MCS without a ``kind``). Returns :func:`_send_digital`'s (received, ok, info),
    with ``info["expected_psnr"]`` where the table chose."""
    from phy.digital import MCS_TABLE

    if mode not in MCS_MODES:
        return _send_digital(img, mode, link, snr_db, n, image_codec, seed)
    names = list(MCS_TABLE)
    choice, expected = names[0], None
    if kind is not None:
        h, w = img.shape[1:]
        min_bytes = smallest_files(img, image_codec)
        choice, expected = table.choose_mcs(kind, snr_db, n, h * w, image_codec, min_bytes)
        expected = round(expected, 3)
    if mode == AUTO:
        rec, ok, info = _send_digital(img, choice, link, snr_db, n, image_codec, seed)
    else:
        start = names.index(choice)
        rec, ok, info = _genie(img, start, names, link, snr_db, n, image_codec, seed)
    info["expected_psnr"] = expected
    return rec, ok, info


def _mcs_mode(mcs: str) -> str:
    """``"auto"``, ``"genie"`` (also for its old name ``"envelope"``) or a fixed MCS name;
    KeyError listing the choices for anything else."""
    from phy.digital import MCS_TABLE, get_mcs

    mode = GENIE if mcs == ENVELOPE else mcs
    if mode not in MCS_MODES:
        try:
            get_mcs(mode)
        except KeyError:
            names = list(MCS_TABLE)
            raise KeyError(f"mcs must be 'auto', 'genie' or one of {names}, got {mcs!r}") from None
    return mode


def _calibrated_channel(mode: str, link, channel: str | None) -> str | None:
    """The calibration table's channel kind the MCS is chosen for: ``"auto"`` needs one
    (KeyError when the link does not tell), the genie uses it when there is one (without it
    the genie searches from the lowest MCS), a fixed MCS none."""
    from phy import assumed_channel, channel_kind

    if mode == AUTO:
        return assumed_channel(channel or channel_kind(link))
    if mode == GENIE:
        try:
            return assumed_channel(channel or channel_kind(link))
        except KeyError:
            return None
    return None


def _digital_stats(infos: list[dict], num_symbols: int, mode: str) -> dict:
    """The batch's stats from each image's info: sums, losses by cause, per-image lists."""
    lost = {"budget": 0, "channel": 0}
    for i in infos:
        if i["lost"]:
            lost[i["lost"]] += 1
    return {
        "bits": sum(i["bits"] for i in infos),
        "num_symbols": num_symbols,
        "failed_codewords": sum(i["failed_codewords"] for i in infos),
        "lost_images": sum(not i["ok"] for i in infos),
        "views_lost": lost,
        "mcs": [i["mcs"] for i in infos],
        "quality": [i["quality"] for i in infos],
        "scale": [i["scale"] for i in infos],
        "resample_filter": RESAMPLE_FILTER,
        "mcs_choice": {AUTO: "auto", GENIE: "genie (bound)"}.get(mode, "fixed"),
    }


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
