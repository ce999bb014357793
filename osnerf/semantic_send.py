"""The semantic (JSCC) schemes' transmitter and receiver for one run: each view encoded
(optionally refined against the transmitter's own model of the channel), sent in its
planned copies through its link, MRC-combined and decoded."""

from __future__ import annotations

import time
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import torch
import torch.nn.functional as F

import phy
from osnerf.scheme_types import Transmission, scheme_seed
from phy import combine_repetitions
from semcodec import codec_limits, decode_received, encode_with_focus, refinement_status
from semcodec.jscc import for_fusion, receiver_mask, refine_symbols


def _send_blocks(link, symbols: torch.Tensor, snr_db: float, repetitions: int, generator):
    """``repetitions`` copies of a [1, n] block through ``link``, MRC-combined."""

    out = link(symbols.expand(repetitions, -1).contiguous(), snr_db, generator=generator)
    return combine_repetitions(out.x_hat, out.noise_var)


REFINE_OUTSIDE_WEIGHT = 0.05
"""With ``refine_steps``, the weight of an on-demand view's pixels outside the demanded
objects (inside the sent box) in the refinement's squared error; the objects' pixels weigh
1 (times their demand weight): the NeRF is scored on the objects, and the box's rim only
has to keep the background plausible."""
_MODEL_LINKS: dict = {}


def refine_model_link(channel: str):
    """The link the jscc transmitter simulates when it refines its symbols
    (:func:`semcodec.jscc.refine_symbols`): a statistical model of the run's channel, drawn from
    the transmitter's own generator, never the real link: ``phy.symbol_model`` of the run's
    channel (the channel itself where ``phy`` draws it from a flat distribution; fast
    Rayleigh for TDL/CDL over OFDM, for ``raytraced`` and for ``ota``, whose symbols ride
    independently faded subcarriers), one tap per symbol with perfect CSI."""

    name = phy.symbol_model(channel)
    if name not in _MODEL_LINKS:
        _MODEL_LINKS[name] = phy.channel_link(name)
    return _MODEL_LINKS[name]


@dataclass
class _Copies:
    """``repetitions`` copies through ``link`` at ``snr_db``, MRC-combined, as a link
    (what :func:`_send_blocks` does to the real symbols)."""

    link: object
    snr_db: float
    repetitions: int

    def __call__(self, x, snr_db=None, generator=None):
        x_hat, nv = _send_blocks(self.link, x, self.snr_db, self.repetitions, generator)
        return SimpleNamespace(x_hat=x_hat, noise_var=nv)


def send_views(ctx, plans, images, on_demand: bool) -> Transmission:
    """Each view through the semantic codec and its link (unbiased receiver, MRC of copies).

    On demand (focus mode) each view and its object masks are upsampled by the plan's
    oversampling s before encoding; outside the sent box the receiver shows the background,
    composited at the decoded resolution and then averaged back over s x s pixels (a box
    edge need not fall on the view's pixel grid: averaging first would mix the decoder's
    output for the erased positions into the edge pixels, a dark frame around every box).

    Args:
        ctx: the :class:`osnerf.scheme_types.RunContext`.
        plans: the views' :class:`osnerf.plan.ViewSend` (the on-demand parts when
            ``on_demand``, else the whole views); images: [num_views, 3, height, width] float32.
    """
    s_up = ctx.plan.oversampling if on_demand else 1
    _, _, h, w = images.shape
    out, symbols, rx_masks, side = [], [], [], []
    sec = {"encode": 0.0, "decode": 0.0, "channel": 0.0, "encode_cpu": 0.0, "decode_cpu": 0.0}
    for k, p in enumerate(plans):
        x, kw = _view_input(ctx, images[k : k + 1], k, s_up, on_demand)
        with _Timer(sec, "encode"):
            enc = _encode(ctx, p, x, kw)
        with _Timer(sec, "channel", cpu=False), torch.no_grad():
            x_hat, nv = _send_blocks(
                ctx.links[p.view],
                enc.symbols,
                p.snr_db,
                p.part.repetitions,
                ctx.view_generator(p.view),
            )
        with _Timer(sec, "decode"):
            img, m = _decode(ctx, p, enc, x_hat, nv, (h, w), s_up, on_demand)
        if m is not None:  # the pixels holding anything that was sent
            rx_masks.append(m.reshape(h, s_up, w, s_up).max(axis=(1, 3)) if s_up > 1 else m)
        out.append(img)
        symbols.append(p.part.repetitions * int(enc.symbols.shape[-1]))
        side.append(int(enc.meta.side_info_bits()))
    return Transmission(
        torch.stack(out),
        np.asarray(symbols, np.int64),
        np.stack(rx_masks) if rx_masks else None,
        sec,
        side_info_bits=int(sum(side)) if on_demand else 0,
        codec_use=codec_use(ctx, int(sum(symbols)), int(sum(p.part.symbols for p in plans))),
    )


