"""The schemes of ``osnerf run``: one table, :data:`SCHEMES`, name -> scheme class.

A scheme takes the views the SCU planned (:class:`osnerf.plan.ViewSend`: the part of each
view's plan it carries out) and their pixels, sends them over the run's links and returns
what the receiver reconstructed (:class:`Transmission`; the shared types live in
:mod:`osnerf.scheme_types` and are re-exported here). Everything else (collection, plan,
links, reconstruction, scoring, report) is shared, so adding a scheme is one class and one
line::

    @register("mine")
    class Mine(Scheme):
        object_routed = True          # sends the on-demand views (masked to the objects)

        def transmit(self, ctx, plans, images):
            ...
            return Transmission(received, symbols)

Schemes of other packages register through the ``osnerf.schemes`` entry-point group
(``name = "package.module:Class"``; the class must subclass :class:`Scheme`). Each scheme's
own randomness comes from the run seed and its name (:func:`scheme_seed`); the channel draws
of a view come from the run seed and the view (:meth:`RunContext.view_generator`). So a
scheme's results do not depend on which other schemes run, in which order, or on how many
symbols its other views took, and schemes that use the link alike meet the same fades on
the same view (a paired comparison: their difference is not draw luck).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping

import numpy as np
import torch

import phy
import semcodec
from common import Registry
from osnerf.scheme_types import RunContext, Scheme, SendSettings, Transmission, scheme_seed
from osnerf.semantic_send import send_views
from semcodec.jscc import focus_pixel_masks
from semcodec.links import ANALOG, DIGITAL, IDEAL, JSCC

ENTRY_POINT_GROUP = "osnerf.schemes"

__all__ = [
    "DEFAULT_SCHEMES",
    "SCHEMES",
    "RunContext",
    "Scheme",
    "SendSettings",
    "Transmission",
    "get_scheme",
    "parse_schemes",
    "register",
    "scheme_seed",
]


def _scheme_class(name: str, cls: object) -> None:
    """Admit a subclass of :class:`Scheme` (built in or a plugin's) and name it after its key."""
    if not (isinstance(cls, type) and issubclass(cls, Scheme)):
        raise TypeError(f"scheme {name!r} must subclass osnerf.schemes.Scheme, got {cls!r}")
    cls.name = name


SCHEMES = Registry[type[Scheme]]("scheme", entry_points=ENTRY_POINT_GROUP, check=_scheme_class)
"""The run's schemes: name -> :class:`Scheme` subclass (plugins through ``osnerf.schemes``)."""


def register(name: str):
    """Class decorator: add the class to :data:`SCHEMES` as ``name`` (one line per scheme)."""
    return SCHEMES.register(name)


def get_scheme(name: str) -> Scheme:
    """An instance of the scheme ``name``; KeyError listing the known ones otherwise."""
    return SCHEMES[name]()


class SchemeListError(argparse.ArgumentTypeError, ValueError):
    """A bad list of scheme names: refused while parsing (argparse ``type=``) or, where a
    command checks later, as bad input (exit 2)."""


def parse_schemes(text: str, table: Mapping | None = None) -> tuple[str, ...]:
    """``"jscc,gt"`` -> names, each a key of ``table`` (default: the run's :data:`SCHEMES`
    with the entry points; ``semcodec.LINK_SCHEMES`` for the link-level commands).

    As argparse ``type=`` a bad list is refused while parsing, so ``osnerf sweep`` rejects
    it before the first point.

    Raises:
        SchemeListError: an empty list or entry (``"jscc,"``), a name given twice, or a
            name not in the table (the known ones listed; a plugin that failed to load,
            its load error).
    """
    known = SCHEMES if table is None else table
    names = tuple(s.strip() for s in str(text).split(","))
    problem = None
    if not any(names) or "" in names:
        problem = "an empty name"
    elif len(set(names)) < len(names):
        problem = f"{next(n for n in names if names.count(n) > 1)!r} twice"
    elif any(n not in known for n in names):
        name = next(n for n in names if n not in known)
        problem = getattr(known, "broken", {}).get(name) or f"unknown {name!r}"
    if problem:
        raise SchemeListError(
            f"must be a comma-separated subset of {','.join(known)}, got {text!r} ({problem})"
        )
    return names


# ----------------------------------------------------------------------------- helpers


@register("jscc")
class OnDemandJSCC(Scheme):
    """The semantic link on demand: only views showing the demanded objects, through the
    codec in focus mode (the feature positions touching the objects, all channels)."""

    kind = JSCC
    object_routed = True
    needs_codec = True
    headline = True
    help = "on-demand semantic JSCC (focus mode on the demanded objects)"

    def transmit(self, ctx, plans, images):
        return send_views(ctx, plans, images, on_demand=self.object_routed)


@register("digital")
class Digital(Scheme):
    """The same views and the same symbol budget per view as the on-demand plan, through an
    image codec (container stripped) + CRC + 5G LDPC + QAM (``semcodec.digital.transmit_digital``).
    No CSI at the transmitter: the MCS comes from the average SNR alone (the calibration
    table's best expected PSNR over the channel's fading), so deep fades cost outages."""

    kind = DIGITAL
    object_routed = True
    help = "image codec + 5G LDPC + QAM, MCS from the average SNR (no CSI at the transmitter)"

    def mcs(self, send) -> str:
        return send.mcs

    def transmit(self, ctx, plans, images):
        cfg = ctx.send
        channel = phy.assumed_channel(cfg.channel)
        out, failed, arrived = [], 0, []
        lost = {"budget": 0, "channel": 0}
        t = time.perf_counter()
        box = cfg.digital_box and self.object_routed
        boxes = []
        for k, p in enumerate(plans):
            sent, n_sym = images[k : k + 1], int(p.part.symbols)
            if box:  # the objects' box, its position charged to the view's budget
                crop = object_box(images[k], ctx.background)
                top, left, rows, cols = crop
                sent = images[k : k + 1, :, top : top + rows, left : left + cols]
                n_sym -= semcodec.contract.box_side_symbols(*images.shape[-2:])
                boxes.append(crop)
            res = semcodec.digital.transmit_digital(
                sent,
                ctx.links[p.view],
                p.snr_db,
                n_sym,
                mcs=self.mcs(cfg),
                image_codec=cfg.image_codec,
                generator=ctx.view_generator(p.view),
                channel=channel,
                # from the SCU's estimate when the run sets one apart, else the link's truth
                plan_snr_db=p.measured_snr_db if cfg.transmitter_estimates else None,
                snr_error_db=cfg.snr_error_db,
            )
            out.append(
                paste_box(res.images[0], images[k], ctx.background, boxes[-1])
                if box
                else res.images[0]
            )
            st = res.stats
            failed += int(st.get("failed_codewords", 0))
            for k in lost:
                lost[k] += int(st["views_lost"][k])
            arrived.append(not any(st["views_lost"].values()))
        side_info_bits = semcodec.contract.box_bits(*images.shape[-2:]) * len(plans) if box else 0
        return Transmission(
            torch.stack(out),
            np.asarray([p.part.symbols for p in plans], np.int64),
            None,
            {"codec_and_ldpc": time.perf_counter() - t},
            received=np.asarray(arrived, bool),
            side_info_bits=side_info_bits,
            failed_codewords=failed,
            views_lost=lost,
        )


def object_box(image: torch.Tensor, background) -> tuple[int, int, int, int]:
    """(top, left, rows, cols) of the demanded objects in a masked view [3, height, width]
    (every pixel off the background colour), grown as ``semcodec.contract.mask_box`` grows a focus
    box; the whole view when nothing differs."""
    bg = torch.as_tensor(np.asarray(background, np.float32)).reshape(3, 1, 1)
    mask = ((image - bg).abs().amax(dim=0) > 0.5 / 255).float()  # [height, width]
    return semcodec.contract.mask_box(mask[None, None], *image.shape[-2:])


def paste_box(received: torch.Tensor, image: torch.Tensor, background, crop) -> torch.Tensor:
    """The received box [3, rows, cols] on a canvas of the background colour the size of
    ``image`` [3, height, width] (what the receiver knows outside the box)."""
    top, left, rows, cols = crop
    canvas = torch.as_tensor(np.asarray(background, np.float32)).reshape(3, 1, 1)
    canvas = canvas.expand_as(image).clone()
    canvas[:, top : top + rows, left : left + cols] = received
    return canvas


@register("digital_genie")
class DigitalGenie(Digital):
    """A bound: the digital link with a genie that knows each view's fade and noise and keeps
    the best image over every MCS that decodes on that draw (the same draws as digital)."""

    bound = "genie: knows each draw's channel and picks the MCS after seeing it"
    help = "bound: digital with the best MCS per draw, chosen after seeing the channel"

    def mcs(self, send) -> str:
        return "genie"


@register("analog")
class Analog(Scheme):
    """Uncoded pixels linearly mapped to symbols (LMMSE at the receiver), on-demand views,
    the same symbol budget per view as the on-demand plan."""

    kind = ANALOG
    object_routed = True
    help = "uncoded analog pixels, same views and budget as jscc"

    def transmit(self, ctx, plans, images):
        return _linear_analog(semcodec.links.transmit_analog, ctx, plans, images)


@register("softcast")
class SoftCast(Scheme):
    """SoftCast (``semcodec.links.transmit_softcast``): DCT chunks, power from their variances,
    LLSE at the receiver, on-demand views, the same symbol budget per view as the on-demand
    plan (its metadata inside it)."""

    kind = ANALOG
    object_routed = True
    help = "SoftCast: training-free linear analog (DCT chunks, LLSE), same views and budget"

    def transmit(self, ctx, plans, images):
        return _linear_analog(semcodec.links.transmit_softcast, ctx, plans, images)


def _linear_analog(send, ctx, plans, images) -> Transmission:
    """A linear analog scheme (``send``: ``semcodec.links.transmit_analog`` or
    ``transmit_softcast``) over each on-demand view at the plan's budget per copy; its side
    information, where it sends any, in ``side_info_bits``."""
    out, side = [], 0
    t = time.perf_counter()
    for k, p in enumerate(plans):
        n = max(1, int(p.part.symbols) // max(p.part.repetitions, 1))
        res = send(
            images[k : k + 1],
            ctx.links[p.view],
            p.snr_db,
            n,
            generator=ctx.view_generator(p.view),
        )
        out.append(res.images[0])
        side += int(res.stats.get("side_info_bits", 0))
    return Transmission(
        torch.stack(out),
        np.asarray([p.part.symbols for p in plans], np.int64),
        None,
        {"encode": 0.0, "decode": time.perf_counter() - t},
        side_info_bits=side,
    )


@register("full")
class FullScene(OnDemandJSCC):
    """Every candidate view, whole, through the semantic codec (no on-demand selection), CBR
    per view from its measured SNR."""

    object_routed = False
    headline = False
    help = "every drone view whole through the semantic codec (no on-demand selection)"


@register("gt")
class GroundTruth(Scheme):
    """The on-demand views undistorted: nothing crosses the channel (the ceiling)."""

    kind = IDEAL
    object_routed = True
    bound = "ceiling: the on-demand views undistorted, nothing crosses the channel"
    help = "bound: the on-demand views undistorted (ceiling)"

    def transmit(self, ctx, plans, images):
        masks = ctx.routing[0].amax(dim=1).numpy() if ctx.routing is not None else None
        rx = None
        if masks is not None:  # what jscc's receiver would know over a perfect channel
            rx = focus_pixel_masks(masks, oversampling=ctx.plan.oversampling)
        return Transmission(
            images.clone(), np.zeros(len(plans), np.int64), rx, {"encode": 0.0, "decode": 0.0}
        )


DEFAULT_SCHEMES = ("jscc", "digital", "full", "gt")
"""What ``osnerf run`` sends by default (analog and the digital genie are opt-in)."""
