"""The radio side of a scene: the same meshes with ITU materials, ray-traced per drone position.

``write_radio_scene`` turns a :class:`SceneGeometry` into a sionna-rt XML scene whose
shapes are the very PLY files the optical renders use, so a drone's position fixes both
its camera view and its channel to the ground station; it adds the terrain around the
plot, which the cameras do not render, so the radio world's ground reaches past the ground
station. ``drone_channels`` asks ``phy.raytrace`` for the channel of every drone position;
``flight_velocities`` gives each drone its velocity along its ring, for a channel that
changes while it flies.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

import phy.raytrace as prt
from common import write_text
from osnerf.scenes.geometry import write_ply
from osnerf.scenes.spec import TERRAIN_MATERIAL, SceneGeometry

_TERRAIN_ID = "radio_terrain"
NUM_SUBCARRIERS = 64
SUBCARRIER_SPACING_HZ = 30e3
"""The subcarriers :func:`drone_channels` traces by default (those of ``osnerf run``'s
ray-traced link): a drone's gain is its mean ``|h|^2`` over them."""


def write_radio_scene(geometry: SceneGeometry, mesh_paths: dict[str, Path], folder: Path) -> Path:
    """Write ``folder/scene.xml`` (sionna-rt format, ITU radio materials); returns its path.

    Its shapes are the parts' PLY files (``mesh_paths``) and, when the geometry has one, the
    terrain, written as ``folder/terrain.ply`` (:data:`TERRAIN_MATERIAL`).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shapes = [
        (p.name, os.path.relpath(mesh_paths[p.name], folder), p.radio_material)
        for p in geometry.parts
    ]
    if geometry.terrain is not None:
        write_ply(geometry.terrain, folder / "terrain.ply")
        shapes.append((_TERRAIN_ID, "terrain.ply", TERRAIN_MATERIAL))
    lines = ['<scene version="2.1.0">']
    for m in sorted({s[2] for s in shapes}):
        lines += [
            f'  <bsdf type="itu-radio-material" id="itu_{m}">',
            f'    <string name="type" value="{m}"/>',
            '    <float name="thickness" value="0.1"/>',
            "  </bsdf>",
        ]
    for name, rel, material in shapes:
        lines += [
            f'  <shape type="ply" id={quoteattr(name)}>',
            f'    <string name="filename" value={quoteattr(rel)}/>',
            '    <boolean name="face_normals" value="true"/>',
            f'    <ref id="itu_{material}" name="bsdf"/>',
            "  </shape>",
        ]
    lines.append("</scene>")
    path = folder / "scene.xml"
    return write_text(path, "\n".join(lines) + "\n")


@dataclass
class DroneChannels:
    """The ray-traced channel of every drone position to the ground station.

    Attributes:
        h: [num_positions, num_subcarriers] complex64 frequency response (absolute gain).
        outage: [num_positions] bool, True where no propagation path exists.
        path_gain_db: [num_positions] float, mean |h|^2 in dB (-inf in outage).
        stats: per-position statistics from phy.raytrace (lists), or {}.
        subcarrier_frequencies_hz: [num_subcarriers] baseband offsets.
        movers: one ``phy.raytrace.MovingTransmitter`` per position when the drones move,
            else None.
        solver: the path solver's settings (``phy.raytrace.RayTracingConfig`` as a dict:
            seed, deterministic, interactions traced, rays shot).
    """

    h: np.ndarray
    outage: np.ndarray
    path_gain_db: np.ndarray
    stats: dict
    subcarrier_frequencies_hz: np.ndarray
    movers: list | None = None
    solver: dict = field(default_factory=dict)


def band_gain_db(h: np.ndarray) -> np.ndarray:
    """[num_positions] mean ``|h|^2`` over the subcarriers of [num_positions, num_subcarriers]
    responses, in dB (``-inf`` where h is 0): the paths add with their phases, so a drone in
    a fade of its line of sight and ground reflection receives less than their sum of powers."""
    with np.errstate(divide="ignore"):
        return 10 * np.log10(np.mean(np.abs(np.asarray(h)) ** 2, axis=1))


def radio_scene_path(folder: Path, meta: dict) -> str:
    """The sionna-rt scene of a dataset: a built-in scene name or the folder's XML."""
    rs = meta.get("radio_scene", "radio/scene.xml")
    return str(Path(folder) / rs) if rs.endswith(".xml") else rs


