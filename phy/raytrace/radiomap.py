"""Radio maps: sionna-rt's ``RadioMapSolver`` on horizontal planes, one per altitude.

A radio map is the path gain from one transmitter to every cell of a measurement plane.
Drones transmit to the ground station, but the solver shoots rays from transmitters; path
gain between isotropic antennas is reciprocal, so a map with the *ground station* as the
transmitter, measured at a drone's altitude, gives the gain of a drone transmitting from
any cell of it to the ground station. One plane per altitude, parallel to the ground.

Cells that no ray crossed have gain 0 (``-inf`` dB): rays from a ground station near the
plane's height cross it at grazing angles, so keep cells large enough and samples many
enough that every cell is hit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phy.raytrace.scene import import_rt, load_scene
from phy.raytrace.tracer import check_positions

_TX_NAME = "osnerf_radiomap_tx"


@dataclass(frozen=True)
class RadioMapConfig:
    """Settings of sionna-rt's ``RadioMapSolver`` (see its documentation).

    Attributes:
        samples_per_tx: rays shot from the transmitter, in [1e3, 1e9].
        max_depth: most interactions per path, in [0, 10].
        seed: seed of the ray sampler, in [0, 2**31 - 1] (the same map for a seed).
    """

    samples_per_tx: int = 10_000_000
    max_depth: int = 2
    seed: int = 42

    def __post_init__(self):
        for name, low, high in (
            ("samples_per_tx", 1_000, 1_000_000_000),
            ("max_depth", 0, 10),
            ("seed", 0, 2**31 - 1),
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
                raise ValueError(f"{name} must be an integer in [{low:g}, {high:g}], got {v!r}")


@dataclass(frozen=True)
class RadioMap:
    """Path gain on horizontal planes.

    Attributes:
        path_gain_db: [num_altitudes, num_y, num_x] float64, ``-inf`` where no ray arrived.
        x_m: [num_x] cell centres along x; y_m: [num_y] cell centres along y (metres).
        altitudes_m: [num_altitudes] heights of the planes (metres, z up).
        tx_position_m: [3] the transmitter (the ground station, by reciprocity).
        cell_size_m: side of a square cell.
    """

    path_gain_db: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    altitudes_m: np.ndarray
    tx_position_m: np.ndarray
    cell_size_m: float

    def at(self, positions_m) -> np.ndarray:
        """[num_positions] path gain (dB) of the cell holding each position, on the plane
        nearest its altitude (a position outside the map gets its nearest edge cell)."""
        p = check_positions(positions_m, "positions_m")
        k = np.abs(p[:, 2:3] - self.altitudes_m[None]).argmin(axis=1)
        ix = np.abs(p[:, 0:1] - self.x_m[None]).argmin(axis=1)
        iy = np.abs(p[:, 1:2] - self.y_m[None]).argmin(axis=1)
        return self.path_gain_db[k, iy, ix]


def _check_plane(center_xy_m, size_m, cell_size_m: float) -> tuple[np.ndarray, np.ndarray]:
    c = np.asarray(center_xy_m, np.float64).reshape(-1)
    s = np.asarray(size_m, np.float64).reshape(-1)
    if c.shape != (2,) or not np.isfinite(c).all():
        raise ValueError(f"center_xy_m must be two finite metres, got {center_xy_m!r}")
    if s.shape != (2,) or not np.isfinite(s).all() or (s <= 0).any():
        raise ValueError(f"size_m must be two sizes > 0 m, got {size_m!r}")
    cs = cell_size_m
    if isinstance(cs, bool) or not isinstance(cs, int | float) or not math.isfinite(cs) or cs <= 0:
        raise ValueError(f"cell_size_m must be > 0 m, got {cs!r}")
    if (s / cs).max() > 4096:
        raise ValueError(
            f"cell_size_m {cs:g} gives more than 4096 cells along a side of {s.max():g} m"
        )
    return c, s


def radio_map(
    scene,
    tx_position_m,
    carrier_frequency_hz: float,
    center_xy_m,
    size_m,
    altitudes_m,
    cell_size_m: float,
    config: RadioMapConfig | None = None,
) -> RadioMap:
    """Path gain from ``tx_position_m`` to horizontal planes at ``altitudes_m``.

    Args:
        scene: a built-in sionna-rt scene name, a scene ``.xml`` path or a ``sionna.rt.Scene``.
        tx_position_m: [3] transmitter (isotropic, vertically polarised), metres.
        carrier_frequency_hz: carrier in Hz, in [1e8, 1e11].
        center_xy_m: [2] centre of every plane; size_m: [2] its extent along x and y (m).
        altitudes_m: [num_altitudes] plane heights (metres).
        cell_size_m: side of a square cell (the solver rounds the size up to whole cells).
        config: :class:`RadioMapConfig`.
    Returns:
        :class:`RadioMap`.
    """
    import mitsuba as mi

    config = config if config is not None else RadioMapConfig()
    cf = carrier_frequency_hz
    if isinstance(cf, bool) or not isinstance(cf, int | float) or not 1e8 <= cf <= 1e11:
        raise ValueError(f"carrier_frequency_hz must be in [1e8, 1e11] Hz, got {cf!r}")
    tx = check_positions(tx_position_m, "tx_position_m")
    if tx.shape[0] != 1:
        raise ValueError(f"tx_position_m must be one [3] position, got shape {tx.shape}")
    alt = np.asarray(altitudes_m, np.float64).reshape(-1)
    if alt.size < 1 or not np.isfinite(alt).all():
        raise ValueError(f"altitudes_m must be one or more finite heights, got {altitudes_m!r}")
    c, s = _check_plane(center_xy_m, size_m, cell_size_m)
    rt = import_rt()
    sc = load_scene(scene)
    sc.frequency = float(cf)
    sc.tx_array = rt.PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    sc.rx_array = rt.PlanarArray(num_rows=1, num_cols=1, pattern="iso", polarization="V")
    sc.add(rt.Transmitter(_TX_NAME, position=mi.Point3f(*map(float, tx[0]))))
    solver = rt.RadioMapSolver()
    layers: list[np.ndarray] = []
    x = y = np.zeros(0)
    try:
        for z in alt:
            rm = solver(
                sc,
                center=mi.Point3f(float(c[0]), float(c[1]), float(z)),
                orientation=mi.Point3f(0.0, 0.0, 0.0),
                size=mi.Point2f(float(s[0]), float(s[1])),
                cell_size=mi.Point2f(float(cell_size_m), float(cell_size_m)),
                samples_per_tx=config.samples_per_tx,
                max_depth=config.max_depth,
                seed=config.seed,
            )
            pg = np.asarray(rm.path_gain.numpy(), np.float64)[0]  # [num_y, num_x]
            centres = np.asarray(rm.cell_centers.numpy(), np.float64)  # [num_y, num_x, 3]
            x, y = centres[0, :, 0], centres[:, 0, 1]
            with np.errstate(divide="ignore"):
                layers.append(10.0 * np.log10(pg))
    finally:
        sc.remove(_TX_NAME)
    return RadioMap(np.stack(layers), x, y, alt, tx[0], float(cell_size_m))
