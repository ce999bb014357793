"""A scene's radio map: path gain at the drones' altitudes, with the candidate drone positions.

Drones transmit to the ground station. sionna-rt's ``RadioMapSolver`` shoots rays from a
transmitter, so the map puts the *ground station* in that role and measures horizontal
planes at the altitudes of the drone rings: by reciprocity (isotropic antennas, one
polarisation) a cell's path gain is that of a drone transmitting from it to the ground
station (:func:`phy.raytrace.radio_map`). Beside the map, each candidate position is traced
with the path solver that ``--channel raytraced`` uses, so the picture shows both. The map's
cells add their paths' powers (sionna-rt's radio maps); a candidate's traced gain is the
run's, its paths added with their phases over the run's subcarriers, so it shows the fading
of, say, a line of sight and its ground reflection that the map averages out.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import phy.raytrace as prt
from common import InputError
from osnerf.scenes.dataset import RenderConfig, check_demand, trajectory
from osnerf.scenes.radio import (
    NUM_SUBCARRIERS,
    SUBCARRIER_SPACING_HZ,
    band_gain_db,
    subcarrier_frequencies,
    write_radio_scene,
)
from osnerf.scenes.registry import get_scene
from osnerf.scenes.render import write_meshes
from osnerf.scenes.spec import SceneGeometry

MAP_MARGIN_M = 0.15
"""The map spans the candidates, the scene and the ground station, plus this fraction of
its largest side on each face."""
DEFAULT_CELLS_PER_SIDE = 60
MAX_CELLS_PER_SIDE = 4096
"""The most cells along a side that the ray tracer's map takes (``phy.raytrace.radio_map``)."""
"""Cells along the larger side when no cell size is given."""


@dataclass
class SceneRadioMap:
    """A radio map of a scene and its candidate drone positions.

    Attributes:
        scene: registry name; target: the objects the drone rings circle.
        geometry: the built scene (its floor plan is drawn under the map).
        map: :class:`phy.raytrace.RadioMap` (the ground station transmits, by reciprocity).
        candidates_m: [num_views, 3] candidate (train) drone positions.
        map_path_gain_db: [num_views] the map's cell at each candidate.
        traced_path_gain_db: [num_views] each candidate traced with the path solver: its
            mean ``|h|^2`` over the run's subcarriers (``-inf`` in outage).
        los: [num_views] bool, a line-of-sight path exists.
        carrier_frequency_hz: the scene's carrier.
    """

    scene: str
    target: tuple[str, ...]
    geometry: SceneGeometry
    map: object
    candidates_m: np.ndarray
    map_path_gain_db: np.ndarray
    traced_path_gain_db: np.ndarray
    los: np.ndarray
    carrier_frequency_hz: float

    @property
    def relative_snr_db(self) -> np.ndarray:
        """[num_views] what ``--channel raytraced`` adds to ``--snr-db`` at each candidate:
        its traced gain minus the median over the candidates not in outage."""
        g = self.traced_path_gain_db
        ok = np.isfinite(g)
        return g - (float(np.median(g[ok])) if ok.any() else 0.0)


