"""How each kind of link-level scheme crosses the air in `osnerf ota`: what it sends
(frame-sized symbol blocks) and how it scores what arrived, one :class:`OtaTransceiver` per
``semcodec.LINK_SCHEMES`` kind in :data:`TRANSCEIVERS`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from osnerf.cli import UsageError


def encode_image_bytes(image: np.ndarray, codec: str, quality: int) -> bytes:
    """[3, H, W] float in [0, 1] -> the codec's wire bytes (``semcodec.IMAGE_CODECS``, the
    baseline's settings, container stripped)."""
    from semcodec.image_codecs import encode_image

    return encode_image(image, codec, int(quality))


def decode_image_bytes(data: bytes, shape, codec: str) -> np.ndarray | None:
    """Wire bytes -> [3, H, W] float32, or None when undecodable (a lost image)."""
    from semcodec.image_codecs import decode_wire

    try:
        arr = decode_wire(data, codec, shape[1], shape[2])
    except ValueError:
        return None
    return np.asarray(arr, np.float32).transpose(2, 0, 1) / 255.0


def digital_blocks(images, args, cfg):
    """Per image: frame-sized LDPC blocks of its codec bytes. Returns (blocks, chunks)."""
    import phy.digital as dig

    mcs = dig.get_mcs(args.mcs)
    per_frame = dig.payload_capacity_bits(cfg.symbols_per_frame, mcs) // 8
    if per_frame < 1:
        raise UsageError(
            f"--symbols-per-frame {cfg.symbols_per_frame} holds no payload at --mcs {args.mcs}"
        )
    blocks, chunks = [], []
    for img in images:
        data = encode_image_bytes(img, args.image_codec, args.quality)
        parts = [data[i : i + per_frame] for i in range(0, len(data), per_frame)]
        syms = [dig.encode_bytes(c, mcs, num_symbols=cfg.symbols_per_frame).numpy() for c in parts]
        blocks.append(np.concatenate(syms).astype(np.complex64))
        chunks.append(parts)
    return blocks, chunks


def digital_receive(result, chunks, images, args, cfg):
    import phy.digital as dig
    import renderer

    out = []
    for b, (parts, img) in enumerate(zip(chunks, images)):
        x_hat, nv = result.blocks[b]
        frames = result.block_frames(b)
        got, ok_all, failed = [], True, 0
        for i, chunk in enumerate(parts):
            sl = slice(i * cfg.symbols_per_frame, (i + 1) * cfg.symbols_per_frame)
            if not frames[i].detected:
                ok_all, failed = False, failed + 1
                frames[i].crc_ok = False
                continue
            r = dig.decode_symbols(x_hat[sl], nv[sl], args.mcs, len(chunk))
            frames[i].crc_ok = bool(r.ok)
            if r.ok:
                got.append(r.payload)
            else:
                ok_all, failed = False, failed + 1
        decoded = decode_image_bytes(b"".join(got), img.shape, args.image_codec) if ok_all else None
        shown = decoded if decoded is not None else np.full_like(img, 0.5)
        out.append(
            {
                "psnr": renderer.psnr(shown, img),
                "decoded": decoded is not None,
                "bytes": sum(len(c) for c in parts),
                "frames_crc_failed": failed,
            }
        )
    return out


def jscc_blocks(images, args, cfg=None):
    import torch

    from phy import parse_cbr
    from semcodec import open_codec

    codec = open_codec(args.codec)
    cbr = parse_cbr(args.cbr)
    encs = [codec.encode(torch.from_numpy(img)[None], args.snr_db, cbr) for img in images]
    return [e.symbols[0].numpy() for e in encs], (encs, codec)


def decode_received(codec, x_hat: np.ndarray, noise_var: np.ndarray, meta, snr_db: float):
    """Zero-forced symbols [num_symbols] with their effective noise variance -> [1, 3, H, W]
    (the codec's one receiver convention, ``semcodec.Codec.decode`` with ``noise_var``: a
    version-2 codec sees each symbol's reliability, a version-1 codec AWGN-like symbols)."""
    import torch

    x = torch.from_numpy(np.asarray(x_hat, np.complex64))[None]
    nv = torch.from_numpy(np.asarray(noise_var, np.float32))[None]
    return codec.decode(x, meta, snr_db, noise_var=nv)


def jscc_receive(result, state, images, args=None, cfg=None):
    import renderer

    encs, codec = state

    out = []
    for b, (enc, img) in enumerate(zip(encs, images)):
        x_hat, nv = result.blocks[b]  # zero-forced symbols, their effective noise variance
        snr = result.snr_db_measured(b)
        snr_in = float(np.clip(snr if snr is not None else 0.0, *codec.snr_range_db))
        rec = decode_received(codec, x_hat, nv, enc.meta, snr_in)[0].numpy()
        out.append(
            {
                "psnr": renderer.psnr(rec, img),
                "decoded": True,
                "num_symbols": int(enc.meta.num_symbols),
                "cbr": float(enc.meta.cbr),
            }
        )
    return out


@dataclass(frozen=True)
class OtaTransceiver:
    """How one kind of link-level scheme crosses the air: ``send(images, args, cfg) ->
    (blocks, state)`` and ``receive(result, state, images, args, cfg) -> per-image stats``."""

    send: Callable
    receive: Callable
    uses_cbr: bool


TRANSCEIVERS = {  # keyed by semcodec's LinkScheme.kind, for the schemes marked over_the_air
    "digital": OtaTransceiver(digital_blocks, digital_receive, uses_cbr=False),
    "jscc": OtaTransceiver(jscc_blocks, jscc_receive, uses_cbr=True),
}


def transceiver(scheme: str) -> OtaTransceiver:
    from semcodec.evaluation import LINK_SCHEMES

    return TRANSCEIVERS[LINK_SCHEMES[scheme].kind]
