"""The result file of `osnerf ota`: per scheme and image the PSNR and frames, the summary,
every frame, the SigMF paths, and the provenance header (with the codec's sha256).

Results are labelled with the SNR the receiver measured from the pilots
(``snr_db_measured``), beside the SNR the emulated air was set to (``snr_db_requested``;
null between real radios, whose air is not ours to set); the jscc encoder's SNR input is
``codec.encoder_snr_db``."""

from __future__ import annotations

import time

import numpy as np

from osnerf.commands.ota_config import OtaRunConfig
from osnerf.provenance import codec_record, result_header
from semcodec import capability_record


def ota_record(opts: OtaRunConfig, cfg, settings, names, bursts, t0: float) -> dict:
    """The result file's record: per scheme and image, the summary, every frame, the SigMF
    paths. ``bursts``: (scheme, per-image receptions, ``hil.ota.BurstResult``, SigMF paths)."""
    results, frames, sigmf, by_scheme = [], [], [], {}
    requested = opts.snr_db  # None: a real air
    for scheme, per_image, result, paths in bursts:
        rows = []
        for b, (name, rec) in enumerate(zip(names, per_image)):
            burst_frames = result.block_frames(b)
            rows.append(
                {
                    "scheme": scheme,
                    "image": name,
                    "psnr": rec.psnr,
                    "snr_db_measured": result.snr_db_measured(b),
                    "snr_db_requested": requested,
                    "frames_sent": len(burst_frames),
                    "frames_lost": sum(not f.detected for f in burst_frames),
                    **rec.stats,
                }
            )
        results += rows
        frames += [{"scheme": scheme, **vars(f)} for f in result.frames]
        sigmf += [str(p) for p in paths]
        by_scheme[scheme] = {
            "mean_psnr": float(np.mean([r["psnr"] for r in rows])),
            "frames_sent": result.frames_sent,
            "frames_lost": result.frames_lost,
            "snr_db_measured": result.snr_db_measured(),
            "snr_db_requested": requested,
        }
        if all("symbol_budget" in r for r in rows):  # the codec's: sent against asked
            sent, budget = (sum(r[k] for r in rows) for k in ("num_symbols", "symbol_budget"))
            by_scheme[scheme].update(
                symbols_sent=sent, symbol_budget=budget, symbols_unused=budget - sent
            )
    config = opts.as_record()
    config.update(
        {
            "symbols_per_frame": cfg.symbols_per_frame,
            "header_symbols": cfg.header_symbols,
            "tx_power_dbfs": cfg.tx_power_dbfs,
        }
    )
    record = result_header(config, opts.seed)
    record["codec"] = None
    if settings.codec is not None:
        record["codec"] = {
            **codec_record(settings.codec, opts.codec),
            "encoder_snr_db": settings.snr_db,
            **capability_record(settings.codec, 0),
        }
        record["codec"]["refinement"]["why"] = "ota sends the codec's symbols as encoded"
    record.update(
        {
            "results": results,
            "sigmf": sigmf,
            "summary": {
                "frames_sent": sum(s["frames_sent"] for s in by_scheme.values()),
                "frames_lost": sum(s["frames_lost"] for s in by_scheme.values()),
                "snr_db_measured": _mean_or_none(
                    [s["snr_db_measured"] for s in by_scheme.values()]
                ),
                "snr_db_requested": requested,
                "schemes": by_scheme,
                "psnr_note": "mean of per-image PSNR (peak 1.0)",
                "seconds": time.perf_counter() - t0,
            },
            "frames": frames,
        }
    )
    return record


def _mean_or_none(values: list) -> float | None:
    """The mean of the values measured (None where every frame was lost), None if none was."""
    known = [v for v in values if v is not None]
    return float(np.mean(known)) if known else None


CAPTURE_GLOBS = ("ota*.sigmf-meta", "ota*.sigmf-data")  # every SigMF file a run writes


def remove_old_captures(sigmf_dir) -> list:
    """``--overwrite``: the SigMF files an earlier run left in ``sigmf_dir`` (its burst, its
    captures, a partial capture of a failed run) are removed before this run writes its own,
    so the folder never mixes two runs. Returns the paths removed."""
    from pathlib import Path

    removed = []
    for pattern in CAPTURE_GLOBS:
        for path in sorted(Path(sigmf_dir).glob(pattern)):
            if path.is_file() or path.is_symlink():
                path.unlink()
                removed.append(path)
    return removed