def codec_use(ctx, sent: int, budget: int) -> dict:
    """What the run did with the codec, for the report: its declared limits, refinement on
    or off (and why), and the symbols sent against the plan's budget (repetitions included;
    a codec may send fewer than its budget, never silently)."""

    return {
        "codec": ctx.codec.name,
        "limits": codec_limits(ctx.codec).as_dict(),
        "refinement": refinement_status(ctx.codec, ctx.send.refine_steps),
        "symbols_sent": sent,
        "symbol_budget": budget,
        "symbols_unused": budget - sent,
    }


class _Timer:
    """Adds the wall (and CPU) seconds of a ``with`` block to ``sec[name]`` (``name_cpu``)."""

    def __init__(self, sec: dict, name: str, cpu: bool = True):
        self.sec, self.name, self.cpu = sec, name, cpu

    def __enter__(self):
        self.t, self.c = time.perf_counter(), time.process_time()

    def __exit__(self, *exc):
        self.sec[self.name] += time.perf_counter() - self.t
        if self.cpu:
            self.sec[f"{self.name}_cpu"] += time.process_time() - self.c


def _view_input(ctx, x, k: int, s_up: int, on_demand: bool) -> tuple[torch.Tensor, dict]:
    """The view as the encoder takes it ([1, 3, s*h, s*w]) and its focus arguments."""
    kw = {}
    if on_demand:
        kw = {"mask": ctx.routing[0][k : k + 1], "demand_weights": list(ctx.routing[1])}
    if s_up > 1:
        x = F.interpolate(x, scale_factor=s_up, mode="bicubic", align_corners=False).clamp(0, 1)
        if kw:
            kw["mask"] = F.interpolate(kw["mask"], scale_factor=s_up, mode="nearest")
    return x, kw


def _encode(ctx, p, x, kw: dict):
    """Encode one view; with ``refine_steps``, refine its symbols against the transmitter's
    own model of the channel (:func:`refine_model_link`), weighted to the demanded objects."""

    codec = ctx.codec
    if ctx.plan.static_link:  # the AWGN simulation holds: split for the fusing receiver
        codec = for_fusion(codec, ctx.send.layer_fusion, "transmitter")
    with torch.no_grad():
        enc = encode_with_focus(codec, x, p.part.encoder_snr_db, p.part.cbr, **kw)
    steps = int(ctx.send.refine_steps)
    if not refinement_status(codec, steps)["on"]:
        return enc  # a codec without a differentiable decode is sent as encoded (reported)
    # the SNR the transmitter simulates: the link's (as before), or its estimate when the run
    # sets the transmitters' belief apart from the channel
    sim_snr = p.measured_snr_db if ctx.send.transmitter_estimates else p.snr_db
    model = _Copies(refine_model_link(ctx.send.channel), sim_snr, p.part.repetitions)
    gen = torch.Generator().manual_seed(scheme_seed(ctx.send.seed, f"view {int(p.view)}", "refine"))
    wts = None
    if kw:  # the demanded objects' pixels first (their weights), the rest of the box
        lam = torch.as_tensor(kw["demand_weights"], dtype=torch.float32)
        obj = (kw["mask"] * lam[None, :, None, None]).sum(1, keepdim=True).clamp(0, 1)
        wts = REFINE_OUTSIDE_WEIGHT + (1.0 - REFINE_OUTSIDE_WEIGHT) * obj
    return refine_symbols(
        codec,
        x,
        enc,
        model,
        sim_snr,
        steps,
        generator=gen,
        decoder_snr_db=p.part.encoder_snr_db,
        pixel_weights=wts,
    )


def _decode(ctx, p, enc, x_hat, nv, size, s_up: int, on_demand: bool):
    """Decode one view at the average SNR after combining (per-symbol noise in ``nv``); on
    demand, the background outside the sent box, then back to the captured size. Returns
    (image [3, h, w], the sent pixels at the decoded resolution or None)."""

    h, w = size
    bg = torch.as_tensor(ctx.background, dtype=torch.float32)[:, None, None]
    with torch.no_grad():
        img = decode_received(
            ctx.rx_codec, x_hat, enc.meta, p.part.encoder_snr_db, ctx.codec.sha256, nv
        )[0]
        m = receiver_mask(enc.meta, s_up * h, s_up * w) if on_demand else None
        if m is not None:
            mt = torch.from_numpy(m)[None]
            img = img * mt + bg * (1.0 - mt)
        if s_up > 1:
            img = F.avg_pool2d(img[None], s_up)[0]
    return img, m
