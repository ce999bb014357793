"""The run's links: one ``phy.Link`` per drone view, with the SNR it runs at.

Every receiver is unbiased (zero-forcing, sionna's LMMSE convention) and reports the
effective noise variance per symbol: perfect CSI on flat channels, LS pilot estimates over
OFDM for ``tdl``/``cdl``, each drone position's ray-traced response for ``raytraced`` (that
changes over the view's symbols when the drones fly, ``drone_speed_m_s``; known exactly, or
estimated from pilots on an OFDM grid with ``csi``), and
``phy`` OFDM frames between two HackRFs for ``ota`` (over an emulated air that is fixed or,
with ``ota_air`` "raytraced", each view's ray-traced channel: :mod:`osnerf.run.ota_air`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import phy
from hil import OtaConfig
from osnerf.link_report import (
    AirSnr,
    FrameCounts,
    LinkReport,
    Motion,
    Positions,
    Radios,
    Receiver,
    Trace,
)
from osnerf.ota_link import DEFAULT_DELAY_S, DEFAULT_MULTIPATH, DEFAULT_PPM, OtaLink, open_radios
from osnerf.run.config import OTA, RunConfig
from osnerf.run.ota_air import raytraced_air_links
from osnerf.scenes import drone_channels, flight_velocities
from phy.ofdm import LMMSEEstimator
from phy.raytrace import RETRACE_WAVELENGTHS, PerPositionChannel, max_doppler_hz


@dataclass
class RunLinks:
    """Attributes:
    links: view -> ``phy.Link``; snr_db: view -> the SNR its link runs at.
    outage: views without any propagation path (never sent).
    report: what the report says about the channel (the frame counts come when it closes).
    ota: the over-the-air link (holds the radios, counts frames), else None.
    """

    links: dict[int, phy.Link]
    snr_db: dict[int, float]
    report: LinkReport
    outage: set[int] = field(default_factory=set)
    ota: OtaLink | None = None

    def close(self) -> None:
        if self.ota is not None:
            measured = [float(v) for v in self.ota.snr_db_measured if v is not None]
            self.report.counts = FrameCounts(
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
        receiver = Receiver(csi="ls (pilots)", ofdm=True)
    else:
        receiver = Receiver(csi="perfect")
    report = LinkReport(cfg.channel, receiver=receiver, channel_params=phy.channel_record(link))
    return RunLinks({i: link for i in idx}, snr, report)


def _ota_links(cfg: RunConfig, views, idx: list[int], snr: dict) -> RunLinks:
    ota_cfg = OtaConfig()
    tx_args, rx_args = cfg.ota_tx_args, cfg.ota_rx_args
    tx, rx, emu = open_radios(
        cfg.ota_device,
        cfg.snr_db,
        ota_cfg,
        seed=cfg.seed,
        tx_serial=tx_args,
        rx_serial=tx_args if rx_args is None else rx_args,
    )
    link = OtaLink(tx, rx, float(cfg.snr_db), ota_cfg, emu)
    radios = Radios(
        device=cfg.ota_device,
        frames="phy OFDM frames, hil PAPR control, int8",
        sample_rate_hz=ota_cfg.sample_rate_hz,
        center_freq_hz=ota_cfg.center_freq_hz,
        symbols_per_frame=ota_cfg.symbols_per_frame,
    )
    report = LinkReport(OTA, radios=radios)
    if emu is not None:
        radios.ppm, radios.delay_s = list(DEFAULT_PPM), DEFAULT_DELAY_S
    if cfg.ota_air == "raytraced":
        try:
            links, snrs, outage, air = raytraced_air_links(cfg, views, idx, link, cfg.ota_device)
        except BaseException:
            link.close()
            raise
        report.traced_air, report.air = air, AirSnr(float(cfg.snr_db))
        return RunLinks(links, snrs, report, outage, link)
    if emu is not None:
        radios.multipath = [[d, str(g)] for d, g in DEFAULT_MULTIPATH]
        report.air = AirSnr(float(cfg.snr_db))
    elif tx.air_settable:  # an emulated Pluto: open_radios set its air
        report.air = AirSnr(float(cfg.snr_db))
    else:  # real boards: nobody sets the air; the codec assumes snr_db, the receiver measures
        report.air = AirSnr(
            air_snr_db=None,
            snr_db_assumed=float(cfg.snr_db),
            note="the air between real boards is not set: snr_db is the SNR the codec and "
            "the receiver assume, snr_db_measured the receiver's pilot estimate",
        )
    return RunLinks({i: link for i in idx}, snr, report, ota=link)


RAYTRACED_GRID = phy.ResourceGrid(fft_size=64, subcarrier_spacing_hz=30e3)
"""The OFDM grid of the ray-traced link with estimated CSI (``RunConfig.csi`` "ls"/"lmmse"):
the traced subcarriers (64 at 30 kHz), a 16-sample cyclic prefix (an OFDM symbol lasts
41.7 us), 14 OFDM symbols per slot with pilots on every used subcarrier of symbols 2 and 11
(9 symbols, 375 us apart), 6 + 5 guard carriers and a null DC: 624 data symbols per slot of
583 us."""
LMMSE_DELAY_SPREAD_S = 100e-9
"""RMS delay spread of the TDL-A frequency covariance the LMMSE receiver assumes."""


def raytraced_link(cfg: RunConfig, h, mover, estimator=None) -> phy.Link:
    """One drone position's link: perfect CSI of each symbol's h on the traced subcarriers
    in turn (``cfg.csi`` None or "perfect"), or the :data:`RAYTRACED_GRID` with pilots and
    the receiver's LS or LMMSE (``estimator``, a ``phy.ofdm.LMMSEEstimator``) estimates.

    Args:
        h: [fft_size] complex64 response at t = 0 on the grid's subcarriers.
        mover: the drone's ``phy.raytrace.MovingTransmitter`` (or None: at rest).
    """
    g = RAYTRACED_GRID
    channel = PerPositionChannel(
        h,
        mover,
        g.subcarrier_frequencies_hz,
        1.0 / cfg.symbol_rate_hz,
        ofdm_symbol_duration_s=g.symbol_length / g.sample_rate_hz,
    )
    if cfg.csi in (None, "perfect"):
        return phy.FlatLink(channel, csi="perfect", equalizer="zf")
    return phy.OFDMLink(g, channel, csi=cfg.csi, equalizer="zf", estimator=estimator)


def raytraced_estimator(cfg: RunConfig, carrier_frequency_hz: float):
    """The LMMSE estimator of ``cfg.csi == "lmmse"`` (None otherwise): TDL-A at
    :data:`LMMSE_DELAY_SPREAD_S` in frequency, Jakes at the drones' speed in time."""
    if cfg.csi != "lmmse":
        return None

    return LMMSEEstimator(
        RAYTRACED_GRID, float(cfg.drone_speed_m_s), carrier_frequency_hz, LMMSE_DELAY_SPREAD_S
    )


