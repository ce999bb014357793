"""What a scheme of ``osnerf run`` is and exchanges: :class:`Scheme` (the base class),
:class:`RunContext` (what it may use), :class:`Transmission` (what its receiver holds) and
:func:`scheme_seed`.

Both the scheme table (:mod:`osnerf.schemes`) and the senders it calls
(:mod:`osnerf.semantic_send`) import these types from here; this module imports neither, so
neither imports the other to share them.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import torch

from osnerf.plan import RunPlan, ViewSend

TRANSMISSION_ARRAYS = ("rx_masks", "received")
"""The optional arrays of a :class:`Transmission` (cached when present)."""
TRANSMISSION_INFO = ("side_info_bits", "codec_use", "failed_codewords", "views_lost")
"""The report's details a :class:`Transmission` carries (cached as JSON)."""


def scheme_seed(run_seed: int, name: str, stage: str = "transmit") -> int:
    """A seed that depends on the run seed, the scheme's name and the stage only."""
    h = hashlib.sha256(f"{int(run_seed)}/{name}/{stage}".encode()).digest()
    return int.from_bytes(h[:8], "little") & (2**62 - 1)


@dataclass
class Transmission:
    """What one scheme's receiver holds after sending its views.

    Attributes:
        images: [num_views, 3, height, width] float32 in [0, 1], the received views.
        symbols: [num_views] int64 channel symbols spent per view (repetitions included).
        rx_masks: [num_views, height, width] float32: pixels the receiver knows were sent
            (focus box or positions), or None for whole views.
        seconds: ``encode``, ``decode`` (and ``encode_cpu``, ``decode_cpu``, ``channel``, or
            ``codec_and_ldpc`` for separate schemes), wall seconds over all views.
        side_info_bits: bits of focus side information sent (semantic schemes on demand).
        codec_use: semantic schemes: the codec's declared limits, refinement on or off, symbols
            sent against the plan's budget (``osnerf.semantic_send.codec_use``); else None.
        failed_codewords: LDPC codewords that failed (separate schemes), else None.
        views_lost: ``{"budget": n, "channel": m}`` for separate schemes, else None.
        received: [num_views] bool, False for a view the receiver knows did not arrive (a
            failed checksum, or nothing fitted its budget): ``images`` holds mid-grey there,
            and the radiance field trains on the other views only. None: every view arrived.
    """

    images: torch.Tensor
    symbols: np.ndarray
    rx_masks: np.ndarray | None = None
    seconds: dict = field(default_factory=dict)
    received: np.ndarray | None = None
    side_info_bits: int = 0
    codec_use: dict | None = None
    failed_codewords: int | None = None
    views_lost: dict | None = None

    def to_cache(self) -> tuple[dict, dict]:
        """(arrays, JSON info) for ``StageCache.save``."""
        arrays = {"images": self.images.numpy(), "symbols": self.symbols}
        for name in TRANSMISSION_ARRAYS:
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        return arrays, {"seconds": self.seconds} | {k: getattr(self, k) for k in TRANSMISSION_INFO}

    @classmethod
    def from_cache(cls, arrays: dict, info: dict) -> Transmission:
        """The inverse of :meth:`to_cache` (also of a cache that kept the details in a dict
        under ``info``)."""
        details = info.get("info", info)
        return cls(
            torch.from_numpy(arrays["images"]),
            arrays["symbols"],
            arrays.get("rx_masks"),
            info["seconds"],
            arrays.get("received"),
            **{k: details[k] for k in TRANSMISSION_INFO if k in details},
        )