def map_extent(points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre [2], size [2]) of a square-margined box around ``points_m`` [n, >= 2]."""
    lo, hi = points_m[:, :2].min(0), points_m[:, :2].max(0)
    pad = MAP_MARGIN_M * float((hi - lo).max())
    return (lo + hi) / 2, (hi - lo) + 2 * pad


def scene_radio_map(
    scene: str,
    target=None,
    render: RenderConfig | None = None,
    map_config=None,
    cell_size_m: float | None = None,
    ground_station_m=None,
) -> SceneRadioMap:
    """The radio map of ``scene`` at its drone rings' altitudes (around ``target``).

    Args:
        scene: registry name; target: objects the rings circle (default: the scene's
            default demand), as ``osnerf run`` places its drones.
        render: the ring settings (``num_train_views``, ``radius_scale``).
        map_config: :class:`phy.raytrace.RadioMapConfig` (its ``max_depth`` and ``seed``
            also trace the candidates).
        cell_size_m: cell side; None: the larger side over :data:`DEFAULT_CELLS_PER_SIDE`.
        ground_station_m: (x, y, z) metres in place of the scene's own ground station (as
            ``osnerf run --ground-station``); None: the scene's.
    """
    info = get_scene(scene)
    target = check_demand(scene, target or info.default_demand)
    render = render or RenderConfig()
    map_config = map_config or prt.RadioMapConfig()
    geometry = info.build()
    train, _, _, _ = trajectory(
        geometry, target, info.fov_deg, info.elevations_deg, info.min_radius_m, render
    )
    gs = np.asarray(
        geometry.ground_station_m if ground_station_m is None else ground_station_m, np.float64
    )
    centre, size = map_extent(np.concatenate([train, geometry.bounds_m, gs[None]]))
    cell = cell_size_m if cell_size_m is not None else float(size.max()) / DEFAULT_CELLS_PER_SIDE
    if float(size.max()) / cell > MAX_CELLS_PER_SIDE:  # refused before any tracing
        raise InputError(
            f"cell_size_m {cell:g} gives more than {MAX_CELLS_PER_SIDE} cells along the map's "
            f"{float(size.max()):g} m side: give at least "
            f"{float(size.max()) / MAX_CELLS_PER_SIDE:.3g}"
        )
    altitudes = np.unique(np.round(train[:, 2], 6))
    with tempfile.TemporaryDirectory(prefix="osnerf-radiomap-") as tmp:
        radio = geometry.radio_scene
        if radio is None:
            meshes = write_meshes(geometry, Path(tmp) / "meshes")
            radio = str(write_radio_scene(geometry, meshes, Path(tmp) / "radio"))
        rmap = prt.radio_map(
            radio, gs, info.carrier_frequency_hz, centre, size, altitudes, cell, map_config
        )
        tracer = prt.RayTracer(
            radio,
            rx_position_m=tuple(gs),
            carrier_frequency_hz=info.carrier_frequency_hz,
            config=prt.RayTracingConfig(max_depth=map_config.max_depth, seed=map_config.seed),
        )
        st = tracer.stats(train)
        h, _ = tracer.cfr(train, subcarrier_frequencies(NUM_SUBCARRIERS, SUBCARRIER_SPACING_HZ))
    traced = np.where(st.outage, -np.inf, band_gain_db(h.numpy()))
    return SceneRadioMap(
        scene,
        target,
        geometry,
        rmap,
        train,
        rmap.at(train),
        traced,
        np.asarray(st.los, bool),
        float(info.carrier_frequency_hz),
    )


def _floor_plan(ax, geometry: SceneGeometry) -> None:
    """The parts' footprints (every triangle projected onto the ground), ground outlined."""
    from matplotlib.collections import PolyCollection

    for part in geometry.parts:
        tri = part.mesh.vertices_m[part.mesh.faces][..., :2]  # [num_faces, 3, 2]
        if part.object_name == "ground":
            ax.add_collection(
                PolyCollection(tri, facecolors="none", edgecolors="0.5", linewidths=0.1)
            )
        else:
            ax.add_collection(
                PolyCollection(tri, facecolors="0.85", edgecolors="0.3", linewidths=0.2, alpha=0.5)
            )


def plot_radio_map(rm: SceneRadioMap, marked=None):
    """A figure with one panel per altitude: the map over the floor plan, the candidates as
    circles coloured by their traced gain (same scale) and numbered by view, the ground
    station as a star. ``marked``: {label: view indices} drawn as extra rings (e.g. the
    views each selection chose)."""
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    m = rm.map
    g = m.path_gain_db
    traced = rm.traced_path_gain_db[np.isfinite(rm.traced_path_gain_db)]
    finite = g[np.isfinite(g)]
    lo = float(traced.min()) if traced.size else float(np.percentile(finite, 2))
    hi = float(traced.max()) if traced.size else float(finite.max())
    norm = Normalize(lo - 6.0, hi + 6.0)  # the candidates' range; nearer the station saturates
    n = len(m.altitudes_m)
    fig = Figure(figsize=(5.2 * n + 1.0, 5.0))
    axes = fig.subplots(1, n, squeeze=False)[0]
    half = m.cell_size_m / 2
    extent = (m.x_m[0] - half, m.x_m[-1] + half, m.y_m[0] - half, m.y_m[-1] + half)
    rings = ("red", "cyan", "magenta", "orange")
    for k, (ax, z) in enumerate(zip(axes, m.altitudes_m)):
        im = ax.imshow(g[k], origin="lower", extent=extent, cmap="viridis", norm=norm)
        _floor_plan(ax, rm.geometry)
        on = np.flatnonzero(np.abs(rm.candidates_m[:, 2] - z) < 1e-3)
        c = rm.candidates_m[on]
        ax.scatter(
            c[:, 0],
            c[:, 1],
            c=np.clip(rm.traced_path_gain_db[on], norm.vmin, None),
            cmap="viridis",
            norm=norm,
            s=60,
            edgecolors="white",
            linewidths=1.0,
            zorder=3,
        )
        for v in on:
            ax.annotate(
                str(v),
                rm.candidates_m[v, :2],
                xytext=(4, 4),
                textcoords="offset points",
                fontsize=7,
                color="white",
            )
        here = set(on.tolist())
        for j, ((label, views), col) in enumerate(zip((marked or {}).items(), rings)):
            sel = [int(v) for v in views if int(v) in here]
            ax.scatter(
                rm.candidates_m[sel, 0],
                rm.candidates_m[sel, 1],
                s=160 + 90 * j,
                facecolors="none",
                edgecolors=col,
                linewidths=1.5,
                label=label,
                zorder=4,
            )
        gs = m.tx_position_m
        ax.scatter(
            [gs[0]],
            [gs[1]],
            marker="*",
            s=200,
            c="red",
            edgecolors="k",
            zorder=5,
            label=f"ground station (z {gs[2]:.1f} m)",
        )
        ax.set_xlim(extent[:2])
        ax.set_ylim(extent[2:])
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{rm.scene}: path gain at z = {z:.2f} m", fontsize=9)
        ax.legend(loc="lower left", fontsize=6)
    fig.colorbar(im, ax=list(axes), label="path gain (dB); circles: traced candidates")
    return fig
