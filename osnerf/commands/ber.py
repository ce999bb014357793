"""`osnerf ber`: uncoded BER vs SNR over AWGN or Rayleigh fading, against closed forms.

``--snr-db`` is Es/N0 per symbol. Rayleigh is flat fast fading (one h ~ CN(0,1) per
symbol) with perfect CSI and coherent detection (ZF + minimum distance = ML).
Writes ``{"config", "seed", "git_commit", "versions", "results": [...]}`` to ``--out``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import phy
from common import write_figure
from osnerf.cli import UsageError, inputs_checked
from osnerf.commands import args as checks
from osnerf.provenance import result_header, write_json_atomic
from phy import (
    MODULATIONS,
    ber_theory,
    bits_per_symbol,
    ser_theory,
    simulate_uncoded,
    snr_db_to_ebno_db,
)
from phy import THEORY_CHANNELS as CHANNEL_CHOICES  # channels with a closed form

MAX_NUM_BITS = 10**9


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--channel",
        default="awgn",
        choices=CHANNEL_CHOICES,
        help=f"one of {', '.join(CHANNEL_CHOICES)} (default awgn)",
    )
    p.add_argument(
        "--modulation",
        default="qpsk",
        choices=tuple(MODULATIONS),
        help=f"one of {', '.join(MODULATIONS)} (default qpsk)",
    )
    p.add_argument(
        "--snr-db",
        default="0,5,10",
        type=checks.snr_db_list,
        help="comma-separated Es/N0 values in dB, e.g. -10,-5,0 (default 0,5,10)",
    )
    p.add_argument("--num-bits", default="1000000", help="bits per SNR point (default 1000000)")
    p.add_argument(
        "--seed", type=checks.seed, default=0, help="seed of the torch.Generator (default 0)"
    )
    p.add_argument("--out", required=True, help="result JSON path")
    p.add_argument("--plot", default=None, help="optional PNG: simulation and theory")
    checks.add_overwrite(p, "--out and --plot")


def parse_snr_list(text) -> list[float]:
    """'0,5,10' (or an already parsed list) -> [0.0, 5.0, 10.0]; UsageError naming --snr-db."""
    try:
        return checks.snr_db_list(",".join(map(str, text)) if isinstance(text, list) else text)
    except argparse.ArgumentTypeError as e:
        raise UsageError(f"--snr-db {e}") from None


def parse_args(args: argparse.Namespace) -> dict:
    if args.channel not in CHANNEL_CHOICES:
        raise UsageError(
            f"--channel must be one of {', '.join(CHANNEL_CHOICES)}, got {args.channel!r}"
        )
    if args.modulation not in MODULATIONS:
        raise UsageError(
            f"--modulation must be one of {', '.join(MODULATIONS)}, got {args.modulation!r}"
        )
    try:
        num_bits = int(float(args.num_bits))
        if float(args.num_bits) != num_bits:
            raise ValueError
    except (ValueError, OverflowError):
        raise UsageError(
            f"--num-bits must be an integer in [1, {MAX_NUM_BITS:.0e}], got {args.num_bits!r}"
        ) from None
    if not 1 <= num_bits <= MAX_NUM_BITS:
        raise UsageError(f"--num-bits must be in [1, {MAX_NUM_BITS:.0e}], got {args.num_bits!r}")
    if args.plot is not None and not str(args.plot).lower().endswith(".png"):
        raise UsageError(f"--plot must be a .png path, got {args.plot!r}")
    checks.output_file(args.out, "--out", overwrite=args.overwrite)
    if args.plot is not None:
        checks.output_file(args.plot, "--plot", overwrite=args.overwrite)
    checks.distinct_outputs(out=args.out, plot=args.plot)
    return {
        "channel": args.channel,
        "channel_params": _channel(args.channel).record(),
        "modulation": args.modulation,
        "snr_db": parse_snr_list(args.snr_db),
        "num_bits": num_bits,
        "snr_definition": "Es/N0 per symbol",
        "detection": "coherent, perfect CSI, ZF + minimum distance"
        if args.channel == "rayleigh"
        else "minimum distance",
        "fading": "flat fast (one h ~ CN(0,1) per symbol)" if args.channel == "rayleigh" else None,
    }


def _channel(name: str):
    """The channel of ``--channel``: AWGN, or fast Rayleigh (one h per symbol)."""
    return phy.AWGN() if name == "awgn" else phy.RayleighFading(mode="fast")


def simulate(config: dict, seed: int) -> list[dict]:
    import torch
    from tqdm import tqdm

    torch.set_num_threads(min(2, torch.get_num_threads()))
    link = phy.FlatLink(_channel(config["channel"]), csi="perfect", equalizer="zf")
    generator = torch.Generator().manual_seed(seed)
    k = bits_per_symbol(config["modulation"])
    results = []
    for snr in config["snr_db"]:
        t0 = time.perf_counter()
        with tqdm(
            total=config["num_bits"],
            desc=f"{snr:g} dB",
            unit="bit",
            unit_scale=True,
            file=sys.stderr,
            leave=False,
        ) as bar:
            counts = simulate_uncoded(
                config["modulation"], link, snr, config["num_bits"], generator, progress=bar.update
            )
        ber = counts.ber
        results.append(
            {
                "snr_db": snr,
                "ebno_db": snr_db_to_ebno_db(snr, k),
                "ber": ber,
                "ber_theory": ber_theory(config["modulation"], snr, config["channel"]),
                "num_bits": counts.num_bits,
                "num_errors": counts.num_errors,
                "ber_std": math.sqrt(max(ber * (1 - ber), 0.0) / counts.num_bits),
                "ser": counts.ser,
                "ser_theory": ser_theory(config["modulation"], snr, config["channel"]),
                "num_symbols": counts.num_symbols,
                "symbol_errors": counts.symbol_errors,
                "seconds": time.perf_counter() - t0,
            }
        )
        print(
            f"{snr:6.2f} dB  BER {ber:.3e}  theory {results[-1]['ber_theory']:.3e}  "
            f"({counts.num_errors} errors)",
            file=sys.stderr,
        )
    return results


def plot(config: dict, results: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    snrs = [r["snr_db"] for r in results]
    lo, hi = min(snrs), max(snrs)
    grid = np.linspace(lo - 1, hi + 1, 200)
    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.semilogy(
        grid, ber_theory(config["modulation"], grid, config["channel"]), "-", label="theory"
    )
    pts = [(r["snr_db"], r["ber"]) for r in results if r["num_errors"] > 0]
    if pts:
        ax.semilogy(*zip(*pts), "o", label="simulation")
    ax.set_xlabel("Es/N0 [dB]")
    ax.set_ylabel("bit error rate")
    ax.set_title(f"uncoded {config['modulation'].upper()} over {config['channel']}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()

    write_figure(path, fig, dpi=120)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    config = parse_args(args)
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    results = simulate(config, args.seed)
    record = result_header(config, args.seed)
    record["results"] = results
    if args.plot:
        plot(config, results, args.plot)
    path = write_json_atomic(args.out, record)
    print(f"wrote {path}", file=sys.stderr)
    return 0