def subcarrier_frequencies(num_subcarriers: int, spacing_hz: float) -> np.ndarray:
    """[num_subcarriers] baseband subcarrier offsets centred on 0 (sionna's convention)."""
    k = np.arange(num_subcarriers) - (num_subcarriers // 2)
    return (k * spacing_hz).astype(np.float64)


def flight_velocities(meta: dict, positions_m: np.ndarray, speed_m_s: float) -> np.ndarray:
    """[num_positions, 3] velocities of drones flying their ring at ``speed_m_s``.

    Each drone flies level along the tangent of its circle about the vertical axis through
    ``meta["trajectory_center_m"]`` (counter-clockwise seen from above, the order in which
    the ring's views are laid out); a drone right above the centre flies along +x.
    """
    pos = np.asarray(positions_m, np.float64).reshape(-1, 3)
    centre = np.asarray(meta.get("trajectory_center_m", (0.0, 0.0, 0.0)), np.float64)
    r = pos[:, :2] - centre[:2]
    tangent = np.c_[-r[:, 1], r[:, 0], np.zeros(len(pos))]  # z x r
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    tangent = np.where(norm > 1e-9, tangent / np.maximum(norm, 1e-300), [1.0, 0.0, 0.0])
    return float(speed_m_s) * tangent


def drone_channels(
    folder: Path,
    meta: dict,
    positions_m: np.ndarray,
    num_subcarriers: int = NUM_SUBCARRIERS,
    subcarrier_spacing_hz: float = SUBCARRIER_SPACING_HZ,
    max_depth: int = 2,
    velocities_m_s: np.ndarray | None = None,
    movers_at_rest: bool = False,
) -> DroneChannels:
    """Ray-trace each drone position to the ground station (``phy.raytrace.RayTracer``).

    Args:
        folder, meta: a dataset folder and its transforms.json dict (radio scene, ground
            station, carrier).
        positions_m: [num_positions, 3] transmitter (drone) positions, metres.
        velocities_m_s: [num_positions, 3] drone velocities (e.g. :func:`flight_velocities`);
            None or all zero: at rest.
        movers_at_rest: give ``movers`` for drones at rest too (their paths, no Doppler).
    Returns:
        :class:`DroneChannels` with the absolute (path-loss included) CFR per position at
        t = 0, the Doppler statistics and, for moving drones, their movers.
    """
    freqs = subcarrier_frequencies(num_subcarriers, subcarrier_spacing_hz)
    tracer = prt.RayTracer(
        radio_scene_path(folder, meta),
        rx_position_m=tuple(float(x) for x in meta["ground_station_m"]),
        carrier_frequency_hz=float(meta["carrier_frequency_hz"]),
        config=prt.RayTracingConfig(max_depth=max_depth),
    )
    pos = np.asarray(positions_m, np.float64)
    h, outage = tracer.cfr(pos, freqs)
    h = np.asarray(h.detach().cpu()).astype(np.complex64)
    outage = np.asarray(outage.detach().cpu()).astype(bool)
    gain_db = band_gain_db(h)
    moving = velocities_m_s is not None and np.any(velocities_m_s)
    vel = np.asarray(velocities_m_s, np.float64) if moving else None
    st = tracer.stats(pos, vel)
    if movers_at_rest and not moving:
        moving, vel = True, np.zeros_like(pos)
    movers = [prt.MovingTransmitter(tracer, p, v) for p, v in zip(pos, vel)] if moving else None
    stats = {
        "path_gain_db": st.path_gain_db.tolist(),
        "rms_delay_spread_s": st.rms_delay_spread_s.tolist(),
        "k_factor_db": st.k_factor_db.tolist(),
        "num_paths": st.num_paths.tolist(),
        "los": st.los.tolist(),
        "outage": st.outage.tolist(),
        "rms_doppler_spread_hz": st.rms_doppler_spread_hz.tolist(),
    }
    solver = dataclasses.asdict(tracer.config)
    return DroneChannels(h, outage, gain_db, stats, freqs, movers, solver)