@dataclass(frozen=True)
class SendSettings:
    """What a run tells its transmitters and receivers, derived once from its config
    (``osnerf.run.RunConfig.send_settings``): the schemes read these, never the config.

    Attributes:
        channel: the run's channel (a name of ``phy.CHANNELS``, or "raytraced"/"ota").
        snr_db: the run's SNR (Es/N0, dB).
        seed: the run's seed (each scheme's draws from it and the scheme's name).
        mcs: the digital scheme's MCS ("auto": from the average SNR).
        image_codec: the digital schemes' image codec.
        refine_steps: the semantic transmitter's refinement steps per view (0: none).
        layer_fusion: the semantic receiver's refinement-layer fusion
            (``semcodec.jscc.for_fusion``).
        digital_box: the object-routed digital schemes send the objects' box.
        snr_error_db: the Gaussian error (dB) of each view's SNR estimate.
        transmitter_estimates: transmitters plan from the SCU's estimate apart from the truth.
        symbol_rate_hz: channel symbols per second (air time).
    """

    channel: str
    snr_db: float
    seed: int
    mcs: str = "auto"
    image_codec: str = "avif"
    refine_steps: int = 0
    layer_fusion: float = 4.0
    digital_box: bool = False
    snr_error_db: float = 0.0
    transmitter_estimates: bool = False
    symbol_rate_hz: float = 1e6


@dataclass(frozen=True)
class NerfBudget:
    """Each scheme's radiance-field training budget, the same for every scheme, derived once
    from the run's config (``osnerf.run.RunConfig.nerf_budget``).

    Attributes:
        max_seconds: cap on the training, seconds of ``clock`` (> 0).
        steps: optimiser steps (None: ``max_seconds`` is the budget).
        clock: what ``max_seconds`` counts ("cpu" or "wall").
        renderer_steps: optimiser steps of the learned renderer (0: none).
    """

    max_seconds: float
    steps: int | None
    clock: str
    renderer_steps: int

    def describe(self) -> str:
        """As the log says it: the steps when they are the budget, else seconds."""
        return f"{self.steps} steps" if self.steps else f"{self.max_seconds:g} s"


@dataclass
class RunContext:
    """What every scheme may use: what the run tells it, the codec, links and plan.

    Attributes:
        send: the run's :class:`SendSettings`.
        links: view -> ``phy.Link`` (unbiased ZF receivers with perfect or estimated CSI).
        plan: the SCU's :class:`osnerf.plan.RunPlan`.
        codec, rx_codec: transmitter's and receiver's codecs (None when no scheme needs one).
        background: [3] float32 background colour of the scene.
        routing: (object masks [n_on_demand, K, h, w] tensor, K demand weights) for focus mode.
    """

    send: SendSettings
    links: dict
    plan: RunPlan
    codec: object | None
    rx_codec: object | None
    background: np.ndarray
    routing: tuple | None = None

    def view_generator(self, view: int) -> torch.Generator:
        """The channel draws of one view (fades, noise): from the run seed and the view only."""
        return torch.Generator().manual_seed(
            scheme_seed(self.send.seed, f"view {int(view)}", "link")
        )


class Scheme:
    """Base class. Subclasses set the class attributes and implement :meth:`transmit`.

    Class attributes:
        name: the table key (set by ``osnerf.schemes.register``).
        object_routed: True: sends the on-demand views masked to the demanded objects and
            its renderer trains inside the objects' box; False: every candidate view whole.
        needs_codec: loads the semantic codec (checked against the knowledge base).
        bound: None, or what the scheme bounds ("ceiling: nothing crosses the channel");
            bounds are labelled as such in help and reports.
        help: one line for ``--help`` and reports.
        headline: the scheme the report's comparisons are about (the others are its baselines).
        kind: one of ``semcodec.links.schemes.SCHEME_KINDS`` (as the link-level schemes):
            what plots and benchmarks group by.
    """

    name: ClassVar[str] = ""
    headline: ClassVar[bool] = False
    kind: ClassVar[str] = ""
    object_routed: ClassVar[bool] = True
    needs_codec: ClassVar[bool] = False
    bound: ClassVar[str | None] = None
    help: ClassVar[str] = ""

    def transmit(
        self, ctx: RunContext, plans: list[ViewSend], images: torch.Tensor
    ) -> Transmission:
        """Send ``images`` [num_views, 3, h, w] (the views of ``plans``) and receive them.
        Channel draws come from ``ctx.view_generator(view)``; other randomness from
        :func:`scheme_seed` of the run seed and the scheme's name."""
        raise NotImplementedError
