"""Every input of ``osnerf eval-codec`` checked before any work: outputs, channel, schemes,
CBR, MCS, the codec and its ranges, images, LPIPS."""

from __future__ import annotations

import argparse
import sys

from osnerf.commands import args as checks
from osnerf.commands.eval_partial import check_partial_kind
from osnerf.provenance import open_codec
from osnerf.schemes import parse_schemes
from phy import num_symbols_for_cbr, parse_cbr
from phy.digital import MCS_TABLE
from renderer import LPIPS_MIN_SIDE_PX, lpips_weights
from semcodec import LINK_SCHEMES, require_capabilities
from semcodec.links import DEFAULT_FIXED_MCS, eval_channels, load_image_folder


def checked_inputs(args: argparse.Namespace):
    """Every input checked before any work: (out path, schemes, SNRs, CBR, fixed MCS, codec or
    None, image names, images, whether LPIPS is scored)."""
    import torch

    inputs = {"--images": args.images}
    out = checks.output_file(args.out, "--out", overwrite=args.overwrite, inputs=inputs)
    if args.plot:
        checks.output_file(args.plot, "--plot", overwrite=args.overwrite, inputs=inputs)
    checks.distinct_outputs(out=args.out, plot=args.plot)
    check_partial_kind(out)  # a folder or FIFO there is refused before any work
    torch.set_num_threads(args.threads)
    channels = eval_channels()
    if args.channel not in channels:
        raise KeyError(f"--channel: unknown channel {args.channel!r}; known: {channels}")
    schemes = _schemes(args)
    snrs = list(args.snr_db)
    try:
        cbr = parse_cbr(args.cbr)
    except ValueError as e:
        raise ValueError(f"--{e}") from None
    mcs = _fixed_mcs(args, schemes)
    codec = _codec(args, schemes, cbr, snrs)
    names, images, score_lpips = _images(args, cbr)
    return out, schemes, snrs, cbr, mcs, codec, names, images, score_lpips


def _schemes(args: argparse.Namespace) -> list[str]:
    try:
        return parse_schemes(args.schemes, LINK_SCHEMES)
    except ValueError as e:
        raise ValueError(f"--schemes {e}") from None


def _fixed_mcs(args: argparse.Namespace, schemes: list[str]) -> str:
    """``--mcs`` (else the default), refused without a fixed-MCS scheme or outside the table."""
    mcs = DEFAULT_FIXED_MCS if args.mcs is None else args.mcs
    fixed = [s for s in schemes if LINK_SCHEMES[s].mcs == "fixed"]
    if args.mcs is not None and not fixed:
        known = ", ".join(n for n, s in LINK_SCHEMES.items() if s.mcs == "fixed")
        raise ValueError(
            f"--mcs applies to the fixed-MCS schemes ({known}), not to --schemes "
            f"{','.join(schemes)}: add one or leave --mcs out"
        )
    if fixed:
        if mcs not in MCS_TABLE:
            raise KeyError(f"--mcs must be one of {', '.join(MCS_TABLE)}, got {mcs!r}")
    return mcs


def _codec(args: argparse.Namespace, schemes: list[str], cbr: float, snrs: list[float]):
    """The semantic codec when a scheme needs one (else None), its CBR and SNR ranges
    covering ``--cbr`` and ``--snr-db``."""
    if not any(LINK_SCHEMES[s].needs_codec for s in schemes):
        return None

    codec = open_codec(args.codec, args.allow_untrained)
    refine = [s for s in schemes if LINK_SCHEMES[s].refines]
    limits = require_capabilities(codec, bool(refine), f"--schemes {','.join(refine)}")
    if limits.line():
        print(f"eval-codec: {limits.line()}", file=sys.stderr)
    lo, hi = codec.cbr_range
    if not lo * 0.999 <= cbr <= hi * 1.001:
        raise ValueError(
            f"--cbr {args.cbr} is outside the codec's range [{lo:.4g}, {hi:.4g}] ({codec.name})"
        )
    slo, shi = codec.snr_range_db
    if not slo <= min(snrs) <= max(snrs) <= shi:
        raise ValueError(
            f"--snr-db [{min(snrs):g}, {max(snrs):g}] dB is not covered by codec "
            f"{codec.name!r}, trained for SNR [{slo:g}, {shi:g}] dB"
        )
    return codec


def _images(args: argparse.Namespace, cbr: float):
    """(names, images, whether LPIPS is scored): every image gets a channel symbol at ``cbr``;
    LPIPS needs every image at least its smallest side, and its weights."""
    names, images = load_image_folder(args.images)
    if args.max_images is not None:
        names, images = names[: args.max_images], images[: args.max_images]
    for name, img in zip(names, images):
        if num_symbols_for_cbr(cbr, *img.shape[-2:]) < 1:
            raise ValueError(
                f"--cbr {args.cbr} gives {name} ({img.shape[-1]}x{img.shape[-2]} px) no channel "
                "symbol; give a larger --cbr"
            )
    score_lpips = not args.no_lpips and all(
        min(img.shape[-2:]) >= LPIPS_MIN_SIDE_PX for img in images
    )
    if score_lpips:
        try:
            lpips_weights()  # checked before any work
        except FileNotFoundError as e:
            raise FileNotFoundError(f"{e}, or pass --no-lpips") from None
    return names, images, score_lpips
