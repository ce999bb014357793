"""SigMF recordings through the ``sigmf`` package: write captures and bursts, read them back.

Raw HackRF captures are ``ci8`` (interleaved int8 I, Q; full scale 128); processed
streams are ``cf32_le``. Annotations mark detected frames with their SNR estimate and CRC
result. Reading checks the SHA-512 and the size, so a truncated or corrupt file raises
:class:`hil.SigmfError` instead of returning garbage.
"""

from __future__ import annotations

import datetime as _dt
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common import write_bytes, write_text
from hil.errors import SigmfError
from hil.iq import quantize_ci8

DATATYPES = ("ci8", "cf32_le")


@dataclass(frozen=True)
class Annotation:
    """One annotated segment of a recording.

    Attributes:
        sample_start: first sample of the segment.
        sample_count: its length in samples.
        label: short label (e.g. ``"frame 3"``).
        snr_db: SNR estimate for the segment, dB (None if unknown).
        crc_ok: CRC result (None if not checked).
        extra: any further JSON-serialisable facts (kept in ``core:comment``).
    """

    sample_start: int
    sample_count: int
    label: str = ""
    snr_db: float | None = None
    crc_ok: bool | None = None
    extra: dict = field(default_factory=dict)


@dataclass
class Recording:
    """A SigMF recording read back.

    Attributes:
        samples: [num_samples] complex64, full scale 1.0.
        sample_rate_hz, center_freq_hz: from the metadata.
        datatype: ``"ci8"`` or ``"cf32_le"``.
        annotations: list of :class:`Annotation`.
        path: the ``.sigmf-meta`` file.
    """

    samples: np.ndarray
    sample_rate_hz: float
    center_freq_hz: float | None
    datatype: str
    annotations: list
    path: Path


def sigmf_paths(path) -> tuple[Path, Path]:
    """``(meta, data)`` paths for a path stem (extensions stripped)."""
    path = Path(path)
    name = path.name
    for ext in (".sigmf-meta", ".sigmf-data"):
        if name.endswith(ext):
            name = name[: -len(ext)]
    stem = path.with_name(name)
    return stem.with_name(name + ".sigmf-meta"), stem.with_name(name + ".sigmf-data")


def _payload(samples, datatype: str) -> bytes:
    """The data file's bytes of ``samples`` in ``datatype`` (see :func:`write_sigmf`)."""
    if datatype not in DATATYPES:
        raise ValueError(f"datatype must be one of {DATATYPES}, got {datatype!r}")
    x = np.asarray(samples)
    if datatype == "ci8":
        if x.dtype == np.int8:
            raw = x.reshape(-1)
        else:
            raw = quantize_ci8(x.reshape(-1))
        payload = raw.astype(np.int8).tobytes()
    else:
        payload = x.reshape(-1).astype(np.complex64).tobytes()
    if not payload:
        raise ValueError("a SigMF recording needs at least one sample, got none")
    return payload


def write_sigmf(
    path,
    samples,
    *,
    sample_rate_hz: float,
    center_freq_hz: float | None = None,
    datatype: str = "ci8",
    annotations=(),
    hw: str | None = None,
    description: str | None = None,
) -> Path:
    """Write a recording; returns the ``.sigmf-meta`` path.

    Args:
        path: path stem (``.sigmf-meta`` / ``.sigmf-data`` are added).
        samples: for ``ci8``: [2 * num_samples] int8 raw interleaved I, Q, or
            [num_samples] / [1, num_samples] complex (full scale 1.0, quantised here);
            for ``cf32_le``: [num_samples] / [1, num_samples] complex.
        sample_rate_hz: sample rate, Hz.
        center_freq_hz: centre frequency of the capture, Hz.
        datatype: ``"ci8"`` or ``"cf32_le"``.
        annotations: :class:`Annotation` objects.
        hw: hardware description (``core:hw``).
        description: free text (``core:description``).
    """
    import sigmf
    from sigmf import SigMFFile

    payload = _payload(samples, datatype)
    meta_path, data_path = sigmf_paths(path)
    meta_path.parent.mkdir(parents=True, exist_ok=True)
    info = {
        sigmf.DATATYPE_KEY: datatype,
        sigmf.SAMPLE_RATE_KEY: float(sample_rate_hz),
        sigmf.VERSION_KEY: sigmf.__specification__,
        sigmf.RECORDER_KEY: "osnerf hil",
    }
    if hw:
        info[sigmf.HW_KEY] = hw
    if description:
        info[sigmf.DESCRIPTION_KEY] = description
    capture: dict[str, str | float] = {
        sigmf.DATETIME_KEY: _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    }
    if center_freq_hz is not None:
        capture[sigmf.FREQUENCY_KEY] = float(center_freq_hz)
    try:
        write_bytes(data_path, payload)
        meta = SigMFFile(data_file=data_path, global_info=info)
        meta.add_capture(0, metadata=capture)
        for a in annotations:
            facts = dict(a.extra)
            if a.snr_db is not None:
                facts["snr_db"] = round(float(a.snr_db), 3)
            if a.crc_ok is not None:
                facts["crc_ok"] = bool(a.crc_ok)
            md = {
                sigmf.LABEL_KEY: a.label or "frame",
                sigmf.COMMENT_KEY: json.dumps(facts, sort_keys=True),
            }
            meta.add_annotation(int(a.sample_start), int(a.sample_count), metadata=md)
        meta.validate()
        write_text(meta_path, meta.dumps(pretty=True))
    except BaseException:
        for q in (data_path, meta_path):  # never a data file without its metadata
            q.unlink(missing_ok=True)
        raise
    return meta_path


