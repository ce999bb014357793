"""The configuration of one ``osnerf run`` (validated before any heavy work)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field, fields
from functools import cached_property

import phy
from common import MAX_BUDGET_S, SEED_RANGE, bound, bound_of, check_bounds
from osnerf.collect import Demand
from osnerf.ota_link import DEVICES as OTA_DEVICES
from osnerf.ota_link import OTA_AIRS
from osnerf.provenance import open_codec
from osnerf.scenes import (
    DEFAULT_SCENE,
    RenderConfig,
    check_demand,
    get_scene,
)
from osnerf.scheme_types import NerfBudget, SendSettings
from osnerf.schemes import DEFAULT_SCHEMES, SCHEMES
from osnerf.scu import VIEW_SELECTIONS
from phy.digital import MCS_TABLE
from semcodec.digital import IMAGE_CODECS

OTA = "ota"
RUN_CHANNELS = (*phy.CHANNELS, OTA)
"""``phy.CHANNELS`` (flat ones with perfect CSI, tdl/cdl over OFDM with LS estimates,
raytraced per drone position) plus the over-the-air link."""
DRONE_SPEED_RANGE_M_S = (0.0, 100.0)
GROUND_STATION_RANGE_M = (-10_000.0, 10_000.0)
"""Each coordinate of ``--ground-station``, metres in the scene's frame."""
MAX_NERF_STEPS = 10_000_000
"""The most NeRF optimiser steps a run takes."""


def _render_bound(name: str) -> dict:
    """A scene setting's range, as the scene's :class:`RenderConfig` declares it."""
    return {"bound": bound_of(RenderConfig, name)}


CACHE_VERSION = 17
"""Part of every cache key: bumped whenever a cached stage's format changes (15: the plan's
whole-view and on-demand parts; 16: a semantic scheme's transmission records what it did
with its codec, ``codec_use``) or what it was computed from (17: the radio scenes' terrain
and munich's ground station), so an older cache is recomputed, never misread."""


