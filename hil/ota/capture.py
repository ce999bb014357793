"""SigMF files of an over-the-air run: the burst as sent, the capture with one annotation
per detected frame, and the partial capture a failed receive left behind."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hil.errors import HilError
from hil.ota.burst import BurstResult
from hil.ota.config import OtaConfig
from hil.sigmf_io import Annotation, write_sigmf


def save_partial_capture(
    error: HilError, stem, cfg: OtaConfig, hw: str = "HackRF One"
) -> Path | None:
    """Write what the receiver got before ``error`` as ci8 SigMF at ``<stem>_rx_partial``.

    Sets ``error.sigmf_path``. Returns the ``.sigmf-meta`` path, or None when the error
    carries no samples (SigMF cannot hold an empty recording).
    """
    capture = getattr(error, "capture", None)
    if capture is None or np.asarray(capture).size == 0:
        return None
    stem = Path(stem)
    error.sigmf_path = write_sigmf(
        stem.with_name(stem.name + "_rx_partial"),
        np.asarray(capture).reshape(-1),
        sample_rate_hz=cfg.sample_rate_hz,
        center_freq_hz=cfg.center_freq_hz,
        hw=f"{hw} (RX)",
        description=f"capture so far, stopped by: {error}",
    )
    return error.sigmf_path


def save_sigmf(result: BurstResult, stem, cfg: OtaConfig, hw: str = "HackRF One") -> list[Path]:
    """Write the burst (TX) and the capture (RX, one annotation per detected frame) as ci8 SigMF."""
    stem = Path(stem)
    anns = [
        Annotation(
            f.start_index,
            f.num_samples,
            f"frame {f.number}",
            f.snr_db,
            f.crc_ok,
            {"block": f.block, "cfo_hz": f.cfo_hz},
        )
        for f in result.frames
        if f.detected and f.start_index is not None
    ]
    paths = [
        write_sigmf(
            stem.with_name(stem.name + "_tx"),
            result.burst,
            sample_rate_hz=cfg.sample_rate_hz,
            center_freq_hz=cfg.center_freq_hz,
            hw=f"{hw} (TX)",
            description="transmitted burst",
        ),
        write_sigmf(
            stem.with_name(stem.name + "_rx"),
            result.capture,
            sample_rate_hz=cfg.sample_rate_hz,
            center_freq_hz=cfg.center_freq_hz,
            annotations=anns,
            hw=f"{hw} (RX)",
            description="received capture; annotations: detected frames",
        ),
    ]
    result.sigmf = [str(p) for p in paths]
    return paths
