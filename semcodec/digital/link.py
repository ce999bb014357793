"""The digital baselines: an image codec's file through CRC + 5G LDPC + QAM, and the same
codec at capacity.

* digital (:func:`transmit_digital`): image codec (AVIF by default, wire bytes: container
  stripped) at the byte budget the MCS allows in ``num_symbols``
  (``phy.digital.payload_capacity_bits``), then phy.digital's CRC + 5G LDPC + QAM through
  the same link. ``mcs="auto"`` (honest: the MCS from a shipped calibration table, no CSI at
  the transmitter), ``"genie"`` (a bound: the best MCS for this very draw) or a fixed MCS
  name (the cliff). A lost image (any payload codeword failing its CRC, or a budget too
  small for the codec's lowest quality at every scale) is received as mid-grey
  (:data:`semcodec.contract.transmit.LOST_IMAGE_VALUE`).
* ideal (:func:`transmit_ideal`): the codec at capacity, ``num_symbols * log2(1 + snr)``
  bits, error free.

Both send the best file of the image that fits the budget over quality and scale
(:func:`semcodec.digital.image_codecs.encode_scaled_to_budget`: below some budget a downscaled
image, upscaled at the receiver); each image's scale is in the stats.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from common import psnr, to_chw
from phy import assumed_channel, channel_kind
from phy.digital import MCS_TABLE, get_mcs, payload_capacity_bits, transmit_bytes
from semcodec.contract.protocol import check_images
from semcodec.contract.transmit import TransmitResult, check_num_symbols, grey
from semcodec.digital.calibration import load_calibration
from semcodec.digital.image_codecs import (
    IMAGE_CODECS,
    RESAMPLE_FILTER,
    decode_scaled,
    encode_scaled_to_budget,
    smallest_files,
)


def decode_or_grey(
    data: bytes | None, shape, image_codec: str, scale: int = 1
) -> tuple[Tensor, bool]:
    """Wire bytes of an image sent at ``scale`` -> ([3, H, W] float32 image, True), or
    (mid-grey, False) when they are None (nothing arrived) or undecodable."""
    if data is None:
        return grey(shape), False
    try:
        a = decode_scaled(data, image_codec, shape[1], shape[2], scale)
    except ValueError:
        return grey(shape), False
    return to_chw(a.astype(np.float32) / 255.0), True


def _check_codec(image_codec: str) -> str:
    if image_codec not in IMAGE_CODECS:
        raise KeyError(f"unknown image codec {image_codec!r}; known: {sorted(IMAGE_CODECS)}")
    return image_codec


def transmit_ideal(
    images: Tensor, snr_db: float, num_symbols: int, image_codec: str = "avif"
) -> TransmitResult:
    """The codec at the capacity rate ``num_symbols * log2(1 + snr)`` bits, no errors (the
    best file over quality and scale)."""
    x = check_images(images)
    n = check_num_symbols(num_symbols)
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
    return grey(img.shape), False, info


def _send_digital(img: Tensor, mcs: str, link, snr_db, n: int, image_codec: str, seed: int):
    """One image at one MCS, one shot. Returns (received [3,H,W], ok, info); ``info["lost"]``
    is None, ``"budget"`` (nothing fitted) or ``"channel"`` (a payload codeword failed)."""
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
    plan_snr_db=None,
    snr_error_db: float = 0.0,
) -> TransmitResult:
    """Image codec + CRC + 5G LDPC + QAM through ``link`` in ``num_symbols`` symbols per image.

    ``mcs``:

    * ``"auto"`` (the honest link, ``digital``): no CSI at the transmitter. The MCS comes
      from the shipped calibration table (:mod:`semcodec.digital.calibration`) given the
      channel kind, the average ``snr_db``, ``num_symbols``, the image size and the sizes of
      the image's lowest-quality file at each scale: the MCS of highest expected PSNR over
      the channel's fading distribution. One shot: a failed codeword loses the image (an
      outage).
    * ``"genie"`` (``digital_genie``, a bound; ``"envelope"`` is its old name): knows this
      draw's fade and noise; the best image over every MCS that decodes on the same draw,
      searched from the honest choice, so it is never below ``"auto"`` on the same draws.
    * a name in ``phy.digital.MCS_TABLE``: that MCS always (shows the cliff).

    The codec's wire bytes are sent (container stripped, :mod:`semcodec.digital.image_codecs`): the
    file of highest PSNR over quality and scale that fits the MCS's payload (a downscaled
    image where that is better, upscaled at the receiver). A lost image is mid-grey:
    ``"budget"`` when no file fits, ``"channel"`` when a payload codeword failed.

    Args:
        images: [batch, 3, height, width] float32 in [0, 1].
        link: ``phy.FlatLink`` / ``phy.OFDMLink`` with ``equalizer="zf"``.
        snr_db: the channel's true average Es/N0 in dB (what the link applies).
        num_symbols: channel symbols per image.
        image_codec: a name of ``semcodec.digital.IMAGE_CODECS``.
        generator: the draws; each image takes one seed from it (the same seed for every
            try of the genie, so the same fade and noise).
        channel: ``phy.CHANNELS`` name of the link's channel for ``"auto"`` (and the genie's
            starting point) (default: told from ``link``; see ``phy.channel_kind``). Needed
            for links whose channel type does not tell (``raytraced`` per-position links); a
            genie without it searches from the lowest MCS.
        plan_snr_db: what the transmitter believes the average SNR is, the MCS's input: a
            float or one per image (default ``snr_db``: exact knowledge).
        snr_error_db: the standard deviation of that belief's error (dB) that ``"auto"``
            plans over (:meth:`DigitalCalibration.choose_mcs`); 0 plans as if it were exact.
    Returns:
        TransmitResult; stats: bits, num_symbols, failed_codewords, lost_images,
        views_lost {"budget", "channel"}, mcs / quality / scale / expected_psnr /
        forecast_loss (the planner's probability that the image is lost) per image,
        resample_filter, mcs_choice ("auto", "genie (bound)" or "fixed"), calibration (how
        the channel is calibrated).
    """
    x = check_images(images)
    n = check_num_symbols(num_symbols)
    _check_codec(image_codec)
    mode = _mcs_mode(mcs)
    kind = _calibrated_channel(mode, link, channel)
    table, calibration = _calibration_of(kind)
    if not snr_error_db >= 0:
        raise ValueError(f"snr_error_db must be >= 0, got {snr_error_db}")
    plans = _per_image(snr_db if plan_snr_db is None else plan_snr_db, len(x))
    gen = generator or torch.Generator().manual_seed(0)
    out, infos = [], []
    for img, plan in zip(x, plans):
        seed = int(torch.randint(0, 2**62, (1,), generator=gen))
        rec, ok, info = _send_image(
            img, mode, kind, table, link, snr_db, n, image_codec, seed, plan, snr_error_db
        )
        out.append(rec)
        infos.append({**info, "ok": ok})
    stats = _digital_stats(infos, n * len(x), mode)
    if kind is not None:
        stats.update(channel=kind, calibration=calibration)
        stats.update({k: [i[k] for i in infos] for k in ("expected_psnr", "forecast_loss")})
    if mode == GENIE:
        stats["tries"] = sum(i["tries"] for i in infos)
    return TransmitResult(torch.stack(out), stats)


def _calibration_of(kind: str | None):
    """(the calibration table, how ``kind`` is calibrated), or (None, None) without a kind."""
    if kind is None:
        return None, None

    table = load_calibration()
    return table, table.source(kind)


def _per_image(snr_db, batch: int) -> list[float]:
    """A float or one value per image -> one float per image."""
    if isinstance(snr_db, (int, float)):
        return [float(snr_db)] * batch
    v = [float(s) for s in torch.as_tensor(snr_db, dtype=torch.float64).reshape(-1)]
    if len(v) == 1:
        return v * batch
    if len(v) != batch:
        raise ValueError(f"plan_snr_db: {len(v)} values for {batch} images")
    return v


def _send_image(
    img,
    mode,
    kind,
    table,
    link,
    snr_db,
    n: int,
    image_codec: str,
    seed: int,
    plan_snr_db: float,
    snr_error_db: float = 0.0,
):
    """One image at the MCS that ``mode`` gives it: a fixed one; ``"auto"``'s choice from the
    calibration ``table`` for channel ``kind`` planned at ``plan_snr_db`` (over an error of
    ``snr_error_db``); or the genie's search from that choice (from the lowest MCS without a
    ``kind``). Returns :func:`_send_digital`'s (received, ok, info), with
    ``info["expected_psnr"]`` and ``info["forecast_loss"]`` where the table chose."""
    if mode not in MCS_MODES:
        return _send_digital(img, mode, link, snr_db, n, image_codec, seed)
    names = list(MCS_TABLE)
    choice, expected, forecast = names[0], None, None
    if kind is not None:
        h, w = img.shape[1:]
        min_bytes = smallest_files(img, image_codec)
        choice, expected = table.choose_mcs(
            kind, plan_snr_db, n, h * w, image_codec, min_bytes, snr_error_db
        )
        expected = round(expected, 3)
        forecast = table.image_loss(
            kind, choice, plan_snr_db, n, image_codec, min_bytes, snr_error_db
        )
    if mode == AUTO:
        rec, ok, info = _send_digital(img, choice, link, snr_db, n, image_codec, seed)
    else:
        start = names.index(choice)
        rec, ok, info = _genie(img, start, names, link, snr_db, n, image_codec, seed)
    info["expected_psnr"] = expected
    info["forecast_loss"] = forecast
    return rec, ok, info


def _mcs_mode(mcs: str) -> str:
    """``"auto"``, ``"genie"`` (also for its old name ``"envelope"``) or a fixed MCS name;
    KeyError listing the choices for anything else."""
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
