"""What a run's report says about its channel: :class:`LinkReport`, typed in memory, flat in
``report.json`` (its ``link``).

Each kind of link fills the sections it has: a simulated channel its receiver and
``channel_params``; the ray-traced channel its receiver, the trace, the drones' motion and
positions; over the air the radios, the air (ray-traced or fixed) and the frame counts. Per-view
maps are keyed by the view's int index in memory; :meth:`LinkReport.to_dict` writes the keys as
strings (as JSON must) and :meth:`LinkReport.from_dict` reads them back as ints. ``to_dict``
writes the sections' keys in one order that every kind of link shares, so a report read and
written again is the same text.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

EQUALIZER = "zf (unbiased) + per-symbol noise variance"


class Section:
    """One section of a link's report: its fields in ``report.json``'s order, flat.
    ``OPTIONAL``: fields left out when None (absent for this kind of link, never a value of
    their own); ``VIEW_MAPS``: per-view maps (int keys here, strings in JSON)."""

    OPTIONAL: ClassVar[tuple[str, ...]] = ()
    VIEW_MAPS: ClassVar[tuple[str, ...]] = ()

    def to_dict(self) -> dict[str, Any]:
        out = {}
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            v = getattr(self, f.name)
            if v is None and f.name in self.OPTIONAL:
                continue
            out[f.name] = {str(k): x for k, x in v.items()} if f.name in self.VIEW_MAPS else v
        return out

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The section's keys in ``report.json``."""
        return tuple(f.name for f in dataclasses.fields(cls))  # type: ignore[arg-type]

    @classmethod
    def from_dict(cls, d: dict) -> Any:
        """The section from the keys of a report's ``link`` that are its fields."""
        kw = {}
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if f.name in d:
                v = d[f.name]
                kw[f.name] = {int(k): x for k, x in v.items()} if f.name in cls.VIEW_MAPS else v
        return cls(**kw)


@dataclass
class Receiver(Section):
    """How the receiver sees the channel: its CSI and, with pilot estimates on an OFDM grid,
    the grid and the symbols' timing."""

    csi: str
    ofdm: bool | None = None
    grid: dict | None = None
    timing: str | None = None
    equalizer: str = EQUALIZER

    OPTIONAL = ("ofdm", "grid", "timing")


@dataclass
class Radios(Section):
    """The over-the-air front ends and their frames (an emulated air's crystal offsets,
    multipath and delay where the host sets the air)."""

    device: str
    frames: str
    sample_rate_hz: float
    center_freq_hz: float
    symbols_per_frame: int
    ppm: list[float] | None = None
    multipath: list[list] | None = None
    delay_s: float | None = None

    OPTIONAL = ("ppm", "multipath", "delay_s")


@dataclass
class TracedAir(Section):
    """Over the air with each view's emulated air its drone's ray-traced paths.
    ``air_views``: view -> that view's paths, gain, SNR and what its bursts saw."""

    scene: str
    radio_scene: str
    carrier_frequency_hz: float
    drone_speed_m_s: float
    max_doppler_hz: float
    median_rms_doppler_spread_hz: float | None
    reference_path_gain_db: float
    outage_views: list[int]
    air_views: dict[int, dict]
    ray_solver: dict
    air_note: str

    VIEW_MAPS = ("air_views",)

    def to_dict(self) -> dict[str, Any]:
        return {"ota_air": "raytraced", **super().to_dict()}


@dataclass
class Trace(Section):
    """The ray-traced channel: each view's path gain (dB), the reference the SNR is set at,
    the views without a path, the traced subcarriers and the solver's statistics."""

    path_gain_db: dict[int, float]
    reference_path_gain_db: float
    outage_views: list[int]
    num_subcarriers: int
    carrier_frequency_hz: float
    stats: dict
    ray_solver: dict

    VIEW_MAPS = ("path_gain_db",)


@dataclass
class Motion(Section):
    """The drones' speed and the Doppler it brings; ``rms_doppler_spread_hz`` per view."""

    drone_speed_m_s: float
    max_doppler_hz: float
    rms_doppler_spread_hz: dict[int, float]
    median_rms_doppler_spread_hz: float | None
    motion: str

    VIEW_MAPS = ("rms_doppler_spread_hz",)


@dataclass
class Positions(Section):
    """Where the radio ends were: the ground station, the drones' ring, each view's drone."""

    ground_station_m: list[float]
    ground_station_from: str
    ground_station_warning: str | None
    drone_ring: dict
    drone_positions_m: dict[int, list[float]]
    distance_to_ground_station_m: dict[int, float]

    VIEW_MAPS = ("drone_positions_m", "distance_to_ground_station_m")


@dataclass
class AirSnr(Section):
    """The SNR set on the air; between real boards nobody sets it (``air_snr_db`` None) and
    the codec and receiver assume ``snr_db_assumed``."""

    air_snr_db: float | None
    snr_db_assumed: float | None = None
    note: str | None = None

    OPTIONAL = ("snr_db_assumed", "note")


@dataclass
class FrameCounts(Section):
    """What the over-the-air link counted when it closed (the receiver's mean pilot SNR
    estimate, None when no frame was measured)."""

    frames_sent: int
    frames_lost: int
    snr_db_measured: float | None = None


SECTIONS: tuple[tuple[str, type[Section], str], ...] = (
    ("radios", Radios, "device"),
    ("traced_air", TracedAir, "ota_air"),
    ("receiver", Receiver, "csi"),
    ("trace", Trace, "path_gain_db"),
    ("motion", Motion, "motion"),
    ("positions", Positions, "ground_station_m"),
    ("air", AirSnr, "air_snr_db"),
    ("counts", FrameCounts, "frames_sent"),
)
"""(attribute, section, the key that marks it in ``report.json``), in ``to_dict``'s order;
``channel_params`` goes before ``air``."""


@dataclass
class LinkReport:
    """A run's channel as the report tells it (see the module's docstring).
    ``channel_params``: the record that fixes the channel (``phy.channel_record``, or the
    ray-traced geometry), so each sweep point records it."""

    channel: str
    radios: Radios | None = None
    traced_air: TracedAir | None = None
    receiver: Receiver | None = None
    trace: Trace | None = None
    motion: Motion | None = None
    positions: Positions | None = None
    channel_params: dict | None = None
    air: AirSnr | None = None
    counts: FrameCounts | None = None

    def to_dict(self) -> dict:
        d: dict[str, Any] = {"channel": self.channel}
        for name, _, _ in SECTIONS:
            if name == "air" and self.channel_params is not None:
                d["channel_params"] = self.channel_params
            section = getattr(self, name)
            if section is not None:
                d.update(section.to_dict())
        return d

    @classmethod
    def from_dict(cls, d: dict) -> LinkReport:
        """Read a report's ``link``; a key that no section has is an error (named)."""
        kw: dict[str, Any] = {"channel": d["channel"], "channel_params": d.get("channel_params")}
        known = {"channel", "channel_params", "ota_air"}
        for name, section, marker in SECTIONS:
            if marker in d:
                kw[name] = section.from_dict(d)
                known |= set(section.names())
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"report link: unknown field(s) {', '.join(unknown)}")
        return cls(**kw)

    @property
    def frames_lost(self) -> int | None:
        """Frames the over-the-air link lost, None for a simulated link."""
        return None if self.counts is None else self.counts.frames_lost