def _raytraced_links(cfg: RunConfig, views, idx: list[int]) -> RunLinks:
    pos = views.drone_positions_m[idx]
    meta = views.meta
    if cfg.ground_station_m is not None:  # the radio end moved; the drones and views stay
        meta = {**meta, "ground_station_m": list(cfg.ground_station_m)}
    vel = flight_velocities(meta, pos, cfg.drone_speed_m_s)
    g = RAYTRACED_GRID
    ch = drone_channels(
        views.folder,
        meta,
        pos,
        num_subcarriers=g.fft_size,
        subcarrier_spacing_hz=g.subcarrier_spacing_hz,
        velocities_m_s=vel,
    )
    gain = ch.path_gain_db
    ref = float(np.median(gain[~ch.outage])) if (~ch.outage).any() else 0.0
    fc = float(views.meta["carrier_frequency_hz"])
    estimator = raytraced_estimator(cfg, fc)
    links, snrs, outage = {}, {}, set()
    for k, i in enumerate(idx):
        if ch.outage[k]:
            outage.add(i)
            continue
        mover = None if ch.movers is None else ch.movers[k]
        links[i] = raytraced_link(cfg, ch.h[k], mover, estimator)
        snrs[i] = float(cfg.snr_db + gain[k] - ref)
    positions, params = _position_info(cfg, meta, pos, idx)
    report = LinkReport(
        "raytraced",
        receiver=_csi_info(cfg, ch.movers is not None),
        trace=Trace(
            path_gain_db={i: float(g) for i, g in zip(idx, gain)},
            reference_path_gain_db=ref,
            outage_views=sorted(outage),
            num_subcarriers=int(ch.h.shape[1]),
            carrier_frequency_hz=fc,
            stats=ch.stats,
            ray_solver=ch.solver,
        ),
        motion=_motion_info(cfg, meta, ch, idx),
        positions=positions,
        channel_params=params,
    )
    return RunLinks(links, snrs, report, outage)


