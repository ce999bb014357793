"""Scheme registry and per-image scoring for ``osnerf eval-codec`` and the benchmark.

:data:`LINK_SCHEMES`: name -> :class:`LinkScheme`, called as ``scheme(ctx, image [1, 3, H, W],
snr_db, cbr, generator, plan_snr_db=None) -> TransmitResult``. One table; unknown names raise
KeyError listing the known ones. ``digital_genie`` and ``ideal*`` are bounds
(``LinkScheme.bound``).

What the transmitter knows is apart from the channel: ``snr_db`` is the channel's true
average SNR (the link applies it; the receiver measures its noise), ``plan_snr_db`` what the
transmitter believes (default: the truth). Every transmitter plans from the belief (the
jscc encoder's SNR, the digital MCS); ``ctx.snr_error_db`` is the spread of the belief's
error that ``digital`` plans over (``digital_naive`` ignores it). Bounds (``ideal``, the
genie's draw) keep the truth.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch

import phy
from common import Registry, list_images, read_image, to_chw, to_hwc
from phy import channel_link, num_symbols_for_cbr, receiver_description
from semcodec.contract.box_focus import encode_with_focus
from semcodec.contract.protocol import MIN_SIDE_PX
from semcodec.contract.transmit import TransmitResult
from semcodec.digital.link import AUTO, GENIE, transmit_digital, transmit_ideal
from semcodec.jscc.codec import Codec, learned_only
from semcodec.jscc.link import REFINE_STEPS, refine_symbols, transmit_jscc
from semcodec.links.framed import DIGITAL_FRAMED, JSCC_FRAMED, FramedScheme
from semcodec.links.softcast import framed_softcast, transmit_softcast
from semcodec.links.uncoded import transmit_analog

DEFAULT_FIXED_MCS = "16qam-1/2"


def eval_channels() -> list[str]:
    """The channels ``eval-codec`` accepts: every name of ``phy.CHANNELS``."""
    return list(phy.CHANNELS)


@dataclass
class EvalContext:
    """What the schemes share: codec, the channel's link, fixed MCS.

    Every link has a ZF equaliser: unbiased estimates and the per-symbol effective noise
    variance (the codec's and the soft demapper's convention). Flat channels: perfect CSI;
    ``tdl``/``cdl``: OFDM (``phy.ResourceGrid()``) with pilot LS estimates.
    """

    channel: str
    codec: Codec | None = None
    fixed_mcs: str = DEFAULT_FIXED_MCS
    links: dict = field(default_factory=dict)
    encodings: dict = field(default_factory=dict)  # (id, snr, cbr) -> (image, Encoded), latest
    refine_steps: int = REFINE_STEPS
    """``jscc_refined``'s Adam steps per image and SNR (:func:`semcodec.jscc.refine_symbols`)."""
    refine_seed: int = 0
    """Seed of the channel draws ``jscc_refined``'s transmitter simulates (its own stream)."""
    snr_error_db: float = 0.0
    """Standard deviation (dB) of the transmitter's SNR estimate's error, which ``digital``
    plans over (0: it plans as if the estimate were exact)."""

    def link(self):
        """The ``phy`` link of ``channel`` (built once, ``phy.channel_link``)."""
        if "zf" not in self.links:
            self.links["zf"] = channel_link(self.channel)
        return self.links["zf"]

    @property
    def receiver(self) -> str:
        """The receiver in words (for result files)."""
        return receiver_description(self.channel)


def _n(img, cbr) -> int:
    return num_symbols_for_cbr(cbr, img.shape[2], img.shape[3])


def _send_jscc(refine: bool, layer: bool = True):
    def run(ctx, img, snr, cbr, gen, plan):
        key = (id(img), float(plan), float(cbr), refine, layer)
        if key not in ctx.encodings:  # the transmitter's symbols: once for all draws
            ctx.encodings.clear()
            tx_codec = ctx.codec if layer else learned_only(ctx.codec)
            enc = encode_with_focus(tx_codec, img, plan, cbr)
            if refine:  # on the transmitter's own draws, never the evaluation's
                tx = torch.Generator().manual_seed(ctx.refine_seed)
                enc = refine_symbols(
                    ctx.codec, img, enc, ctx.link(), plan, ctx.refine_steps, generator=tx
                )
            ctx.encodings[key] = (img, enc)
        enc = ctx.encodings[key][1]
        return transmit_jscc(ctx.codec, img, ctx.link(), snr, cbr, generator=gen, encoded=enc)

    return run


