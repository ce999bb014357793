"""`osnerf codec-info --codec NAME[:CHECKPOINT]`: a codec's complexity, as JSON on stdout.

For any registered codec (plugins included): its parameters (every ``torch.nn.Module`` it
holds, each counted once), multiply-accumulates per pixel of ``encode`` and ``decode``
(torch's own ``torch.utils.flop_counter.FlopCounterMode``, FLOPs / 2; operations torch does
not count, such as a plugin's numpy, are not in it) and the median wall time of each over
``--repeats`` calls on one thread, on one image (default the first Kodak image). Beside it
the digital link on the same image: AVIF's search for the best file that fits the budget of
the MCS the calibration table plans at ``--snr-db`` (what ``digital`` runs per image), and
LDPC encoding and decoding of that file's codewords (``phy.digital``, belief propagation).
"""

from __future__ import annotations

import argparse
import json
import sys

from common import median_seconds, write_text
from osnerf.cli import inputs_checked
from osnerf.commands import args as checks
from osnerf.paths import shared_data_dir
from osnerf.provenance import open_codec, result_header

MAX_REPEATS = 100


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--codec",
        default=None,
        metavar="NAME[:CHECKPOINT]",
        help="the codec (default: jscc with the shipped checkpoint); plugins through the "
        "semcodec.codecs entry points",
    )
    checks.add_allow_untrained(p)
    p.add_argument(
        "--image",
        default=None,
        help="the image to time on (default: the first Kodak image of the shared data)",
    )
    p.add_argument("--snr-db", type=checks.snr_db, default=10.0, help="SNR (default 10 dB)")
    p.add_argument("--cbr", default="1/16", help="channel bandwidth ratio (default 1/16)")
    p.add_argument(
        "--repeats",
        type=checks.count(1, MAX_REPEATS),
        default=5,
        help=f"calls timed per step, the median reported (1..{MAX_REPEATS}, default 5)",
    )
    p.add_argument("--no-digital", action="store_true", help="leave out the digital timings")
    p.add_argument("--out", default=None, help="also write the JSON here")


def _modules(codec) -> list:
    """Every ``nn.Module`` the codec is or holds (attributes, one level), each once."""
    from torch import nn

    found = [codec] if isinstance(codec, nn.Module) else []
    for v in vars(codec).values() if hasattr(codec, "__dict__") else ():
        if isinstance(v, nn.Module):
            found.append(v)
    return found


def count_parameters(codec) -> dict:
    """Parameters (and buffers) of every module the codec holds, each tensor counted once."""
    seen_p, seen_b = {}, {}
    for m in _modules(codec):
        for p in m.parameters():
            seen_p[id(p)] = p.numel()
        for b in m.buffers():
            seen_b[id(b)] = b.numel()
    return {"parameters": int(sum(seen_p.values())), "buffers": int(sum(seen_b.values()))}


def _macs(fn) -> int:
    from torch.utils.flop_counter import FlopCounterMode

    with FlopCounterMode(display=False) as counter:
        fn()
    return int(counter.get_total_flops() // 2)


def codec_complexity(codec, image, snr_db: float, cbr: float, repeats: int) -> dict:
    """Parameters, MACs per pixel and median times of ``encode`` and ``decode`` on ``image``
    [1, 3, height, width] (one thread: the caller sets it)."""
    import torch

    from semcodec import decode_received, encode_with_focus

    pixels = image.shape[-2] * image.shape[-1]
    with torch.no_grad():
        enc = encode_with_focus(codec, image, snr_db, cbr)

        def encode():
            return encode_with_focus(codec, image, snr_db, cbr)

        def decode():
            return decode_received(codec, enc.symbols, enc.meta, snr_db)

        enc_macs, dec_macs = _macs(encode), _macs(decode)
        enc_s, dec_s = median_seconds(encode, repeats), median_seconds(decode, repeats)
    return {
        **count_parameters(codec),
        "encode_macs_per_pixel": enc_macs / pixels,
        "decode_macs_per_pixel": dec_macs / pixels,
        "encode_seconds": enc_s,
        "decode_seconds": dec_s,
        "num_symbols": int(enc.symbols.shape[-1]),
    }


def run(args: argparse.Namespace) -> int:
    import torch

    from phy import parse_cbr
    from semcodec.links import load_image_folder

    try:
        cbr = parse_cbr(args.cbr)
    except ValueError as e:
        raise ValueError(f"--{e}") from None
    if args.image is None:
        kodak = shared_data_dir() / "kodak"
        names, images = load_image_folder(sorted(kodak.glob("*.png"))[0])
    else:
        names, images = load_image_folder(args.image)
    codec = open_codec(args.codec, args.allow_untrained)
    inputs_checked()
    torch.set_num_threads(1)
    image = images[0]
    doc = result_header(
        {
            "codec": args.codec,
            "image": names[0],
            "height": int(image.shape[-2]),
            "width": int(image.shape[-1]),
            "snr_db": args.snr_db,
            "cbr": cbr,
            "repeats": args.repeats,
            "threads": 1,
            "macs": "torch.utils.flop_counter.FlopCounterMode total FLOPs / 2 (torch ops only)",
            "seconds": "median wall time of --repeats calls after one warm-up, one thread",
        },
        None,
    )
    doc["codec"] = {"name": codec.name, "sha256": codec.sha256}
    doc["complexity"] = codec_complexity(codec, image, args.snr_db, cbr, args.repeats)
    if not args.no_digital:
        from phy import num_symbols_for_cbr
        from semcodec.digital import digital_timing

        n = num_symbols_for_cbr(cbr, image.shape[-2], image.shape[-1])
        doc["digital"] = digital_timing(image, args.snr_db, n, args.repeats)
    text = json.dumps(doc, indent=1)
    if args.out:
        write_text(args.out, text)
    print(text)
    c = doc["complexity"]
    print(
        f"codec-info: {codec.name}: {c['parameters']:,} parameters, "
        f"{c['encode_macs_per_pixel']:.0f} + {c['decode_macs_per_pixel']:.0f} MACs/pixel, "
        f"encode {c['encode_seconds'] * 1e3:.0f} ms, decode {c['decode_seconds'] * 1e3:.0f} ms",
        file=sys.stderr,
    )
    return 0