@dataclass(frozen=True)
class RunConfig:
    """One pipeline run.

    Attributes:
        scene: built-in scene name (``osnerf scenes`` lists them).
        demand: ``OBJECT[:WEIGHT][,OBJECT...]``; None = the scene's default demand.
        channel: a name of ``phy.CHANNELS`` ("rayleigh" = block fading, one h per view and
            copy; flat channels with perfect CSI; "tdl"/"cdl" over OFDM with LS estimates;
            "raytraced": each drone position's ray-traced channel) or "ota" (over the air
            between two HackRFs: emulated boards 20 ppm apart with multipath at ``snr_db``, or
            real ones; see ``ota_device``).
        snr_db: Es/N0 in dB (for "raytraced": at the median drone position).
        schemes: names in ``osnerf.schemes.SCHEMES``.
        seed: seeds every random draw (each scheme's from the seed and its name).
        max_seconds: cap on each scheme's NeRF training, seconds of ``nerf_clock`` (> 0);
            with ``nerf_steps`` None, the budget itself.
        resolution_px: drone image size (16..512).
        num_train_views: drone views captured (the candidates to send).
        num_test_views: held-out drone views, for scoring (never sent).
        symbol_rate_hz: symbol rate used to turn symbols into air time (> 0).
        codec: the transmitter's semantic codec, NAME[:CHECKPOINT] of ``semcodec.CODECS``
            (plugins included) or a checkpoint path (None: jscc, the shipped checkpoint).
        receiver_codec: the receiver's codec, the same forms (None: the same as ``codec``).
        allow_untrained: run a codec without trained weights (freshly initialised, e.g.
            deepjscc without a checkpoint); otherwise such a codec is refused. Not part of
            the cache key: it changes what runs, never a result.
        mcs: the digital scheme's MCS: "auto" (from the average SNR, no CSI at the
            transmitter) or a fixed phy.digital.MCS_TABLE name.
        image_codec: digital baseline image codec (``semcodec.digital.IMAGE_CODECS``).
        render_spp: Mitsuba samples per pixel.
        nerf_clock: what ``max_seconds`` counts: "cpu" (this process's CPU seconds over its
            threads: the same work on a busy machine as on an idle one) or "wall".
        nerf_steps: NeRF optimiser steps per scheme (>= 1): every scheme's field gets the
            same steps (the fair default); None: the same ``max_seconds`` instead.
        ota_device: for channel "ota": "emulated" (two emulated HackRFs), or a real front end
            of ``hil.DEVICES``: "hackrf" (two boards), "pluto" (one board, full duplex: the
            first libiio finds, or ``ip:$IIOD_REMOTE``), "soapy" (a SoapySDR device named by
            ``ota_tx_args``) or "zmq" (a GNU Radio flowgraph at ``ota_tx_args`` and
            ``ota_rx_args``).
        ota_tx_args, ota_rx_args: for ota_device "soapy", the Soapy device strings of the
            transmitter and the receiver (None: the first found; the receiver's: the
            transmitter's, one full-duplex device); for "zmq", the flowgraph's ZeroMQ
            addresses (both needed). Not part of the cache key when None.
        renderer_steps: optimiser steps of the learned renderer (``renderer.FeatureConfig``:
            a feature grid and decoder distilled from the field's own renders) built for each
            scheme's field; it renders the held-out views beside the full render (time per
            view, PSNR and setup CPU seconds of each in the report). Steps, not seconds: the
            same renderer on a busy machine as on an idle one. 0 skips it.
        refine_steps: the semantic schemes' transmitter (jscc, full) refines each view's
            symbols with this many Adam steps on the expected squared error over its own
            model of the channel at the view's measured SNR (:func:`semcodec.jscc.refine_symbols`,
            :func:`osnerf.semantic_send.refine_model_link`), on demand weighted to the demanded
            objects (:data:`osnerf.semantic_send.REFINE_OUTSIDE_WEIGHT`); 0: the encoder's symbols.
        layer_fusion: the semantic schemes' receiver estimates the codec's analog refinement
            layer as if the radiance field averaged each surface over about this many
            independently received views (:func:`semcodec.jscc.for_fusion`, in [1, 1000]): a
            noisier, less shrunk estimate per view and a better field. On a static link
            (the SCU's pilot copies do not fade independently) the transmitter also simulates
            its split between learned channels and the layer for that receiver. 1: each
            view's own LMMSE and split.
        drone_speed_m_s: for channel "raytraced": each drone flies at this speed (m/s, in
            [0, 100]) along its ring around the demanded objects (level, counter-clockwise
            seen from above) while it sends, and its channel changes with every symbol from
            each traced path's Doppler shift (symbol ``i`` of a view at ``i /
            symbol_rate_hz``); 0: the static channel of each position. Also for channel
            "ota" with ``ota_air`` "raytraced": the emulated air's paths turn at their
            Doppler shifts, sample by sample.
        ground_station_m: for channel "raytraced": the ground station's antenna at (x, y, z)
            metres in the scene's frame, each in [-10000, 10000], in place of the scene's
            own (None; "scene" on the command line). It moves the radio end only: the
            drones, their pictures and every other setting stay as they are, so only the
            channels change (re-traced, no re-render). The report's link records where it was.
        ring_scale: the drones' ring radius over the radius at which the demanded objects
            just fill a camera's view, in [1, 10] (the ring never comes closer than the
            scene's ``min_radius_m``). It moves every drone, so its pictures and its channel
            change together (the scene's views are rendered once per ring and cached).
        view_selection: how the SCU picks among the views the collector found (a name of
            ``osnerf.scu.VIEW_SELECTIONS``): "sight" (every visible view; with ``max_views``,
            greedy coverage of the object's viewing directions), "radio" (the highest
            expected SNR) or "joint" (coverage gain times link quality). A view's expected
            SNR is the SNR its link runs at (with "raytraced": ``snr_db`` plus its traced
            path gain over the median position's).
        max_views: the most views sent on demand, in [1, 512] ("radio" and "joint" need it);
            None: every view the collector found.
        csi: what the receiver of channel "raytraced" knows of the channel (``phy.CSI_OFDM``):
            "perfect" (each symbol's h, symbols on the traced subcarriers one after the
            other), or "ls"/"lmmse": the symbols ride an OFDM grid on the traced subcarriers
            (``osnerf.run.links.RAYTRACED_GRID``: pilots on OFDM symbols 2 and 11 of each
            14, every used subcarrier) and the receiver estimates h from the pilots, by LS
            with linear interpolation in frequency then time, or by sionna's LMMSE filter
            (TDL-A covariance in frequency, Jakes in time at ``drone_speed_m_s``); the
            estimate's error variance joins each symbol's noise variance. None: the
            channel's own receiver (perfect CSI on flat and ray-traced channels, LS pilots
            on tdl/cdl).
        ota_air: for channel "ota" over emulated radios (``ota_device`` "emulated", or an
            emulated Pluto), the air between them: "fixed" (a fixed multipath at
            ``snr_db``) or "raytraced" (each view's drone's ray-traced paths, with their
            Doppler shifts when ``drone_speed_m_s`` > 0, ``snr_db`` at the median drone
            position as for channel "raytraced"; :mod:`osnerf.run.ota_air`). Real boards'
            air is nobody's to set: "raytraced" is refused for them.
        plan_snr_db: what every transmitter believes each view's SNR is, in place of the
            SCU's pilot measurement (jscc's encoder SNR, rate and copies, the digital MCS);
            None: the measurement. The channel still runs at ``snr_db``.
        snr_error_db: a zero-mean Gaussian error (dB) added to each view's estimate (the
            measurement, or ``plan_snr_db``), drawn from the run seed, the same for every
            scheme; digital plans over it. With either set, digital plans from the estimate,
            not the link's true average SNR.
        digital_box: the object-routed digital schemes (digital, digital_genie) send the
            demanded objects' bounding box of each on-demand view (its position charged to
            the view's budget, ``semcodec.contract.box_side_symbols``), as codecs that cannot
            focus do (``semcodec.encode_with_focus``), instead of the whole masked view: the
            framing of jscc's on-demand region, so the end-to-end gap measures the link.
    """

    scene: str = DEFAULT_SCENE
    demand: str | None = None
    channel: str = "rayleigh"
    snr_db: float = field(default=0.0, metadata=bound(*phy.SNR_DB_RANGE, "dB"))
    schemes: tuple[str, ...] = DEFAULT_SCHEMES
    seed: int = field(default=0, metadata=bound(*SEED_RANGE, integer=True))
    max_seconds: float = field(default=600.0, metadata=bound(0, MAX_BUDGET_S, "s", low_open=True))
    resolution_px: int = field(default=80, metadata=_render_bound("resolution_px"))
    num_train_views: int = field(default=24, metadata=_render_bound("num_train_views"))
    num_test_views: int = field(default=8, metadata=_render_bound("num_test_views"))
    symbol_rate_hz: float = field(default=1e6, metadata=bound(0, 1e12, "Hz", low_open=True))
    codec: str | None = None
    receiver_codec: str | None = None
    allow_untrained: bool = False
    mcs: str = "auto"
    image_codec: str = "avif"
    render_spp: int = field(default=32, metadata=_render_bound("spp"))
    nerf_clock: str = "cpu"
    ota_device: str = "emulated"
    nerf_steps: int | None = field(
        default=1000, metadata=bound(1, MAX_NERF_STEPS, integer=True, optional=True)
    )
    renderer_steps: int = field(default=1200, metadata=bound(0, 100_000, integer=True))
    refine_steps: int = field(default=30, metadata=bound(0, 10_000, integer=True))
    layer_fusion: float = field(default=4.0, metadata=bound(1, 1000))
    drone_speed_m_s: float = field(default=0.0, metadata=bound(*DRONE_SPEED_RANGE_M_S, "m/s"))
    ground_station_m: tuple[float, float, float] | None = None
    ring_scale: float = field(
        default=RenderConfig.radius_scale, metadata=_render_bound("radius_scale")
    )
    view_selection: str = "sight"
    max_views: int | None = field(default=None, metadata=bound(1, 512, integer=True, optional=True))
    csi: str | None = None
    ota_air: str = "fixed"
    ota_tx_args: str | None = None
    ota_rx_args: str | None = None
    plan_snr_db: float | None = field(
        default=None, metadata=bound(*phy.SNR_DB_RANGE, "dB", optional=True)
    )
    snr_error_db: float = field(default=0.0, metadata=bound(0, 20, "dB"))
    digital_box: bool = False

    @property
    def transmitter_estimates(self) -> bool:
        """Whether the transmitters plan from an estimate apart from the link's true SNR
        (``plan_snr_db`` or ``snr_error_db`` set)."""
        return self.plan_snr_db is not None or self.snr_error_db > 0

    def __post_init__(self):
        get_scene(self.scene)
        if self.channel not in RUN_CHANNELS:
            raise ValueError(
                f"channel must be one of {', '.join(RUN_CHANNELS)}, got {self.channel!r}"
            )
        known = SCHEMES
        if not self.schemes:
            raise ValueError(f"schemes must name at least one of {', '.join(known)}")
        for s in self.schemes:
            if s not in known:
                why = f" ({known.broken[s]})" if s in known.broken else ""
                raise ValueError(f"schemes must be a subset of {','.join(known)}, got {s!r}{why}")
        if len(set(self.schemes)) != len(self.schemes):
            raise ValueError(f"schemes must not repeat a name, got {','.join(self.schemes)}")
        check_bounds(self)
        self._check_speed()
        self._check_positions()
        self._check_csi()
        if self.ota_device not in OTA_DEVICES:
            raise ValueError(
                f"ota_device must be one of {', '.join(OTA_DEVICES)}, got {self.ota_device!r}"
            )
        named = self.ota_tx_args is not None or self.ota_rx_args is not None
        if named and (self.channel != OTA or self.ota_device not in ("soapy", "zmq")):
            raise ValueError(
                "ota_tx_args/ota_rx_args name the devices of channel ota with ota_device soapy "
                "or zmq"
            )
        zmq = self.channel == OTA and self.ota_device == "zmq"
        if zmq and None in (self.ota_tx_args, self.ota_rx_args):
            raise ValueError("ota_device zmq needs ota_tx_args and ota_rx_args (ZMQ addresses)")
        if self.nerf_clock not in ("wall", "cpu"):
            raise ValueError(f"nerf_clock must be 'wall' or 'cpu', got {self.nerf_clock!r}")
        self._check_selection()
        self._check_digital()
        self.render_config()  # validates the view settings

    def _check_speed(self) -> None:
        v = self.drone_speed_m_s
        if self.ota_air not in OTA_AIRS:
            raise ValueError(f"ota_air must be one of {', '.join(OTA_AIRS)}, got {self.ota_air!r}")
        traced_air = self.channel == OTA and self.ota_air == "raytraced"
        if self.ota_air != "fixed" and self.channel != OTA:
            raise ValueError(
                f"ota_air sets the air of channel ota only, got channel {self.channel!r}"
            )
        if traced_air and self.ota_device == "hackrf":
            raise ValueError(
                "ota_air raytraced: the air between real HackRFs is not the host's to set; use "
                "ota_device emulated (or an emulated pluto)"
            )
        if v > 0 and self.channel != "raytraced" and not traced_air:
            raise ValueError(
                f"drone_speed_m_s moves the drones of channel raytraced (or ota with ota_air "
                f"raytraced) only, got {v!r} with channel {self.channel!r}"
            )

    def _check_positions(self) -> None:
        gs = self.ground_station_m
        if gs is not None:
            lo, hi = GROUND_STATION_RANGE_M
            try:
                xyz = tuple(float(v) for v in gs if not isinstance(v, bool))
            except (TypeError, ValueError):
                xyz = ()
            if len(xyz) != 3 or len(gs) != 3 or not all(lo <= v <= hi for v in xyz):
                raise ValueError(
                    f"ground_station_m must be (x, y, z) metres, each in [{lo:g}, {hi:g}], "
                    f"got {gs!r}"
                )
            if self.channel != "raytraced":
                raise ValueError(
                    f"ground_station_m moves the ground station of channel raytraced only, "
                    f"got {gs!r} with channel {self.channel!r}"
                )
            object.__setattr__(self, "ground_station_m", xyz)  # (8, -6, 1.5): the same run

    def _check_csi(self) -> None:
        if self.csi is None:
            return
        if self.csi not in phy.CSI_OFDM:
            raise ValueError(f"csi must be one of {', '.join(phy.CSI_OFDM)}, got {self.csi!r}")
        if self.channel != "raytraced":
            raise ValueError(
                f"csi chooses the receiver of channel raytraced only (tdl/cdl estimate with "
                f"LS pilots, flat channels know h), got {self.csi!r} with channel {self.channel!r}"
            )

    def _check_selection(self) -> None:
        if self.view_selection not in VIEW_SELECTIONS:
            raise ValueError(
                f"view_selection must be one of {', '.join(VIEW_SELECTIONS)}, "
                f"got {self.view_selection!r}"
            )
        if self.max_views is None and self.view_selection != "sight":
            raise ValueError(
                f"view_selection {self.view_selection!r} chooses among the visible views: "
                "give max_views"
            )

    def _check_digital(self) -> None:
        if self.mcs != "auto" and self.mcs not in MCS_TABLE:
            raise ValueError(
                f"mcs must be 'auto' or one of {', '.join(MCS_TABLE)}, got {self.mcs!r}"
            )
        if self.image_codec not in IMAGE_CODECS:
            raise ValueError(
                f"image_codec must be one of {', '.join(IMAGE_CODECS)}, got {self.image_codec!r}"
            )

    def send_settings(self) -> SendSettings:
        """What the run tells its transmitters and receivers."""
        return SendSettings(
            channel=self.channel,
            snr_db=float(self.snr_db),
            seed=int(self.seed),
            mcs=self.mcs,
            image_codec=self.image_codec,
            refine_steps=int(self.refine_steps),
            layer_fusion=float(self.layer_fusion),
            digital_box=bool(self.digital_box),
            snr_error_db=float(self.snr_error_db),
            transmitter_estimates=self.transmitter_estimates,
            symbol_rate_hz=float(self.symbol_rate_hz),
        )

    def nerf_budget(self) -> NerfBudget:
        """Each scheme's radiance-field training budget."""
        return NerfBudget(
            max_seconds=float(self.max_seconds),
            steps=self.nerf_steps,
            clock=self.nerf_clock,
            renderer_steps=int(self.renderer_steps),
        )

    def render_config(self) -> RenderConfig:
        return RenderConfig(
            resolution_px=self.resolution_px,
            num_train_views=self.num_train_views,
            num_test_views=self.num_test_views,
            spp=self.render_spp,
            radius_scale=float(self.ring_scale),
        )

    def demand_obj(self) -> Demand:
        text = self.demand or ",".join(get_scene(self.scene).default_demand)
        d = Demand.parse(text)
        check_demand(self.scene, d.objects)
        return d

    @cached_property
    def _codec_sha256(self) -> tuple[str, str]:
        """(transmitter, receiver) codec weights' sha256 (opening a codec reads its checkpoint)."""
        allow = self.allow_untrained
        tx = open_codec(self.codec, allow, warn=False).sha256
        rx = tx
        if self.receiver_codec:
            rx = open_codec(self.receiver_codec, allow, "--receiver-codec", warn=False).sha256
        return tx, rx

    def key(self) -> str:
        """Hash of everything that changes any scheme's results (the cache key): the settings
        and the weights of both ends' codecs (their ``sha256``, so a checkpoint replaced under
        the same path, the shipped default included, makes another key). The list of schemes
        is not part of it: each scheme's stages are cached under its own name."""
        d = {k: v for k, v in asdict(self).items() if k not in ("schemes", "allow_untrained")}
        if d["ota_air"] == "fixed":  # the air every run had before it was a choice: same key
            del d["ota_air"]
        for name in ("ota_tx_args", "ota_rx_args"):  # likewise before devices were named
            if d[name] is None:
                del d[name]
        if d["plan_snr_db"] is None and not d["snr_error_db"]:  # exact knowledge: as before
            del d["plan_snr_db"], d["snr_error_db"]
        if not d["digital_box"]:  # the whole masked view, as before: same key
            del d["digital_box"]
        for f in fields(self):  # 60 and 60.0 are the same run (the API takes either)
            if isinstance(f.default, float) and f.name in d:  # the float fields
                d[f.name] = float(d[f.name])
        d["codec_sha256"] = self._codec_sha256
        blob = json.dumps({**d, "v": CACHE_VERSION}, sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]
