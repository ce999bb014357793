"""The result file of `osnerf ota`: per scheme and image the PSNR and frames, the summary,
every frame, the SigMF paths, and the provenance header (with the codec's sha256)."""

from __future__ import annotations

import time

import numpy as np


def ota_record(args, cfg, settings, names, bursts, t0: float) -> dict:
    """The result file's record: per scheme and image, the summary, every frame, the SigMF
    paths. ``bursts``: (scheme, per-image receptions, ``hil.BurstResult``, SigMF paths)."""
    from osnerf.provenance import result_header

    results, frames, sigmf, by_scheme = [], [], [], {}
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
        }
        if all("symbol_budget" in r for r in rows):  # the codec's: sent against asked
            sent, budget = (sum(r[k] for r in rows) for k in ("num_symbols", "symbol_budget"))
            by_scheme[scheme].update(
                symbols_sent=sent, symbol_budget=budget, symbols_unused=budget - sent
            )
    config = {k: v for k, v in vars(args).items() if k not in ("command",)}
    config.update(
        {
            "symbols_per_frame": cfg.symbols_per_frame,
            "header_symbols": cfg.header_symbols,
            "tx_power_dbfs": cfg.tx_power_dbfs,
        }
    )
    record = result_header(config, args.seed)
    if settings.codec is not None:
        from semcodec import capability_record

        record["codec"] = {"name": settings.codec.name, "sha256": settings.codec.sha256}
        record["codec"].update(capability_record(settings.codec, 0))
        record["codec"]["refinement"]["why"] = "ota sends the codec's symbols as encoded"
    record.update(
        {
            "results": results,
            "sigmf": sigmf,
            "summary": {
                "frames_sent": sum(s["frames_sent"] for s in by_scheme.values()),
                "frames_lost": sum(s["frames_lost"] for s in by_scheme.values()),
                "snr_db_measured": float(
                    np.mean([s["snr_db_measured"] for s in by_scheme.values()])
                ),
                "schemes": by_scheme,
                "psnr_note": "mean of per-image PSNR (peak 1.0)",
                "seconds": time.perf_counter() - t0,
            },
            "frames": frames,
        }
    )
    return record