def read_sigmf(path) -> Recording:
    """Read a recording written by :func:`write_sigmf` (or any single-channel ci8 / cf32_le SigMF).

    Raises:
        SigmfError: missing files, unreadable metadata, hash mismatch (corrupt), a size that
            is not a whole number of samples (truncated), or an unsupported datatype.
    """
    import sigmf

    meta_path, data_path = sigmf_paths(path)
    if not meta_path.is_file():
        raise SigmfError(f"SigMF metadata not found: {meta_path}")
    if not data_path.is_file():
        raise SigmfError(f"SigMF data file not found: {data_path}")
    try:  # the datatype first, so that a short data file is blamed, not the metadata
        datatype = json.loads(meta_path.read_text())["global"][sigmf.DATATYPE_KEY]
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise SigmfError(f"{meta_path}: metadata is not valid JSON: {e}") from e
    except (KeyError, TypeError) as e:
        raise SigmfError(f"{meta_path}: malformed metadata: no global {e}") from e
    if datatype not in DATATYPES:
        raise SigmfError(
            f"{meta_path}: datatype {datatype!r} not supported (use one of {DATATYPES})"
        )
    size = 2 if datatype == "ci8" else 8
    nbytes = data_path.stat().st_size
    if nbytes == 0 or nbytes % size:
        raise SigmfError(
            f"{data_path}: {nbytes} bytes is not a whole number of {datatype} samples "
            "(truncated? the data file is damaged, not its metadata)"
        )
    try:
        with warnings.catch_warnings():  # a truncated file warns first; we raise below
            warnings.simplefilter("ignore")
            meta = sigmf.fromfile(str(meta_path))
    except sigmf.error.SigMFError as e:
        if "hash" in str(e).lower():
            raise SigmfError(
                f"{data_path}: its bytes do not match the SHA-512 in {meta_path.name} "
                "(the data file is corrupt or truncated)"
            ) from e
        raise SigmfError(f"{meta_path}: corrupt or truncated recording: {e}") from e
    except (KeyError, ValueError, TypeError) as e:
        raise SigmfError(f"{meta_path}: malformed metadata: {e}") from e
    raw = np.fromfile(data_path, dtype=np.int8 if datatype == "ci8" else np.complex64)
    samples = (raw.astype(np.float32) / 128.0).view(np.complex64) if datatype == "ci8" else raw
    rate = meta.get_global_field(sigmf.SAMPLE_RATE_KEY)
    if rate is None or not float(rate) > 0:
        raise SigmfError(f"{meta_path}: core:sample_rate missing or not positive")
    captures = meta.get_captures()
    freq = captures[0].get(sigmf.FREQUENCY_KEY) if captures else None
    anns = []
    for a in meta.get_annotations():
        try:
            facts = json.loads(a.get(sigmf.COMMENT_KEY, "{}") or "{}")
        except json.JSONDecodeError:
            facts = {"comment": a.get(sigmf.COMMENT_KEY)}
        snr = facts.pop("snr_db", None)
        crc = facts.pop("crc_ok", None)
        anns.append(
            Annotation(
                int(a[sigmf.SAMPLE_START_KEY]),
                int(a.get(sigmf.SAMPLE_COUNT_KEY, 0)),
                a.get(sigmf.LABEL_KEY, ""),
                snr,
                crc,
                facts,
            )
        )
    return Recording(samples.astype(np.complex64), float(rate), freq, datatype, anns, meta_path)


class SigmfReplay:
    """Replays a recording through the receive interface of :class:`hil.HackRF`.

    ``rx(num_samples)`` returns consecutive ``[1, num_samples] complex64`` blocks of the
    recording, zero-padded after its end; ``sample_rate_hz`` / ``center_freq_hz`` come
    from the file.
    """

    def __init__(self, path):
        self.recording = read_sigmf(path)
        self.sample_rate_hz = self.recording.sample_rate_hz
        self.center_freq_hz = self.recording.center_freq_hz
        self.position = 0

    def rx(self, num_samples: int) -> np.ndarray:
        num_samples = int(num_samples)
        if num_samples <= 0:
            raise ValueError(f"num_samples must be > 0, got {num_samples}")
        x = self.recording.samples[self.position : self.position + num_samples]
        self.position += num_samples
        out = np.zeros(num_samples, np.complex64)
        out[: len(x)] = x
        return out[None, :]

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        r = self.recording
        return (
            f"SigmfReplay({str(r.path)!r}, {r.datatype}, sample_rate_hz={r.sample_rate_hz}, "
            f"position={self.position})"
        )
