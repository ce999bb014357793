"""``osnerf run --channel ota --ota-air raytraced``: each view's emulated air is the
ray-traced channel of its drone's position.

Before each burst of a view, the emulated air (the HackRF emulator's medium, or an
emulated Pluto's through its air attribute) is set to the paths sionna-rt traced from
that drone's position to the ground station: each path's delay after the first arrival,
complex gain and, with ``drone_speed_m_s``, Doppler shift, re-traced every
``phy.raytrace.RETRACE_WAVELENGTHS`` of flight over the burst
(``phy.raytrace.MovingTransmitter``). The channel's time starts at the burst's first
sample, so every burst of a view (the SCU's pilots, each scheme) sees the same fading.

SNR: as for ``channel raytraced``, ``snr_db`` holds at the median drone position: every
path gain is divided by that position's path gain, so a shadowed drone's air is weaker.
The bulk delay, the radios' crystals and the frame sync are those of the fixed air.
Real boards: nobody sets their air; the run is refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import torch

from hil import burst_num_samples
from hil.emulation import segments_from_arrays
from osnerf.link_report import TracedAir
from osnerf.ota_link import DEFAULT_DELAY_S, air_channel
from osnerf.scenes import drone_channels, flight_velocities
from phy.raytrace import RETRACE_WAVELENGTHS, max_doppler_hz

if TYPE_CHECKING:  # annotations only
    from osnerf.ota_link import OtaLink
    from phy.raytrace import MovingTransmitter


@dataclass
class ViewAirLink:
    """One view's over-the-air link with its drone's ray-traced air (a ``phy`` link).

    Attributes:
        ota: the run's ``osnerf.ota_link.OtaLink`` (its radios, shared by every view).
        view: the drone view.
        snr_db: the SNR this view's link runs at (``snr_db`` + its path gain over the median).
        mover: the drone's ``phy.raytrace.MovingTransmitter`` (velocity 0: at rest).
        scale: amplitude factor of every path gain (1 / sqrt of the median path gain).
        device: "emulated" or "pluto" (whose gains calibrate the air's SNR).
        air_snr_db: ``snr_db`` of the run (the air's SNR at the median position).
        seed: the run's seed; burst ``b`` of the view draws noise from (seed, view, b).
        record: this view's entry of the report's link info (updated per burst).
    """

    ota: OtaLink
    view: int
    snr_db: float
    mover: MovingTransmitter
    scale: float
    device: str
    air_snr_db: float
    seed: int
    record: dict = field(default_factory=dict)
    bursts: int = 0

    def air(self, num_samples: int):
        """The ``hil.AirChannel`` of a burst of ``num_samples`` samples."""
        cfg = self.ota.ota_cfg
        cir = self.mover.cir(num_samples / cfg.sample_rate_hz)
        segs = segments_from_arrays(cir.a * self.scale, cir.tau_s, cir.doppler_hz, cir.start_s)
        return air_channel(self.device, self.air_snr_db, cfg, DEFAULT_DELAY_S, (), segs)

    def __call__(self, x, snr_db=None, generator: torch.Generator | None = None):
        if snr_db is not None and abs(float(snr_db) - self.snr_db) > 1e-9:
            raise ValueError(
                f"view {self.view}'s air runs at {self.snr_db:g} dB, asked for {float(snr_db):g} dB"
            )
        x = torch.as_tensor(x)
        if x.dim() != 2:
            raise ValueError(f"x must be [batch, num_symbols] complex64, got {tuple(x.shape)}")
        n = burst_num_samples([x.shape[1]] * x.shape[0], self.ota.ota_cfg)
        channel = self.air(n)
        seed = int(np.random.SeedSequence([self.seed, self.view, self.bursts]).generate_state(1)[0])
        self.ota.set_air(channel, seed)
        self.bursts += 1
        self.record["segments"] = max(self.record.get("segments", 0), len(channel.path_segments))
        return self.ota.transmit(x)


def raytraced_air_links(cfg, views, idx: list[int], ota, device: str) -> tuple:
    """Each view's :class:`ViewAirLink` over the run's radios ``ota``.

    Returns:
        (links: view -> link, snr_db: view -> its SNR, outage: views without any path,
        the report's section on the air).
    Raises:
        ValueError: ``ota``'s boards are real (their air is not ours to set).
    """
    if not ota.air_settable:
        raise ValueError(
            "ota_air raytraced: the air between real boards is not the host's to set; use "
            "ota_device emulated, or an emulated Pluto (osnerf hil emulate pluto)"
        )
    pos = views.drone_positions_m[idx]
    vel = flight_velocities(views.meta, pos, cfg.drone_speed_m_s)
    ch = drone_channels(views.folder, views.meta, pos, velocities_m_s=vel, movers_at_rest=True)
    gain = ch.path_gain_db
    ref = float(np.median(gain[~ch.outage])) if (~ch.outage).any() else 0.0
    assert ch.movers is not None  # movers_at_rest: every position's mover is traced
    links, snrs, outage, per_view = {}, {}, set(), {}
    for k, i in enumerate(idx):
        if ch.outage[k]:
            outage.add(i)
            continue
        first = ch.movers[k].cir(0.0)  # the trace at the view's position (cached)
        live = first.a[0] != 0
        snrs[i] = float(cfg.snr_db + gain[k] - ref)
        per_view[i] = {
            "paths": int(live.sum()),
            "max_doppler_hz": float(np.abs(first.doppler_hz[0][live]).max(initial=0.0)),
            "path_gain_db": float(gain[k]),
            "snr_db": snrs[i],
        }
        links[i] = ViewAirLink(
            ota,
            i,
            snrs[i],
            ch.movers[k],
            10 ** (-ref / 20),
            device,
            float(cfg.snr_db),
            int(cfg.seed),
            per_view[i],
        )
    fc = float(views.meta["carrier_frequency_hz"])
    spread = np.asarray(ch.stats["rms_doppler_spread_hz"], np.float64)[~ch.outage]
    info = TracedAir(
        scene=cfg.scene,
        radio_scene=views.meta.get("radio_scene", "radio/scene.xml"),
        carrier_frequency_hz=fc,
        drone_speed_m_s=float(cfg.drone_speed_m_s),
        max_doppler_hz=max_doppler_hz(cfg.drone_speed_m_s, fc),
        median_rms_doppler_spread_hz=float(np.median(spread)) if spread.size else None,
        reference_path_gain_db=ref,
        outage_views=sorted(outage),
        air_views=per_view,
        ray_solver=ch.solver,
        air_note="each view's emulated air is its drone's ray-traced paths (delay, gain, "
        "Doppler at the scene's carrier), gains over the median position's path gain, air "
        f"SNR {float(cfg.snr_db):g} dB there; re-traced every {RETRACE_WAVELENGTHS:g} "
        "wavelengths of flight within a burst (segments); every burst of a view starts at "
        "the drone's position",
    )
    return links, snrs, outage, info
