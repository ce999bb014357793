"""The run's links: one ``phy.Link`` per drone view, with the SNR it runs at.

Every receiver is unbiased (zero-forcing, sionna's LMMSE convention) and reports the
effective noise variance per symbol: perfect CSI on flat channels, LS pilot estimates over
OFDM for ``tdl``/``cdl``, each drone position's ray-traced response for ``raytraced``, and
``phy`` OFDM frames between two HackRFs for ``ota``.
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
        return _ota_links(cfg, idx, snr)
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


def _ota_links(cfg: RunConfig, idx: list[int], snr: dict) -> RunLinks:
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
    from osnerf.scenes import drone_channels
    from phy.raytrace import PerPositionChannel

    ch = drone_channels(views.folder, views.meta, views.drone_positions_m[idx])
    gain = ch.path_gain_db
    ref = float(np.median(gain[~ch.outage])) if (~ch.outage).any() else 0.0
    links, snrs, outage = {}, {}, set()
    for k, i in enumerate(idx):
        if ch.outage[k]:
            outage.add(i)
            continue
        links[i] = phy.FlatLink(PerPositionChannel(ch.h[k]), csi="perfect", equalizer="zf")
        snrs[i] = float(cfg.snr_db + gain[k] - ref)
    info = {
        "channel": "raytraced",
        "csi": "perfect",
        "equalizer": "zf (unbiased) + per-symbol noise variance",
        "path_gain_db": {i: float(g) for i, g in zip(idx, gain)},
        "reference_path_gain_db": ref,
        "outage_views": sorted(outage),
        "num_subcarriers": int(ch.h.shape[1]),
        "carrier_frequency_hz": float(views.meta["carrier_frequency_hz"]),
        "stats": ch.stats,
    }
    return RunLinks(links, snrs, outage, info)
