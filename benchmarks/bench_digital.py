"""Digital baseline throughput: ``phy.digital.transmit_bytes`` against a direct sionna call.

Side by side in one run, on the same info-bit count and codeword size: our chain (CRC24B
per codeword, 5G LDPC, scrambling, QAM, AWGN link, soft demapping, BP decoding with CRC
early stopping, at most 20 iterations) and the bare sionna.phy chain (LDPC5G encoder ->
Mapper -> AWGN -> Demapper -> LDPC5G decoder, a fixed 20 iterations). Throughput is payload
(information) bits per second through encode + channel + decode, 2 threads; CPU seconds
are reported too because wall time on a shared machine mostly measures the other jobs. At a high SNR
early stopping makes ours faster; near the threshold both run all 20 iterations. Timings on
a shared 2-core machine are noisy.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

import phy
from phy.digital import DEFAULT_NUM_ITER, codeword_layout, min_num_symbols, transmit_bytes

PAYLOAD_BYTES = 4000  # 32 kbit
CASES = [("qpsk-1/2", 3.0), ("qpsk-1/2", 15.0), ("16qam-3/4", 11.0), ("16qam-3/4", 25.0)]


def _best_of(fn, repeats: int = 2) -> tuple[float, float]:
    """Best (wall seconds, CPU seconds of this process) over ``repeats`` runs."""
    best = (float("inf"), float("inf"))
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, (time.perf_counter() - t0, time.process_time() - c0))
    return best


def _direct_sionna(mcs: str, snr_db: float, num_info_bits: int):
    """The same codeword size, coded with sionna's blocks directly (no CRC, no early stop)."""
    from sionna.phy.channel import AWGN
    from sionna.phy.fec.ldpc import LDPC5GDecoder, LDPC5GEncoder
    from sionna.phy.mapping import Demapper, Mapper

    m = phy.digital.get_mcs(mcs)
    lay = codeword_layout(min_num_symbols(num_info_bits // 8, m), m)
    k, n = lay.ldpc_k(0), lay.coded_bits(0)
    num_cw = lay.num_codewords
    enc = LDPC5GEncoder(k, n, num_bits_per_symbol=m.bits_per_symbol)
    dec = LDPC5GDecoder(enc, num_iter=DEFAULT_NUM_ITER)
    mapper, demapper = Mapper("qam", m.bits_per_symbol), Demapper("app", "qam", m.bits_per_symbol)
    channel = AWGN()
    no = torch.tensor(phy.snr_db_to_noise_var(snr_db))
    u = torch.randint(0, 2, (num_cw, k), generator=torch.Generator().manual_seed(0)).float()

    def once():
        with torch.no_grad():
            u_hat = dec(demapper(channel(mapper(enc(u)), no), no))
        return (u_hat != u).any(dim=1).float().mean().item()

    return once, num_cw * k


def run(out_dir: Path) -> dict:
    torch.set_num_threads(2)
    payload = np.random.default_rng(0).integers(0, 256, PAYLOAD_BYTES, dtype=np.uint8).tobytes()
    link = phy.FlatLink(phy.AWGN())
    results = {"payload_bytes": PAYLOAD_BYTES, "max_iterations": DEFAULT_NUM_ITER, "cases": []}
    for mcs, snr_db in CASES:
        g = torch.Generator().manual_seed(1)
        res = transmit_bytes(payload, mcs, link, snr_db, generator=g)  # warm-up, builds codes
        ours_s, ours_cpu = _best_of(
            lambda mcs=mcs, snr_db=snr_db, g=g: transmit_bytes(
                payload, mcs, link, snr_db, generator=g
            )
        )
        direct, direct_bits = _direct_sionna(mcs, snr_db, 8 * PAYLOAD_BYTES)
        bler_direct = direct()
        direct_s, direct_cpu = _best_of(direct)
        ours_mbps = 8 * PAYLOAD_BYTES / ours_s / 1e6
        direct_mbps = direct_bits / direct_s / 1e6
        row = {
            "mcs": mcs,
            "snr_db": snr_db,
            "num_codewords": res.num_codewords,
            "ours_ok": res.ok,
            "ours_failed_codewords": len(res.failed_codewords),
            "ours_mean_iterations": round(res.extra["mean_iterations"], 2),
            "ours_s": round(ours_s, 3),
            "ours_cpu_s": round(ours_cpu, 3),
            "ours_mbit_per_s": float(f"{ours_mbps:.4g}"),
            "direct_sionna_bler": bler_direct,
            "direct_sionna_s": round(direct_s, 3),
            "direct_sionna_cpu_s": round(direct_cpu, 3),
            "direct_sionna_mbit_per_s": float(f"{direct_mbps:.4g}"),
            "ratio_ours_over_direct": round(ours_mbps / direct_mbps, 2),
        }
        print(row)
        results["cases"].append(row)
    return results
