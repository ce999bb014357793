"""The virtual air that connects emulated radios, on a virtual sample clock.

One transmitter, any number of receivers. The transmitter's timeline is every sample it
has sent (its own sample clock, index 0 = when the medium was made); each receiver's
timeline is every sample it has received (its own clock). Receiver sample ``k`` is taken
at time ``t = k / fs_rx_true`` and sees the transmitter's signal at index
``(t - delay) * fs_tx_true`` through the multipath, rotated by the carrier offset, plus
noise, receiver gain, I/Q imbalance, DC and the int8 ADC.

The multipath is ``AirChannel.fir``: fixed taps, or paths with fractional delays, gains
and Doppler shifts in segments (:mod:`hil.emulation.paths`), applied on the transmitter's sample
grid before the resampling. Its time counts from the channel's epoch: the first sample the
transmitter sends after the channel was set (at construction or by :meth:`Medium.set_channel`).

Determinism: with ``wait_for_bursts = B``, receivers block until the transmitter has sent
what they need or has completed ``B`` bursts, so what they receive does not depend on how
threads interleave. Afterwards an idle transmitter's timeline advances with silence as
receivers read on (a later burst starts "now").
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from hil.emulation.air import (
    RESAMPLER_TAPS,
    AirChannel,
    fractional_resample,
    iq_imbalance,
)
from hil.iq import quantize_ci8

AMP_GAIN_DB = 14.0


_CARRIER_BLOCK = 1024


def carrier(df: float, k0: int, n: int, fs: float) -> np.ndarray:
    """``exp(2j pi df t)`` at ``t = (k0 + i) / fs``, i < n: [n] complex64, from one block of
    phasors and one rotation per block (float64 phases: within 1e-7 of the direct formula)."""
    w = 2 * np.pi * df / fs
    steps = np.exp(1j * w * np.arange(_CARRIER_BLOCK))
    starts = np.exp(1j * w * (k0 + np.arange(0, n, _CARRIER_BLOCK, dtype=np.float64)))
    return (starts[:, None] * steps[None, :]).astype(np.complex64).reshape(-1)[:n]


class Medium:
    """Shared air for emulated radios (thread-safe).

    Args:
        channel: the :class:`hil.AirChannel` between the transmitter and every receiver.
        seed: seeds each receiver's noise (``numpy`` PCG64 keyed by (seed, receiver index)).
        wait_for_bursts: receivers wait for this many completed transmit bursts (see module doc).
        wait_timeout_s: wall-clock limit of one such wait; past it the read times out.
    """

    def __init__(
        self,
        channel: AirChannel | None = None,
        seed: int = 0,
        wait_for_bursts: int = 0,
        wait_timeout_s: float = 10.0,
    ):
        self.channel = channel or AirChannel()
        self.seed = int(seed)
        self.wait_for_bursts = int(wait_for_bursts)
        self.wait_timeout_s = float(wait_timeout_s)
        self.cond = threading.Condition()
        self.transmitter = None
        self._tx = np.zeros(1 << 16, np.complex64)  # transmitter samples tx_base .. tx_len - 1
        self.tx_base = 0
        self.tx_len = 0
        self.tx_streaming = False
        self.bursts_completed = 0
        self.epoch: int | None = None  # transmitter index of channel time 0 (None: not yet)
        self._heard_until_s = -math.inf  # receivers heard silence up to here, no transmitter yet
        self._rngs: dict[int, np.random.Generator] = {}
        self._firs: dict[tuple[int, float], tuple] = {}  # (id(channel), fs) -> (channel, fir)

    # ------------------------------------------------------------------ transmit side
    def start_tx(self, radio) -> None:
        with self.cond:
            if self.transmitter is not None and self.transmitter is not radio:
                raise RuntimeError("this medium already has a transmitter (one TX, many RX)")
            self.transmitter = radio
            self.tx_streaming = True
            self.cond.notify_all()

    def end_tx(self, radio) -> None:
        with self.cond:
            if self.transmitter is radio and self.tx_streaming:
                self.tx_streaming = False
                self.bursts_completed += 1
            self.cond.notify_all()

    def append_tx(self, radio, raw: np.ndarray) -> None:
        """Add ``raw`` [2 * num_samples] int8 written by the transmitter at its current gains."""
        self.append_tx_iq(radio, (raw.astype(np.float32) / np.float32(128.0)).view(np.complex64))

    def append_tx_iq(self, radio, x: np.ndarray) -> None:
        """Add ``x`` [num_samples] complex64 (full scale 1.0 at the DAC) at ``radio.tx_gain_db``."""
        scale = 10 ** ((radio.tx_gain_db - self.channel.reference_txvga_db) / 20)
        x = np.asarray(x, np.complex64) * np.float32(scale)
        with self.cond:
            if self.tx_len == 0 and self._heard_until_s > -math.inf:
                # a receiver streamed before there was a transmitter: what it sends starts
                # after the silence already heard, not in the receiver's past
                fs_tx = radio.sample_rate_hz * (1 + radio.ppm * 1e-6)
                heard = int(math.floor((self._heard_until_s - self.channel.delay_s) * fs_tx)) + 1
                if heard > 0:
                    self._ensure(heard)
                    self._tx[:heard] = 0
                    self.tx_len = heard
            if self.epoch is None:
                self.epoch = self.tx_len
            self._ensure(self.tx_len + len(x))
            b = self.tx_base
            self._tx[self.tx_len - b : self.tx_len - b + len(x)] = x
            self.tx_len += len(x)
            self.cond.notify_all()

    def _ensure(self, n: int) -> None:
        """Room for transmitter samples up to index ``n`` (exclusive)."""
        need = n - self.tx_base
        if need > len(self._tx):
            grown = np.zeros(max(need, 2 * len(self._tx)), np.complex64)
            grown[: self.tx_len - self.tx_base] = self._tx[: self.tx_len - self.tx_base]
            self._tx = grown

    def forget_before(self, index: int) -> None:
        """Drop the transmitter's samples before ``index`` (no receiver will read them again),
        so a medium that runs for hours holds a bounded buffer."""
        with self.cond:
            index = min(int(index), self.tx_len)
            if index - self.tx_base < (1 << 20):  # not worth a copy yet
                return
            kept = self._tx[index - self.tx_base : self.tx_len - self.tx_base]
            self._tx = np.zeros(max(1 << 16, 2 * len(kept)), np.complex64)
            self._tx[: len(kept)] = kept
            self.tx_base = index

    def idle_until(self, num_samples: int, underrun: bool = False) -> None:
        """Run an idle transmitter's timeline on in silence up to ``num_samples`` (its own
        clock), so that what it sends next starts no earlier than that. ``underrun``: also
        while it streams (it did not keep up; the gap goes out as silence)."""
        with self.cond:
            if (underrun or not self.tx_streaming) and num_samples > self.tx_len:
                self._ensure(num_samples)
                self._tx[self.tx_len - self.tx_base : num_samples - self.tx_base] = 0
                self.tx_len = int(num_samples)

    def set_channel(self, channel: AirChannel, seed: int) -> None:
        """Replace the air and the noise seed (between bursts): every receiver's noise
        starts again from ``seed``, so the same settings give the same samples, and the
        channel's time starts again at the next sample sent (its epoch)."""
        with self.cond:
            self.channel = channel
            self.seed = int(seed)
            self.epoch = None
            self._rngs.clear()
            self.cond.notify_all()

    def fir(self, sample_rate_hz: float):
        """The channel's ``hil.emulation.paths.TimeVaryingFir`` at ``sample_rate_hz`` (cached)."""
        ch, key = self.channel, (id(self.channel), float(sample_rate_hz))
        hit = self._firs.get(key)
        if hit is None or hit[0] is not ch:
            if len(self._firs) >= 4:
                self._firs.clear()
            hit = self._firs[key] = (ch, ch.fir(key[1]))
        return hit[1]

    def notify(self) -> None:
        with self.cond:
            self.cond.notify_all()

    # ------------------------------------------------------------------ receive side
    def _rng(self, radio) -> np.random.Generator:
        key = radio.index
        if key not in self._rngs:
            self._rngs[key] = np.random.default_rng([self.seed, key])
        return self._rngs[key]

    def render(self, radio, k0: int, n: int, still_receiving) -> np.ndarray | None:
        """Receiver ``radio``'s samples ``k0 .. k0+n-1`` as [2n] int8, or None on a timeout.

        ``still_receiving()`` is polled while waiting: when it turns False the wait ends
        (returns None), as a real transfer would be cancelled.
        """
        y = self.render_iq(radio, k0, n, still_receiving)
        return None if y is None else quantize_ci8(y)

    def render_iq(self, radio, k0: int, n: int, still_receiving) -> np.ndarray | None:
        """As :meth:`render`, before the ADC: [n] complex64 at the ADC input (full scale 1.0)."""
        ch = self.channel
        fs_rx = radio.sample_rate_hz * (1 + radio.ppm * 1e-6)
        t = (k0 + np.arange(n, dtype=np.float64)) / fs_rx
        sig = np.zeros(n, np.complex64)
        deadline = time.monotonic() + self.wait_timeout_s
        with self.cond:
            while True:
                tx = self.transmitter
                if tx is None and self.wait_for_bursts == 0:
                    self._heard_until_s = max(self._heard_until_s, float(t[-1]))
                    break
                if tx is not None:
                    fs_tx = tx.sample_rate_hz * (1 + tx.ppm * 1e-6)
                    u_last = (t[-1] - ch.delay_s) * fs_tx
                    fir = self.fir(fs_tx)
                    need = int(math.ceil(u_last)) + RESAMPLER_TAPS // 2 + 1 + fir.lead
                    if self.tx_len >= need:
                        break
                if not (self.tx_streaming or self.bursts_completed < self.wait_for_bursts):
                    break
                if not still_receiving():
                    return None
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self.cond.wait(min(left, 0.05))
            if tx is not None:
                u = (t - ch.delay_s) * fs_tx
                if not self.tx_streaming and self.bursts_completed >= self.wait_for_bursts:
                    idle_to = max(0, int(math.floor(u[-1])) + 1)
                    if idle_to > self.tx_len:  # an idle transmitter's clock runs on in silence
                        self._ensure(idle_to)
                        self._tx[self.tx_len - self.tx_base : idle_to - self.tx_base] = 0
                        self.tx_len = idle_to
                fir = self.fir(fs_tx)
                lo = max(0, int(math.floor(u[0])) - RESAMPLER_TAPS - fir.span)
                hi = min(self.tx_len, int(math.ceil(u[-1])) + RESAMPLER_TAPS + 1 + fir.lead)
                lo = max(lo, self.tx_base)  # forgotten samples are never needed again
                b = self.tx_base
                seg = self._tx[lo - b : hi - b].copy() if hi > lo else np.zeros(0, np.complex64)
                tx_freq = tx.center_freq_hz * (1 + tx.ppm * 1e-6)
                df = tx_freq - radio.center_freq_hz * (1 + radio.ppm * 1e-6)
                epoch = 0 if self.epoch is None else self.epoch
        # silence (an idle transmitter) stays silence: nothing to filter or resample
        if tx is not None and len(seg) and abs(df) < 0.5 * fs_rx and seg.any():
            if not fir.identity:  # channel time of seg[0]: (lo - epoch) / fs_tx
                seg = fir.apply(seg, (lo - epoch) / fs_tx)
            sig = fractional_resample(seg, u - lo)
            if df != 0:
                sig = sig * carrier(df, k0, n, fs_rx)
        rng = self._rng(radio)
        noise = rng.standard_normal(2 * n, dtype=np.float32).view(np.complex64) * np.float32(
            math.sqrt(ch.noise_var / 2)
        )
        y: np.ndarray = (sig + noise) * np.float32(
            10 ** ((radio.rx_gain_db - ch.reference_rx_gain_db) / 20)
        )
        y = iq_imbalance(y, ch.iq_gain_imbalance_db, ch.iq_phase_imbalance_deg)
        if ch.dc_offset:
            y = y + np.complex64(ch.dc_offset)
        return y