def ground_station_warning(meta: dict, gs) -> str | None:
    """Why the ground station's antenna sits where no antenna can (inside an object's box, or
    below the lowest surface of the scene), or None. ``meta``: the scene's ``object_aabb``
    (object -> [[min x, y, z], [max x, y, z]] metres); ``gs``: [3] metres."""
    gs = np.asarray(gs, np.float64).reshape(3)
    boxes = {o: np.asarray(b, np.float64) for o, b in meta.get("object_aabb", {}).items()}
    if not boxes:
        return None
    at = ", ".join(f"{v:g}" for v in gs)
    floor = min(b[0, 2] for b in boxes.values())
    if gs[2] < floor:
        return (
            f"the ground station at ({at}) m is {floor - gs[2]:.3g} m below the scene's lowest "
            f"surface (z = {floor:g} m): its rays start under the terrain"
        )
    for name, b in boxes.items():
        if name != "ground" and np.all(gs > b[0]) and np.all(gs < b[1]):
            return (
                f"the ground station at ({at}) m lies inside the box of object {name!r} "
                f"({', '.join(f'{v:g}' for v in b[0])} to {', '.join(f'{v:g}' for v in b[1])} m)"
            )
    return None


def _position_info(
    cfg: RunConfig, meta: dict, pos: np.ndarray, idx: list[int]
) -> tuple[Positions, dict]:
    """Where the radio ends were: the ground station (the scene's or ``--ground-station``),
    the drones' ring and each view's drone; and the channel's parameters, which repeat the
    geometry that fixes the ray-traced channel, so each sweep point records it."""
    gs = np.asarray(meta["ground_station_m"], np.float64)
    dist = np.linalg.norm(pos - gs, axis=1)  # [num_views] metres
    ring = {
        "centre_m": [float(v) for v in meta["trajectory_center_m"]],
        "radius_m": float(meta["trajectory_radius_m"]),
        "ring_scale": float(cfg.ring_scale),
    }
    params = {
        "channel": "raytraced",
        "scene": meta["scene"],
        "ground_station_m": gs.tolist(),
        "ground_station_from": "scene" if cfg.ground_station_m is None else "--ground-station",
        "ring_radius_m": ring["radius_m"],
        "ring_scale": ring["ring_scale"],
        "median_distance_m": float(np.median(dist)),
        "drone_speed_m_s": float(cfg.drone_speed_m_s),
        "carrier_frequency_hz": float(meta["carrier_frequency_hz"]),
    }
    where = ground_station_warning(meta, gs)
    if where is not None:
        import sys

        print(f"run: warning: {where}", file=sys.stderr)
    positions = Positions(
        ground_station_m=params["ground_station_m"],
        ground_station_from=params["ground_station_from"],
        ground_station_warning=where,
        drone_ring=ring,
        drone_positions_m={i: [float(v) for v in p] for i, p in zip(idx, pos)},
        distance_to_ground_station_m={i: float(d) for i, d in zip(idx, dist)},
    )
    return positions, params