def _digital(codec_name, mcs=AUTO, over_error: bool = True):
    def run(ctx, img, snr, cbr, gen, plan):
        m = ctx.fixed_mcs if mcs is None else mcs
        return transmit_digital(
            img,
            ctx.link(),
            snr,
            _n(img, cbr),
            mcs=m,
            image_codec=codec_name,
            generator=gen,
            channel=ctx.channel,
            plan_snr_db=plan,
            snr_error_db=ctx.snr_error_db if over_error else 0.0,
        )

    return run


def _ideal(codec_name):
    def run(ctx, img, snr, cbr, gen, plan):  # a bound: the truth, whatever was believed
        return transmit_ideal(img, snr, _n(img, cbr), image_codec=codec_name)

    return run


def _analog(ctx, img, snr, cbr, gen, plan):  # plans nothing: no SNR at the transmitter
    return transmit_analog(img, ctx.link(), snr, _n(img, cbr), generator=gen)


def _softcast(ctx, img, snr, cbr, gen, plan):  # plans nothing: no SNR at the transmitter
    return transmit_softcast(img, ctx.link(), snr, _n(img, cbr), generator=gen)


SCHEME_KINDS = (JSCC, DIGITAL, IDEAL, ANALOG) = ("jscc", "digital", "ideal", "analog")
"""What a scheme is, link-level or run-level: the semantic codec, a separate image codec +
LDPC + QAM, a separate scheme at capacity (error free), or uncoded pixels. Plots and
benchmarks group by kind, never by a scheme's name."""


@dataclass(frozen=True)
class LinkScheme:
    """One link-level scheme: ``scheme(ctx, image [1, 3, H, W], snr_db, cbr, generator)``.

    Attributes:
        run: the function that sends the image (returns a ``TransmitResult``).
        help: one line for ``--help``, plots and reports.
        kind: one of :data:`SCHEME_KINDS`.
        bound: what it bounds when it is not a real system (shown as such), else None.
        framed: its transmitter and receiver apart around a framed link
            (:mod:`semcodec.links.framed`: what ``osnerf ota`` sends between two radios), or None
            when it cannot cross one.
        mcs: how a digital scheme picks its modulation and code rate: ``"auto"`` (from the
            average SNR), ``"genie"`` (from the draw: a bound) or ``"fixed"`` (``--mcs``);
            None for the other kinds.
        image_codec: the ``semcodec.digital.IMAGE_CODECS`` name a separate (digital, ideal) scheme
            compresses with; None for the others.
    """

    run: Callable[..., TransmitResult]
    help: str
    kind: str
    bound: str | None = None
    framed: FramedScheme | None = None
    mcs: str | None = None
    image_codec: str | None = None

    refines: bool = False
    """The transmitter refines each image's symbols (``ctx.refine_steps``)."""

    @property
    def over_the_air(self) -> bool:
        """Whether ``osnerf ota`` can send it between two radios (it has a framed pair)."""
        return self.framed is not None

    @property
    def needs_codec(self) -> bool:
        """Whether it sends through the semantic codec (``ctx.codec`` must be loaded)."""
        return self.kind == JSCC

    def __call__(self, ctx, img, snr_db, cbr, generator, plan_snr_db=None) -> TransmitResult:
        """Send ``img`` over the channel at ``snr_db``; the transmitter plans from
        ``plan_snr_db`` (default ``snr_db``: exact knowledge)."""
        plan = snr_db if plan_snr_db is None else plan_snr_db
        return self.run(ctx, img, snr_db, cbr, generator, plan)


_GENIE = "bound: knows this draw's fade and noise, the best MCS that decodes on it"
_IDEAL = "bound: the codec at the AWGN capacity of the average SNR, error free"

