"""Ray-traced drone-to-ground channels: sionna-rt paths -> CIR -> per-subcarrier response.

One :class:`RayTracer` holds a scene, a receiver (the ground station) and a carrier. For a
batch of transmitter (drone) positions it runs sionna-rt's ``PathSolver`` once with one
transmitter per position, keeps each position's channel impulse response (path
coefficients ``a`` and delays ``tau``, delays relative to the first arrival, i.e. perfect
timing), and turns it into a frequency response with sionna.phy's ``cir_to_ofdm_channel``.
Antennas are single isotropic, vertically polarised (SISO). A transmitter may move: given
its velocity, sionna-rt also returns each path's Doppler shift (``Paths.doppler``) and the
absolute delay of the first arrival, from which :mod:`phy.raytrace.mobility` evolves the
channel in time. The scene and the receiver are static.

CIRs are cached in-process by (scene, receiver position, carrier, solver settings,
transmitter position rounded to 0.1 mm, velocity rounded to 0.1 mm/s), so a trajectory
that revisits positions, or a second call with other subcarriers, does not trace again.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from phy.raytrace.scene import import_rt, load_scene, scene_key
from phy.raytrace.stats import RayStats, cir_stats

_CACHE: dict[tuple, tuple[np.ndarray, np.ndarray, bool, np.ndarray, float]] = {}
_CACHE_MAX = 200_000
_TX_PREFIX = "osnerf_tx_"
_RX_NAME = "osnerf_rx"


def clear_cache() -> None:
    """Forget every cached CIR."""
    _CACHE.clear()


@dataclass(frozen=True)
class RayTracingConfig:
    """Settings of sionna-rt's ``PathSolver`` (see its documentation).

    Attributes:
        max_depth: most interactions per path, in [0, 10] (0: line of sight only).
        samples_per_src: rays shot per transmitter, in [1e3, 1e7].
        max_num_paths_per_src: most paths kept per transmitter, in [1, 1e7].
        los, specular_reflection, diffuse_reflection, refraction, diffraction: which
            interactions are traced.
        seed: seed of the ray sampler.
        deterministic: sionna-rt's deterministic path solver (``PathSolver(deterministic=
            True)``): the same seed gives the same paths, in the same order, on every run;
            without it a fixed seed does not guarantee that.
        max_positions_per_call: transmitters traced together in one solver call, in [1, 1024].
    """

    max_depth: int = 3
    samples_per_src: int = 100_000
    max_num_paths_per_src: int = 100_000
    los: bool = True
    specular_reflection: bool = True
    diffuse_reflection: bool = False
    refraction: bool = True
    diffraction: bool = False
    seed: int = 42
    deterministic: bool = True
    max_positions_per_call: int = 64

    def __post_init__(self):
        def check_int(name, low, high):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= high:
                raise ValueError(f"{name} must be an integer in [{low:g}, {high:g}], got {v!r}")

        check_int("max_depth", 0, 10)
        check_int("samples_per_src", 1_000, 10_000_000)
        check_int("max_num_paths_per_src", 1, 10_000_000)
        check_int("seed", 0, 2**31 - 1)
        check_int("max_positions_per_call", 1, 1024)
        for name in (
            "los",
            "specular_reflection",
            "diffuse_reflection",
            "refraction",
            "diffraction",
            "deterministic",
        ):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")

    def solver_kwargs(self) -> dict:
        out = dataclasses.asdict(self)
        out.pop("max_positions_per_call")
        out.pop("deterministic")  # an argument of the solver's constructor
        return out


def check_positions(positions_m, name: str = "tx_positions_m", unit: str = "metres") -> np.ndarray:
    """[num_positions, 3] float64 metres from an array-like; ``[3]`` becomes ``[1, 3]``.

    Raises:
        ValueError: naming ``name`` when the shape is not [N, 3], N >= 1, or a value is not
            a finite number.
    """
    try:
        p = np.asarray(
            positions_m.detach().cpu().numpy() if isinstance(positions_m, Tensor) else positions_m,
            dtype=np.float64,
        )
    except (TypeError, ValueError):
        raise ValueError(
            f"{name} must be [num_positions, 3] finite {unit}, got {positions_m!r}"
        ) from None
    if p.ndim == 1:
        p = p[None]
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 1:
        raise ValueError(f"{name} must be [num_positions, 3] finite {unit}, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"{name} must be [num_positions, 3] finite {unit}, got a non-finite value")
    return p


def check_frequencies(freqs_hz, name: str = "subcarrier_frequencies_hz") -> np.ndarray:
    """[num_subcarriers] float64 baseband frequencies (offsets from the carrier) in Hz."""
    try:
        f = np.asarray(
            freqs_hz.detach().cpu().numpy() if isinstance(freqs_hz, Tensor) else freqs_hz,
            dtype=np.float64,
        )
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be [num_subcarriers] finite Hz, got {freqs_hz!r}") from None
    if f.ndim != 1 or f.size < 1 or not np.isfinite(f).all():
        raise ValueError(f"{name} must be [num_subcarriers] finite Hz, got shape {f.shape}")
    return f


@dataclass(frozen=True)
class RayCIR:
    """Channel impulse responses of ``num_positions`` positions, padded to ``max_paths``.

    Attributes:
        a: [num_positions, max_paths] complex64 baseband path coefficients (0 for padding).
        tau_s: [num_positions, max_paths] float32 delays after the first arrival (0 padding).
        valid: [num_positions, max_paths] bool.
        los: [num_positions] bool, a line-of-sight path exists.
        doppler_hz: [num_positions, max_paths] float32 Doppler shift of each path (0 for a
            transmitter at rest, and for padding).
        first_delay_s: [num_positions] float64 absolute delay of the first arrival (0 in
            outage); the carrier phase ``a`` leaves out (``a`` uses relative delays).
    """

    a: np.ndarray
    tau_s: np.ndarray
    valid: np.ndarray
    los: np.ndarray
    doppler_hz: np.ndarray
    first_delay_s: np.ndarray

    @property
    def outage(self) -> np.ndarray:
        """[num_positions] bool: no path with non-zero gain."""
        return ~(self.valid & (np.abs(self.a) > 0)).any(axis=1)


class RayTracer:
    """Channels from transmitter (drone) positions to one receiver (ground station).

    Args:
        scene: a built-in sionna-rt scene name (``"simple_street_canyon"``, ``"munich"``,
            ...), a scene ``.xml`` path, or a loaded ``sionna.rt.Scene`` (its frequency and
            antenna arrays are set, and transmitters/receivers are added and removed
            around each solve).
        rx_position_m: [3] receiver position in metres (scene coordinates, z up).
        carrier_frequency_hz: carrier in Hz, in [1e8, 1e11].
        config: :class:`RayTracingConfig`.
    """

    def __init__(
        self,
        scene="simple_street_canyon",
        rx_position_m=(0.0, 0.0, 1.5),
        carrier_frequency_hz: float = 3.5e9,
        config: RayTracingConfig | None = None,
    ):
        cf = carrier_frequency_hz
        if (
            isinstance(cf, bool)
            or not isinstance(cf, int | float)
            or not math.isfinite(cf)
            or not 1e8 <= cf <= 1e11
        ):
            raise ValueError(f"carrier_frequency_hz must be in [1e8, 1e11] Hz, got {cf!r}")
        self.carrier_frequency_hz = float(cf)
        self.rx_position_m = check_positions(rx_position_m, "rx_position_m")
        if self.rx_position_m.shape[0] != 1:
            raise ValueError(
                f"rx_position_m must be one [3] position, got shape {self.rx_position_m.shape}"
            )
        self.rx_position_m = self.rx_position_m[0]
        self.config = config if config is not None else RayTracingConfig()
        if not isinstance(self.config, RayTracingConfig):
            raise ValueError(f"config must be a RayTracingConfig, got {type(config).__name__}")
        self._key = (
            scene_key(scene),
            tuple(np.round(self.rx_position_m, 4)),
            self.carrier_frequency_hz,
            self.config,
        )
        self.scene = load_scene(scene)
        rt = import_rt()
        self.scene.frequency = self.carrier_frequency_hz
        self.scene.tx_array = rt.PlanarArray(
            num_rows=1, num_cols=1, pattern="iso", polarization="V"
        )
        self.scene.rx_array = rt.PlanarArray(
            num_rows=1, num_cols=1, pattern="iso", polarization="V"
        )
        self._solver = rt.PathSolver(deterministic=self.config.deterministic)
        self.num_traced = 0  # positions actually traced (cache misses), for tests/benchmarks

    def __repr__(self) -> str:
        return (
            f"RayTracer(scene={self._key[0]!r}, rx_position_m={self.rx_position_m.tolist()}, "
            f"carrier_frequency_hz={self.carrier_frequency_hz:g}, config={self.config})"
        )

    # ------------------------------------------------------------------ tracing
    def _trace(self, positions: np.ndarray, velocities: np.ndarray) -> list[tuple]:
        """Run the path solver for [M, 3] positions moving at [M, 3] velocities; one
        (a, tau, los, doppler, first_delay) per position."""
        import mitsuba as mi

        rt = import_rt()
        scene = self.scene
        names = [f"{_TX_PREFIX}{i}" for i in range(len(positions))]
        for name, p, v in zip(names, positions, velocities):
            scene.add(
                rt.Transmitter(
                    name,
                    position=mi.Point3f(*map(float, p)),
                    velocity=mi.Vector3f(*map(float, v)),
                )
            )
        scene.add(rt.Receiver(_RX_NAME, position=mi.Point3f(*map(float, self.rx_position_m))))
        try:
            paths = self._solver(scene, synthetic_array=True, **self.config.solver_kwargs())
            a, tau = paths.cir(normalize_delays=True, out_type="numpy")
            valid = np.asarray(paths.valid.numpy(), dtype=bool)  # [num_rx, num_tx, num_paths]
            inter = np.asarray(paths.interactions.numpy())  # [max_depth, num_rx, num_tx, num_paths]
            doppler = np.asarray(paths.doppler.numpy())  # [num_rx, num_tx, num_paths]
            tau_abs = np.asarray(paths.tau.numpy())  # [num_rx, num_tx, num_paths]
            rx_names, tx_names = list(scene.receivers), list(scene.transmitters)
        finally:
            for name in names:
                scene.remove(name)
            scene.remove(_RX_NAME)
        a = np.asarray(a)
        if not np.iscomplexobj(a):  # (real, imag) pair
            a = a[0] + 1j * a[1]
        r = rx_names.index(_RX_NAME)
        out = []
        for name in names:
            t = tx_names.index(name)
            ai = a[r, 0, t, 0, :, 0] if a.size else np.zeros(0, np.complex64)
            ti = tau[r, t, :] if tau.size else np.zeros(0, np.float32)
            vi = valid[r, t, :] if valid.size else np.zeros(0, bool)
            vi = vi & (ti >= 0)
            los = bool((vi & (inter[:, r, t, :] == 0).all(axis=0)).any()) if vi.size else False
            di = doppler[r, t, :][vi] if doppler.size else np.zeros(0, np.float32)
            first = float(tau_abs[r, t, :][vi].min()) if vi.any() else 0.0
            out.append(
                (
                    ai[vi].astype(np.complex64),
                    ti[vi].astype(np.float32),
                    los,
                    di.astype(np.float32),
                    first,
                )
            )
        return out

    def _pos_key(self, p: np.ndarray, v: np.ndarray) -> tuple:
        return (*self._key, tuple(np.round(p, 4)), tuple(np.round(v, 4)))

    def cir(self, tx_positions_m, tx_velocities_m_s=None) -> RayCIR:
        """Channel impulse responses for transmitter positions (traced once, then cached).

        Args:
            tx_positions_m: [num_positions, 3] (or [3]) metres.
            tx_velocities_m_s: [num_positions, 3] (or [3]: one for all) metres per second;
                None: at rest (no Doppler).
        Returns:
            :class:`RayCIR`.
        """
        pos = check_positions(tx_positions_m)
        vel = np.zeros_like(pos)
        if tx_velocities_m_s is not None:
            v = check_positions(tx_velocities_m_s, "tx_velocities_m_s", "m/s")
            if v.shape[0] not in (1, len(pos)):
                raise ValueError(
                    f"tx_velocities_m_s must be [3] or [num_positions={len(pos)}, 3], "
                    f"got shape {v.shape}"
                )
            vel = np.broadcast_to(v, pos.shape).copy()
        keys = [self._pos_key(p, v) for p, v in zip(pos, vel)]
        missing = list(dict.fromkeys(k for k in keys if k not in _CACHE))
        if missing:
            todo = np.array([k[-2] for k in missing], dtype=np.float64)
            todo_v = np.array([k[-1] for k in missing], dtype=np.float64)
            step = self.config.max_positions_per_call
            for s in range(0, len(todo), step):
                traced = self._trace(todo[s : s + step], todo_v[s : s + step])
                for k, res in zip(missing[s : s + step], traced):
                    if len(_CACHE) >= _CACHE_MAX:
                        _CACHE.pop(next(iter(_CACHE)))
                    _CACHE[k] = res
            self.num_traced += len(missing)
        entries = [_CACHE[k] for k in keys]
        max_paths = max(1, max(len(e[0]) for e in entries))
        n = len(entries)
        a = np.zeros((n, max_paths), np.complex64)
        tau = np.zeros((n, max_paths), np.float32)
        valid = np.zeros((n, max_paths), bool)
        doppler = np.zeros((n, max_paths), np.float32)
        for i, (ai, ti, _, di, _) in enumerate(entries):
            a[i, : len(ai)], tau[i, : len(ti)], valid[i, : len(ai)] = ai, ti, True
            doppler[i, : len(di)] = di
        los = np.array([e[2] for e in entries], dtype=bool)
        first = np.array([e[4] for e in entries], dtype=np.float64)
        return RayCIR(a, tau, valid, los, doppler, first)

    def cfr(self, tx_positions_m, subcarrier_frequencies_hz) -> tuple[Tensor, Tensor]:
        """Per-subcarrier frequency response for each transmitter position.

        Args:
            tx_positions_m: [num_positions, 3] (or [3]) metres.
            subcarrier_frequencies_hz: [num_subcarriers] baseband offsets from the carrier
                (e.g. ``ResourceGrid.subcarrier_frequencies_hz``).
        Returns:
            h: [num_positions, num_subcarriers] complex64, absolute (path loss included);
                exactly 0 in outage, never NaN.
            outage: [num_positions] bool, True where no path exists.
        """
        from sionna.phy.channel import cir_to_ofdm_channel

        freqs = check_frequencies(subcarrier_frequencies_hz)
        c = self.cir(tx_positions_m)
        a = torch.from_numpy(c.a)[:, None, None, None, None, :, None]  # [n, 1, 1, 1, 1, paths, 1]
        tau = torch.from_numpy(c.tau_s)[:, None, None, :]  # [n, 1, 1, paths]
        f = torch.from_numpy(freqs.astype(np.float32))
        h = cir_to_ofdm_channel(f, a, tau, normalize=False)  # [n, 1, 1, 1, 1, 1, num_subcarriers]
        h = h.reshape(len(c.a), -1).to(torch.complex64)
        outage = torch.from_numpy(c.outage)
        h = torch.where(outage[:, None], torch.zeros_like(h), h)
        return h, outage

    def stats(self, tx_positions_m, tx_velocities_m_s=None) -> RayStats:
        """Path gain, RMS delay spread, K factor, number of paths, LoS, outage, and (for a
        moving transmitter) the Doppler spread per position."""
        c = self.cir(tx_positions_m, tx_velocities_m_s)
        return cir_stats(c.a, c.tau_s, c.valid, c.los, c.doppler_hz)
