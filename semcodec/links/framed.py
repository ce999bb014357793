"""Link schemes over a framed link: the transmitter and the receiver apart, frame by frame.

A framed link (two radios, ``osnerf ota``) carries one block of channel symbols per image,
of any length, cut into frames of ``symbols_per_frame`` symbols, and says of each frame
whether it arrived. A :class:`FramedScheme` is the two halves of a link-level scheme around
such a link: ``transmit(images, settings) -> (blocks, state)`` makes the blocks, the link
carries them, and ``receive(received, state, images, settings)`` turns each
:class:`ReceivedBlock` into a :class:`FramedReception` (the image, its PSNR, the scheme's
numbers and one CRC verdict per frame). ``LinkScheme.framed`` holds the scheme's pair.

* digital: the image codec at ``quality`` (wire bytes; the image downscaled by ``scale``
  and upscaled at the receiver), cut into frame-sized chunks; each
  chunk is its own CRC + 5G LDPC + QAM block of one frame at ``mcs``
  (``phy.digital.encode_bytes``), so every frame has its own CRC. An image shows only when
  every frame arrived and passed its CRC; otherwise mid-grey (:data:`LOST_IMAGE_VALUE`).
* jscc: the semantic codec's symbols at ``cbr``; the receiver decodes the zero-forced
  symbols with their noise variance (:func:`semcodec.decode_received`) and the link's
  measured SNR, clipped to the codec's SNR range (0 dB when no frame arrived).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from common import psnr
from phy.digital import decode_symbols, encode_bytes, get_mcs, payload_capacity_bits
from semcodec.contract.box_focus import decode_received, encode_with_focus
from semcodec.contract.protocol import symbol_budget
from semcodec.digital.image_codecs import SCALES, downscale, encode_image
from semcodec.digital.link import decode_or_grey


@dataclass(frozen=True)
class FramedSettings:
    """What both ends of a framed scheme agree on before anything is sent.

    Attributes:
        snr_db: the air's average Es/N0 in dB (the JSCC encoder's SNR input).
        symbols_per_frame: channel symbols per frame, >= 1.
        mcs: digital: a name of ``phy.digital.MCS_TABLE``.
        image_codec: digital: a name of ``semcodec.digital.IMAGE_CODECS``.
        quality: digital: the image codec's quality setting.
        scale: digital: the image is sent downscaled by this factor of
            ``semcodec.digital.image_codecs.SCALES`` and upscaled at the receiver (1: whole).
        cbr: jscc: channel symbols per source value.
        codec: jscc: the semantic codec (``semcodec.open_codec``); None for digital.
    """

    snr_db: float
    symbols_per_frame: int
    mcs: str = "qpsk-1/2"
    image_codec: str = "avif"
    quality: int = 50
    scale: int = 1
    cbr: float = 1 / 16
    codec: object | None = None

    def __post_init__(self):
        if int(self.symbols_per_frame) != self.symbols_per_frame or self.symbols_per_frame < 1:
            raise ValueError(
                f"symbols_per_frame must be an integer >= 1, got {self.symbols_per_frame!r}"
            )
        if self.scale not in SCALES:
            raise ValueError(f"scale must be one of {SCALES}, got {self.scale!r}")


@dataclass
class ReceivedBlock:
    """One image's block as the framed link delivered it.

    Attributes:
        x_hat: [num_symbols] complex64, zero-forced (unbiased); 0 where a frame was lost.
        noise_var: [num_symbols] float32, the effective noise variance of each symbol.
        frames_detected: one bool per frame; frame i holds symbols
            ``[i * symbols_per_frame, (i + 1) * symbols_per_frame)``.
        snr_db_measured: the receiver's pilot SNR over the block's frames (None: all lost).
    """

    x_hat: np.ndarray
    noise_var: np.ndarray
    frames_detected: list[bool]
    snr_db_measured: float | None = None


@dataclass
class FramedReception:
    """What the receiver made of one block.

    Attributes:
        image: [3, height, width] float32, the image shown (mid-grey when lost).
        psnr: PSNR of ``image`` against the image sent (peak 1.0).
        stats: the scheme's per-image numbers for a result file (digital: ``decoded``,
            ``bytes``, ``frames_crc_failed``; jscc: ``decoded``, ``num_symbols``,
            ``symbol_budget``, ``cbr``).
        frames_crc_ok: one per frame: its CRC verdict (False when the frame was lost), or
            None where the scheme has no CRC (jscc).
    """

    image: np.ndarray
    psnr: float
    stats: dict = field(default_factory=dict)
    frames_crc_ok: list[bool | None] = field(default_factory=list)


@dataclass(frozen=True)
class FramedScheme:
    """A link-level scheme's transmitter and receiver around a framed link.

    Attributes:
        transmit: ``(images [batch, 3, height, width] float32, FramedSettings) -> (blocks,
            state)``: one [num_symbols] complex64 block per image, and what the receiver is
            told besides the symbols (side information).
        receive: ``(received: list[ReceivedBlock], state, images, FramedSettings) ->
            list[FramedReception]``, one per image.
    """

    transmit: Callable
    receive: Callable


def frame_payload_bytes(symbols_per_frame: int, mcs: str) -> int:
    """Payload bytes one digital frame carries (CRC and LDPC included in the frame)."""
    return payload_capacity_bits(symbols_per_frame, get_mcs(mcs)) // 8


def _digital_transmit(images, settings: FramedSettings):
    """Per image: its codec bytes in frame-sized chunks, one LDPC block each. The state is
    each image's chunk sizes in bytes (the receiver's side information)."""
    mcs = get_mcs(settings.mcs)
    spf = settings.symbols_per_frame
    per_frame = frame_payload_bytes(spf, settings.mcs)
    if per_frame < 1:
        raise ValueError(f"symbols_per_frame={spf} holds no payload at mcs {settings.mcs!r}")
    blocks, sizes = [], []
    for img in np.asarray(images, np.float32):
        small = downscale(img, settings.scale)
        data = encode_image(small, settings.image_codec, int(settings.quality))
        parts = [data[i : i + per_frame] for i in range(0, len(data), per_frame)]
        syms = [encode_bytes(c, mcs, num_symbols=spf).numpy() for c in parts]
        blocks.append(np.concatenate(syms).astype(np.complex64))
        sizes.append([len(c) for c in parts])
    return blocks, sizes


def _digital_frames(block: ReceivedBlock, sizes: list[int], settings: FramedSettings):
    """Decode each frame of one block: (the payload bytes of those that passed, CRC verdicts)."""
    spf = settings.symbols_per_frame
    payloads, crc_ok = [], []
    for i, num_bytes in enumerate(sizes):
        if not block.frames_detected[i]:
            crc_ok.append(False)
            continue
        sl = slice(i * spf, (i + 1) * spf)
        r = decode_symbols(block.x_hat[sl], block.noise_var[sl], settings.mcs, num_bytes)
        crc_ok.append(bool(r.ok))
        if r.ok:
            payloads.append(r.payload)
    return payloads, crc_ok


def _digital_receive(received, sizes, images, settings: FramedSettings):
    out = []
    for block, frame_sizes, img in zip(received, sizes, np.asarray(images, np.float32)):
        payloads, crc_ok = _digital_frames(block, frame_sizes, settings)
        data = b"".join(payloads) if all(crc_ok) else None
        shown, decoded = decode_or_grey(data, img.shape, settings.image_codec, settings.scale)
        shown = shown.numpy()
        stats = {
            "decoded": decoded,
            "bytes": sum(frame_sizes),
            "frames_crc_failed": sum(not ok for ok in crc_ok),
        }
        out.append(FramedReception(shown, psnr(shown, img), stats, crc_ok))
    return out


def _jscc_transmit(images, settings: FramedSettings):
    """Per image: the codec's symbols at ``cbr`` (tiled and padded where the codec declares
    an input size). The state is each image's ``Encoded``."""
    codec = settings.codec
    encs = [
        encode_with_focus(codec, torch.from_numpy(img)[None], settings.snr_db, settings.cbr)
        for img in np.asarray(images, np.float32)
    ]
    return [e.symbols[0].numpy() for e in encs], encs


def _jscc_receive(received, encs, images, settings: FramedSettings):
    codec = settings.codec
    out = []
    for block, enc, img in zip(received, encs, np.asarray(images, np.float32)):
        snr = block.snr_db_measured
        snr_in = float(np.clip(snr if snr is not None else 0.0, *codec.snr_range_db))
        x = torch.from_numpy(np.asarray(block.x_hat, np.complex64))[None]
        nv = torch.from_numpy(np.asarray(block.noise_var, np.float32))[None]
        rec = decode_received(codec, x, enc.meta, snr_in, noise_var=nv)[0].numpy()
        stats = {
            "decoded": True,
            "num_symbols": int(enc.meta.num_symbols),
            "symbol_budget": symbol_budget(settings.cbr, *img.shape[-2:]),
            "cbr": float(enc.meta.cbr),
            "side_info_bits": int(enc.meta.side_info_bits()),
        }
        crc = [None] * len(block.frames_detected)
        out.append(FramedReception(rec, psnr(rec, img), stats, crc))
    return out


DIGITAL_FRAMED = FramedScheme(_digital_transmit, _digital_receive)
JSCC_FRAMED = FramedScheme(_jscc_transmit, _jscc_receive)
