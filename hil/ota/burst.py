"""The transmit side of an over-the-air burst: ``phy``'s frame layer (:class:`PhyFrames`),
the burst of header-led frames with gaps (:func:`build_burst`, PAPR-clipped at one scale
so the clip level is exactly full scale), and what the receiver reports about it
(:class:`FrameReport`, :class:`BurstResult`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hil.errors import HilError
from hil.ota.config import OtaConfig
from hil.ota.header import MAX_FRAMES, header_symbols


def as_numpy(x) -> np.ndarray:
    """A numpy array of ``x`` (a torch tensor is detached and moved to the CPU)."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x)


class PhyFrames:
    """``phy``'s over-the-air frame (FrameConfig, build_frame, find_frames, receive_frame,
    receive_frames).

    The receiver equalises by zero-forcing: unbiased symbols with each symbol's effective
    noise variance, the codec's convention (``semcodec.jscc.model.lmmse_input``).

    Args:
        frame_config: a ``phy.FrameConfig``; None builds one from ``frame_kwargs``
            (e.g. ``sample_rate_hz``, ``detection_threshold``, ``carrier_freq_hz``).
    """

    def __init__(self, frame_config=None, **frame_kwargs):
        import phy  # loads torch, which import hil does not

        missing = [
            n
            for n in (
                "FrameConfig",
                "build_frame",
                "find_frames",
                "receive_frame",
                "receive_frames",
            )
            if not hasattr(phy, n)
        ]
        if missing:
            raise HilError(
                f"phy's frame API is not in this checkout (missing phy.{', phy.'.join(missing)})"
            )
        self.phy = phy
        self.cfg = frame_config if frame_config is not None else phy.FrameConfig(**frame_kwargs)

    def build(self, symbols: np.ndarray) -> np.ndarray:
        import torch

        return as_numpy(
            self.phy.build_frame(torch.as_tensor(symbols, dtype=torch.complex64), self.cfg)
        ).astype(np.complex64)

    def find(self, iq: np.ndarray) -> list[int]:
        import torch

        return [
            int(s)
            for s in self.phy.find_frames(torch.as_tensor(iq, dtype=torch.complex64), self.cfg)
        ]

    def receive(self, iq: np.ndarray, num_symbols: int):
        import torch

        return self.phy.receive_frame(
            torch.as_tensor(iq, dtype=torch.complex64), self.cfg, num_symbols, equalizer="zf"
        )

    def receive_all(self, iq: np.ndarray, num_symbols: int) -> list:
        """Every complete frame of ``iq`` from one search (``phy.receive_frames``), ascending;
        each result's ``start_index`` is its first sample in ``iq``."""
        import torch

        return self.phy.receive_frames(
            torch.as_tensor(iq, dtype=torch.complex64), self.cfg, num_symbols, equalizer="zf"
        )


@dataclass
class FrameReport:
    """What the receiver made of one transmitted frame.

    ``header_error`` says why a detection where this frame starts was dropped: its header
    contradicts the frame's number (:func:`hil.ota.header.header_mismatch`); None otherwise.
    """

    number: int
    block: int
    detected: bool = False
    start_index: int | None = None
    num_samples: int = 0
    snr_db: float | None = None
    cfo_hz: float | None = None
    crc_ok: bool | None = None
    header_error: str | None = None


@dataclass
class BurstResult:
    """Received blocks and per-frame reports of one over-the-air burst.

    Attributes:
        blocks: per input block, ``(x_hat [num_symbols] complex64, noise_var [num_symbols]
            float32)``; symbols of lost frames are 0 with noise_var ``ERASED_NOISE_VAR``.
        frames: one :class:`FrameReport` per transmitted frame.
        burst: [num_samples] complex64 as transmitted (full scale 1.0).
        capture: [num_samples] complex64 as received.
    """

    blocks: list
    frames: list
    burst: np.ndarray
    capture: np.ndarray
    sigmf: list = field(default_factory=list)

    @property
    def frames_sent(self) -> int:
        return len(self.frames)

    @property
    def frames_lost(self) -> int:
        return sum(not f.detected for f in self.frames)

    def block_frames(self, block: int) -> list:
        return [f for f in self.frames if f.block == block]

    def snr_db_measured(self, block: int | None = None) -> float | None:
        """Mean SNR (linear mean, in dB) over the detected frames (of one block)."""
        frames = self.frames if block is None else self.block_frames(block)
        snrs = [f.snr_db for f in frames if f.detected and f.snr_db is not None]
        return float(10 * np.log10(np.mean(10 ** (np.array(snrs) / 10)))) if snrs else None


def build_burst(
    blocks: list, cfg: OtaConfig, frames, first_number: int = 0
) -> tuple[np.ndarray, list[FrameReport], list[tuple]]:
    """Frame every block and lay the frames out with gaps, PAPR-clipped and scaled.

    Args:
        blocks: list of [num_symbols] complex64 arrays (unit mean power by convention).
        first_number: the header number of the first frame; frame ``i`` of the burst
            carries ``(first_number + i) % MAX_FRAMES`` (a stream of bursts numbers its
            frames on), its report and layout stay at index ``i``.
    Returns:
        (burst [num_samples] complex64 with |I|, |Q| <= 1, reports, layout) where layout
        holds ``(block, offset, length)`` of each frame's data symbols.
    """
    import torch

    from phy import clip_papr  # loads torch, which import hil does not

    reports, layout, parts = [], [], [np.zeros(cfg.gap_samples, np.complex64)]
    # one scale for every frame: a frame of unit-power symbols has mean power p_nominal and
    # is clipped at sqrt(PAPR * p_nominal), which becomes full scale (|x| = 1)
    # random (not periodic: a periodic probe is impulsive in time and gets clipped) QPSK
    quadrants = np.random.default_rng(0).integers(0, 4, cfg.header_symbols + cfg.symbols_per_frame)
    probe = np.exp(2j * np.pi * (quadrants + 0.5) / 4)
    p_nominal = float(np.mean(np.abs(frames.build(probe.astype(np.complex64))) ** 2))
    limit = math.sqrt(10 ** (cfg.max_papr_db / 10) * p_nominal)
    number = 0
    for b, block in enumerate(blocks):
        block = np.asarray(block, np.complex64).reshape(-1)
        for offset in range(0, max(len(block), 1), cfg.symbols_per_frame):
            if number >= MAX_FRAMES:
                raise ValueError(
                    f"blocks need more than {MAX_FRAMES} frames; send fewer or larger frames"
                )
            chunk = block[offset : offset + cfg.symbols_per_frame]
            data = np.zeros(cfg.symbols_per_frame, np.complex64)
            data[: len(chunk)] = chunk
            header = header_symbols((first_number + number) % MAX_FRAMES, cfg.header_repeat)
            iq = frames.build(np.concatenate([header, data]))
            p_frame = float(np.mean(np.abs(iq) ** 2))
            papr_db = max(0.0, 10 * math.log10(limit**2 / p_frame))  # the same clip level for all
            iq = clip_papr(torch.as_tensor(iq)[None], papr_db)[0].numpy() / limit
            iq = (np.clip(iq.real, -1, 1) + 1j * np.clip(iq.imag, -1, 1)).astype(np.complex64)
            reports.append(FrameReport(number, b, num_samples=len(iq)))
            layout.append((b, offset, len(chunk)))
            parts += [iq, np.zeros(cfg.gap_samples, np.complex64)]
            number += 1
    return np.concatenate(parts), reports, layout