def _csi_info(cfg: RunConfig, moving: bool) -> Receiver:
    """What the report says about the ray-traced link's receiver: its CSI, and with
    estimates the grid, the pilot pattern and spacing, and the interpolation."""
    if cfg.csi in (None, "perfect"):
        return Receiver(csi="perfect" if not moving else "perfect (h at each symbol's time)")
    g = RAYTRACED_GRID
    t_sym = g.symbol_length / g.sample_rate_hz
    how = {
        "ls": "ls (pilots): LS on each pilot, linear interpolation across the subcarriers of "
        "each pilot symbol, then linear in time between the slot's pilot symbols, held "
        "before the first and after the last; its error variance counts the pilots' noise, "
        "not the channel's change between them",
        "lmmse": "lmmse (pilots): sionna's LMMSEChannelEstimator on the LS pilot estimates, "
        f"frequency then time, TDL-A covariance at {LMMSE_DELAY_SPREAD_S * 1e9:g} ns RMS "
        f"delay spread, Jakes time covariance at {cfg.drone_speed_m_s:g} m/s, slot by slot",
    }[cfg.csi]
    return Receiver(
        csi=how,
        ofdm=True,
        grid={
            "fft_size": g.fft_size,
            "subcarrier_spacing_hz": g.subcarrier_spacing_hz,
            "cp_length": g.cp_length,
            "ofdm_symbol_duration_s": t_sym,
            "num_ofdm_symbols_per_slot": g.num_ofdm_symbols,
            "pilot_ofdm_symbols": list(g.pilot_ofdm_symbols),
            "pilot_subcarrier_spacing": g.pilot_subcarrier_spacing,
            "max_pilot_spacing_s": float(np.diff(g.pilot_ofdm_symbols).max() * t_sym),
            "data_symbols_per_slot": g.num_data_symbols,
        },
        timing="OFDM symbol l of a block is sent at l * ofdm_symbol_duration_s, the copies "
        "of a block one after the other; air time in the report counts data symbols at "
        "symbol_rate_hz",
    )


def _motion_info(cfg: RunConfig, meta: dict, ch, idx: list[int]) -> Motion:
    """What the report says about the drones' motion: speed, Doppler, symbol timing."""
    when = (
        "symbol i of a view is sent at i / symbol_rate_hz and rides subcarrier i mod "
        "num_subcarriers, from the view's position at t = 0"
        if cfg.csi in (None, "perfect")
        else "OFDM symbol l of a view's grid is sent at l * ofdm_symbol_duration_s, from the "
        "view's position at t = 0"
    )
    spread = np.asarray(ch.stats["rms_doppler_spread_hz"], np.float64)
    live = ~np.asarray(ch.outage, bool)
    return Motion(
        drone_speed_m_s=float(cfg.drone_speed_m_s),
        max_doppler_hz=max_doppler_hz(cfg.drone_speed_m_s, meta["carrier_frequency_hz"]),
        rms_doppler_spread_hz={i: float(s) for i, s, ok in zip(idx, spread, live) if ok},
        median_rms_doppler_spread_hz=float(np.median(spread[live])) if live.any() else None,
        motion="drones fly level along their ring (counter-clockwise seen from above); "
        f"{when}; a view's copies are sent one after the other, so each later copy sees the "
        "channel further along the flight; each path's Doppler shift (sionna-rt) turns its "
        f"phase, re-traced every {RETRACE_WAVELENGTHS:g} wavelengths of flight"
        if cfg.drone_speed_m_s > 0
        else "drones at rest: one fixed response per position",
    )
