"""The run's links: one ``phy.Link`` per drone view, with the SNR it runs at.

Every receiver is unbiased (zero-forcing, sionna's LMMSE convention) and reports the
effective noise variance per symbol: perfect CSI on flat channels, LS pilot estimates over
OFDM for ``tdl``/``cdl``, each drone position's ray-traced response for ``raytraced`` (that
changes over the view's symbols when the drones fly, ``drone_speed_m_s``), and
``phy`` OFDM frames between two HackRFs for ``ota`` (over an emulated air that is fixed or,
with ``ota_air`` "raytraced", each view's ray-traced channel: :mod:`osnerf.run.ota_air`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import phy
from osnerf.run.config import OTA, RunConfig


@dataclass
class RunLinks:
    """Attributes:
    links: view -> ``phy.Link``; snr_db: view -> the SNR its link runs at.
    outage: views without any propagation path (never sent).
    info: what the report says about the channel.
    ota: the over-the-air link (holds the radios, counts frames), else None.
    """

    links: dict[int, phy.Link]
    snr_db: dict[int, float]
    outage: set[int] = field(default_factory=set)
    info: dict = field(default_factory=dict)
    ota: object | None = None

    def close(self) -> None:
        if self.ota is not None:
            measured = [float(v) for v in self.ota.snr_db_measured if v is not None]
            self.info.update(
                frames_sent=int(self.ota.frames_sent),
                frames_lost=int(self.ota.frames_lost),
                snr_db_measured=round(float(np.mean(measured)), 3) if measured else None,
            )
            self.ota.close()


def build_links(cfg: RunConfig, views, indices) -> RunLinks:
    """Links for the drone views ``indices`` of ``views`` under ``cfg.channel``."""
    idx = [int(i) for i in indices]
    snr = {i: float(cfg.snr_db) for i in idx}
    if cfg.channel == OTA:
        return _ota_links(cfg, views, idx, snr)
    if cfg.channel == "raytraced":
        return _raytraced_links(cfg, views, idx)
    link = phy.channel_link(cfg.channel)
    if cfg.channel in phy.OFDM_CHANNELS:
        info = {"channel": cfg.channel, "csi": "ls (pilots)", "ofdm": True}
    else:
        info = {"channel": cfg.channel, "csi": "perfect"}
    info["equalizer"] = "zf (unbiased) + per-symbol noise variance"
    info["channel_params"] = phy.channel_record(link)
    return RunLinks({i: link for i in idx}, snr, info=info)


def _ota_links(cfg: RunConfig, views, idx: list[int], snr: dict) -> RunLinks:
    from hil import OtaConfig
    from osnerf.ota_link import (
        DEFAULT_DELAY_S,
        DEFAULT_MULTIPATH,
        DEFAULT_PPM,
        OtaLink,
        open_radios,
    )

    ota_cfg = OtaConfig()
    tx, rx, emu = open_radios(cfg.ota_device, cfg.snr_db, ota_cfg, seed=cfg.seed)
    link = OtaLink(tx, rx, float(cfg.snr_db), ota_cfg, emu)
    info = {
        "channel": OTA,
        "device": cfg.ota_device,
        "frames": "phy OFDM frames, hil PAPR control, int8",
        "sample_rate_hz": ota_cfg.sample_rate_hz,
        "center_freq_hz": ota_cfg.center_freq_hz,
        "symbols_per_frame": ota_cfg.symbols_per_frame,
    }
    if getattr(cfg, "ota_air", "fixed") == "raytraced":
        from osnerf.run.ota_air import raytraced_air_links

        try:
            links, snrs, outage, air = raytraced_air_links(cfg, views, idx, link, cfg.ota_device)
        except BaseException:
            link.close()
            raise
        if emu is not None:
            info.update(ppm=list(DEFAULT_PPM), delay_s=DEFAULT_DELAY_S)
        return RunLinks(links, snrs, outage, {**info, **air, "air_snr_db": float(cfg.snr_db)}, link)
    if emu is not None:
        info.update(
            ppm=list(DEFAULT_PPM),
            multipath=[[d, str(g)] for d, g in DEFAULT_MULTIPATH],
            delay_s=DEFAULT_DELAY_S,
            air_snr_db=float(cfg.snr_db),
        )
    elif getattr(tx, "air_settable", False):  # an emulated Pluto: open_radios set its air
        info.update(air_snr_db=float(cfg.snr_db))
    else:  # real boards: nobody sets the air; the codec assumes snr_db, the receiver measures
        info.update(
            air_snr_db=None,
            snr_db_assumed=float(cfg.snr_db),
            note="the air between real boards is not set: snr_db is the SNR the codec and "
            "the receiver assume, snr_db_measured the receiver's pilot estimate",
        )
    return RunLinks({i: link for i in idx}, snr, info=info, ota=link)


def _raytraced_links(cfg: RunConfig, views, idx: list[int]) -> RunLinks:
    from osnerf.scenes import drone_channels, flight_velocities
    from phy.raytrace import PerPositionChannel

    pos = views.drone_positions_m[idx]
    vel = flight_velocities(views.meta, pos, cfg.drone_speed_m_s)
    ch = drone_channels(views.folder, views.meta, pos, velocities_m_s=vel)
    gain = ch.path_gain_db
    ref = float(np.median(gain[~ch.outage])) if (~ch.outage).any() else 0.0
    links, snrs, outage = {}, {}, set()
    for k, i in enumerate(idx):
        if ch.outage[k]:
            outage.add(i)
            continue
        mover = None if ch.movers is None else ch.movers[k]
        channel = PerPositionChannel(
            ch.h[k], mover, ch.subcarrier_frequencies_hz, 1.0 / cfg.symbol_rate_hz
        )
        links[i] = phy.FlatLink(channel, csi="perfect", equalizer="zf")
        snrs[i] = float(cfg.snr_db + gain[k] - ref)
    info = {
        "channel": "raytraced",
        "csi": "perfect" if ch.movers is None else "perfect (h at each symbol's time)",
        "equalizer": "zf (unbiased) + per-symbol noise variance",
        "path_gain_db": {i: float(g) for i, g in zip(idx, gain)},
        "reference_path_gain_db": ref,
        "outage_views": sorted(outage),
        "num_subcarriers": int(ch.h.shape[1]),
        "carrier_frequency_hz": float(views.meta["carrier_frequency_hz"]),
        "stats": ch.stats,
        "ray_solver": ch.solver,
        **_motion_info(cfg, views.meta, ch, idx),
    }
    return RunLinks(links, snrs, outage, info)


def _motion_info(cfg: RunConfig, meta: dict, ch, idx: list[int]) -> dict:
    """What the report says about the drones' motion: speed, Doppler, symbol timing."""
    from phy.raytrace import RETRACE_WAVELENGTHS, max_doppler_hz

    spread = np.asarray(ch.stats["rms_doppler_spread_hz"], np.float64)
    live = ~np.asarray(ch.outage, bool)
    return {
        "drone_speed_m_s": float(cfg.drone_speed_m_s),
        "max_doppler_hz": max_doppler_hz(cfg.drone_speed_m_s, meta["carrier_frequency_hz"]),
        "rms_doppler_spread_hz": {i: float(s) for i, s, ok in zip(idx, spread, live) if ok},
        "median_rms_doppler_spread_hz": float(np.median(spread[live])) if live.any() else None,
        "motion": "drones fly level along their ring (counter-clockwise seen from above); "
        "symbol i of a view is sent at i / symbol_rate_hz and rides subcarrier i mod "
        "num_subcarriers; each path's Doppler shift (sionna-rt) turns its phase, re-traced "
        f"every {RETRACE_WAVELENGTHS:g} wavelengths of flight"
        if cfg.drone_speed_m_s > 0
        else "drones at rest: one fixed response per position",
    }