LINK_SCHEMES = Registry[LinkScheme](
    "link scheme",
    {
        "jscc": LinkScheme(_send_jscc(False), "semantic JSCC", JSCC, framed=JSCC_FRAMED),
        "jscc_learned": LinkScheme(
            _send_jscc(False, layer=False),
            "semantic JSCC with its learned channels only (no analog refinement layer)",
            JSCC,
        ),
        "jscc_refined": LinkScheme(
            _send_jscc(True),
            "semantic JSCC, symbols refined at the transmitter for this image: Adam on the "
            "expected MSE over its own channel draws (knows the decoder, channel kind and "
            "average SNR, not the draw)",
            JSCC,
            refines=True,
        ),
        "digital": LinkScheme(
            _digital("avif"),
            "AVIF + 5G LDPC + QAM, one MCS from the average SNR (no CSI at the transmitter)",
            DIGITAL,
            framed=DIGITAL_FRAMED,
            mcs=AUTO,
            image_codec="avif",
        ),
        "digital_naive": LinkScheme(
            _digital("avif", over_error=False),
            "AVIF + 5G LDPC + QAM, the MCS from the SNR estimate as if it were exact (no "
            "back-off for its error)",
            DIGITAL,
            mcs=AUTO,
            image_codec="avif",
        ),
        "digital_genie": LinkScheme(
            _digital("avif", GENIE),
            f"AVIF, {_GENIE}",
            DIGITAL,
            _GENIE,
            mcs=GENIE,
            image_codec="avif",
        ),
        "digital_fixed": LinkScheme(
            _digital("avif", None),
            "AVIF + LDPC + QAM at one fixed MCS (--mcs): the cliff",
            DIGITAL,
            mcs="fixed",
            image_codec="avif",
        ),
        "ideal": LinkScheme(_ideal("avif"), f"AVIF, {_IDEAL}", IDEAL, _IDEAL, image_codec="avif"),
        "analog": LinkScheme(_analog, "uncoded pixels, LMMSE at the receiver", ANALOG),
        "softcast": LinkScheme(
            _softcast,
            "SoftCast: DCT chunks, lowest-energy dropped, power from chunk variances, LLSE at "
            "the receiver, metadata in the budget (training-free analog)",
            ANALOG,
            framed=framed_softcast(),
        ),
        "digital_webp": LinkScheme(
            _digital("webp"),
            "WebP + LDPC + QAM, MCS from the average SNR",
            DIGITAL,
            mcs=AUTO,
            image_codec="webp",
        ),
        "digital_jpeg": LinkScheme(
            _digital("jpeg"),
            "JPEG + LDPC + QAM, MCS from the average SNR",
            DIGITAL,
            mcs=AUTO,
            image_codec="jpeg",
        ),
        "ideal_webp": LinkScheme(
            _ideal("webp"), f"WebP, {_IDEAL}", IDEAL, _IDEAL, image_codec="webp"
        ),
        "ideal_jpeg": LinkScheme(
            _ideal("jpeg"), f"JPEG, {_IDEAL}", IDEAL, _IDEAL, image_codec="jpeg"
        ),
    },
)
"""name -> :class:`LinkScheme`: the one table of link-level schemes (``eval-codec``,
``osnerf ota``, the codec benchmark). The run-level schemes are ``osnerf.schemes.SCHEMES``."""


def schemes_help() -> str:
    """``name: help`` of every scheme, bounds marked, for ``--help``."""
    return "; ".join(f"{k} ({v.help})" for k, v in LINK_SCHEMES.items())


def load_image_folder(folder: str | Path) -> tuple[list[str], list[torch.Tensor]]:
    """Every image that ``--images`` names (a folder, or one file) as [1, 3, H, W] float32 in
    [0, 1] (:func:`common.read_image`); one-line errors naming the file.

    Images must be at least :data:`EVAL_MIN_SIDE_PX` on each side (the codec's and SSIM's
    minimum).
    """
    names, images = [], []
    for p in list_images(folder, "--images"):
        try:
            a = read_image(p)
        except ValueError as e:
            raise ValueError(f"--images: {e}") from None
        if min(a.shape[:2]) < EVAL_MIN_SIDE_PX:
            raise ValueError(
                f"--images: {p.name} is {a.shape[1]}x{a.shape[0]} px; images must be at least "
                f"{EVAL_MIN_SIDE_PX}x{EVAL_MIN_SIDE_PX} (SSIM's Gaussian window)"
            )
        names.append(p.name)
        images.append(to_chw(a[None]))
    return names, images


SSIM_SIGMA = 1.5
SSIM_WINDOW_PX = 2 * int(3.5 * SSIM_SIGMA + 0.5) + 1
"""The side of :func:`ssim`'s Gaussian window (11 px): scikit-image's truncation at 3.5 sigma."""
EVAL_MIN_SIDE_PX = max(MIN_SIDE_PX, SSIM_WINDOW_PX)


def ssim(x: torch.Tensor, y: torch.Tensor) -> float:
    """SSIM (scikit-image, Gaussian weights as Wang et al.) of one image pair [1, 3, H, W]."""
    from skimage.metrics import structural_similarity

    a = to_hwc(x[0].clamp(0, 1))
    b = to_hwc(y[0])
    return float(
        structural_similarity(
            a,
            b,
            channel_axis=2,
            data_range=1.0,
            gaussian_weights=True,
            sigma=SSIM_SIGMA,
            use_sample_covariance=False,
        )
    )
