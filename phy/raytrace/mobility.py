"""A moving transmitter's channel over time, from sionna-rt's per-path Doppler shifts.

After one trace at position ``p`` with velocity ``v``, path ``i`` (baseband coefficient
``a_i``, delay ``tau_i`` after the first arrival, Doppler shift ``f_i`` from
``sionna.rt.Paths.doppler``) evolves as in ``sionna.rt.Paths.cir(num_time_steps=...)``::

    h(t, f) = sum_i a_i exp(-2j pi f tau_i) exp(2j pi f_i t)

with ``f`` the baseband subcarrier offset. The delays are held: over a few wavelengths of
flight they change by ``|v| t / c``, a small fraction of a nanosecond.

A longer flight is re-traced: when ``|v| T`` of a transmission of duration ``T`` exceeds
:data:`RETRACE_WAVELENGTHS` wavelengths, ``T`` is cut into equal segments of at most that
flight each; segment ``k`` starts at ``t_k`` and is traced at ``p + v t_k``, with Doppler
evolution inside it. The carrier phase runs on across segments: segment ``k``'s
coefficients are multiplied by ``exp(-2j pi f_c (d_k - d_0))``, where ``d_k`` is the
absolute delay of its first arrival (the receiver's timing follows the first arrival, so
the relative delays start afresh in each segment).

The largest Doppler shift of a transmitter at speed ``v`` is ``f_d = v f_c / c``; a path
leaving along the velocity has ``f_i = f_d``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phy.conventions import SPEED_OF_LIGHT_M_S
from phy.raytrace.tracer import RayTracer, check_positions

RETRACE_WAVELENGTHS = 4.0
"""A transmission whose flight exceeds this many wavelengths is re-traced along its path."""


def max_doppler_hz(speed_m_s: float, carrier_frequency_hz: float) -> float:
    """``f_d = v f_c / c``: the Doppler shift of a path leaving along the velocity (Hz)."""
    return float(speed_m_s) * float(carrier_frequency_hz) / SPEED_OF_LIGHT_M_S


def num_segments(speed_m_s: float, duration_s: float, carrier_frequency_hz: float) -> int:
    """Traces a flight of ``speed_m_s * duration_s`` metres needs (1: Doppler evolution only)."""
    wavelength_m = SPEED_OF_LIGHT_M_S / float(carrier_frequency_hz)
    flight = abs(float(speed_m_s)) * max(float(duration_s), 0.0)
    return max(1, math.ceil(flight / (RETRACE_WAVELENGTHS * wavelength_m) - 1e-9))


@dataclass(frozen=True)
class MovingCIR:
    """A moving transmitter's paths, traced at the start of each segment of its flight.

    Attributes:
        start_s: [num_segments] float64 start time of each segment (the first is 0).
        a: [num_segments, max_paths] complex128 coefficients, the carrier phase carried on
            from the first segment (0 for padding).
        tau_s: [num_segments, max_paths] float64 delays after each segment's first arrival.
        doppler_hz: [num_segments, max_paths] float64 Doppler shifts.
    """

    start_s: np.ndarray
    a: np.ndarray
    tau_s: np.ndarray
    doppler_hz: np.ndarray

    def response(self, row_times_s, freqs_hz, col_times_s=None) -> np.ndarray:
        """``h[t, k] = h(row_times_s[t] + col_times_s[k], freqs_hz[k])``.

        Separable in time so that a grid costs one matrix product per segment: each row
        takes the segment its ``row_times_s`` falls in. ``col_times_s`` (default 0) lets
        the symbols of one row be sent one after the other (a flat mapping).

        Args:
            row_times_s: [num_rows] float, non-decreasing seconds from the start.
            freqs_hz: [num_subcarriers] float baseband subcarrier offsets.
            col_times_s: [num_subcarriers] float seconds added within a row (or None).
        Returns:
            [num_rows, num_subcarriers] complex128.
        """
        rows = np.asarray(row_times_s, np.float64)
        f = np.asarray(freqs_hz, np.float64)
        cols = np.zeros_like(f) if col_times_s is None else np.asarray(col_times_s, np.float64)
        seg = np.searchsorted(self.start_s, rows, side="right") - 1
        out = np.zeros((rows.size, f.size), np.complex128)
        for s in np.unique(seg):
            a, tau, fd = self.a[s], self.tau_s[s], self.doppler_hz[s]
            # [num_subcarriers, max_paths]: delay phase and the Doppler within a row
            freq = np.exp(-2j * np.pi * np.outer(f, tau)) * np.exp(2j * np.pi * np.outer(cols, fd))
            t = rows[seg == s] - self.start_s[s]
            time = np.exp(2j * np.pi * np.outer(t, fd)) * a  # [rows in segment, max_paths]
            out[seg == s] = time @ freq.T
        return out


class MovingTransmitter:
    """A transmitter flying straight at constant velocity from ``position_m`` at t = 0.

    Args:
        tracer: the :class:`RayTracer` (scene, receiver, carrier; its cache is shared).
        position_m: [3] metres at t = 0.
        velocity_m_s: [3] metres per second.
    """

    def __init__(self, tracer: RayTracer, position_m, velocity_m_s):
        self.tracer = tracer
        self.position_m = check_positions(position_m, "position_m")[0]
        self.velocity_m_s = check_positions(velocity_m_s, "velocity_m_s", "m/s")[0]
        self._segments: dict[int, MovingCIR] = {}

    @property
    def speed_m_s(self) -> float:
        return float(np.linalg.norm(self.velocity_m_s))

    @property
    def max_doppler_hz(self) -> float:
        return max_doppler_hz(self.speed_m_s, self.tracer.carrier_frequency_hz)

    def __repr__(self) -> str:
        return (
            f"MovingTransmitter(position_m={self.position_m.tolist()}, "
            f"velocity_m_s={self.velocity_m_s.tolist()})"
        )

    def cir(self, duration_s: float) -> MovingCIR:
        """The paths of a transmission lasting ``duration_s`` seconds (traced, then cached)."""
        fc = self.tracer.carrier_frequency_hz
        n = num_segments(self.speed_m_s, duration_s, fc)
        if n not in self._segments:
            start = np.arange(n) * (float(duration_s) / n)
            pos = self.position_m + start[:, None] * self.velocity_m_s  # [num_segments, 3]
            c = self.tracer.cir(pos, self.velocity_m_s)
            phase = np.exp(-2j * np.pi * fc * (c.first_delay_s - c.first_delay_s[0]))
            a = np.where(c.valid, c.a.astype(np.complex128), 0) * phase[:, None]
            tau = np.where(c.valid, c.tau_s, 0).astype(np.float64)
            fd = np.where(c.valid, c.doppler_hz, 0).astype(np.float64)
            self._segments[n] = MovingCIR(start, a, tau, fd)
        return self._segments[n]

    def response(self, row_times_s, freqs_hz, col_times_s=None) -> np.ndarray:
        """:meth:`MovingCIR.response` of a transmission as long as the last time asked for.

        Returns:
            [num_rows, num_subcarriers] complex128, absolute (path loss included).
        """
        rows = np.asarray(row_times_s, np.float64)
        cols = 0.0 if col_times_s is None else float(np.max(col_times_s, initial=0.0))
        duration = float(rows.max(initial=0.0)) + cols
        return self.cir(duration).response(rows, freqs_hz, col_times_s)


def flat_symbol_times(num_symbols: int, num_subcarriers: int, symbol_duration_s: float):
    """Rows and in-row times of a flat mapping: symbol ``i`` rides subcarrier
    ``i % num_subcarriers`` and is sent at ``i * symbol_duration_s``.

    Returns:
        (row_times_s [num_rows] float64, col_times_s [num_subcarriers] float64), with
        ``num_rows = ceil(num_symbols / num_subcarriers)``; symbol ``i`` is entry
        ``(i // num_subcarriers, i % num_subcarriers)`` of the response.
    """
    rows = -(-int(num_symbols) // int(num_subcarriers))
    row_times = np.arange(rows) * num_subcarriers * float(symbol_duration_s)
    return row_times, np.arange(num_subcarriers) * float(symbol_duration_s)
