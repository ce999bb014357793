"""``python -m campaign promote CANDIDATE``: a candidate against the shipped default, promoted
only by :data:`RULE`.

The comparison: Kodak (first 12) through ``osnerf eval-codec`` on AWGN, fast and block
Rayleigh (4 draws) at every CBR of :data:`CBRS` and SNR of :data:`SNRS_DB`, plus over the air
(``osnerf ota``, emulated boards) on seeds 0-4; both codecs see the same images and seeds.
It is written to a new ``bench-results/promotion_<sha12>_<time>.json`` whatever the decision
(every record is kept). Only that full comparison against the shipped default can promote:
a narrower one (another ``--baseline``, fewer images, channels, ...) runs with ``--dry-run``
only. A promotion keeps the old default as ``semcodec/checkpoints/<its name's
suffix>.safetensors``, writes the candidate as ``default.safetensors`` (weights as stored,
card extended), repoints the campaign's lines, re-runs the README codec table's jscc rows for
the new default and regenerates the pages (:mod:`benchmarks.results`): all of it computed
first, then swapped in as one step that an error or Ctrl-C undoes.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from statistics import mean

from benchmarks import results as pages
from campaign.store import Campaign, at_work, card_of, now_utc
from campaign.swap import swap
from common import InputError, to_json
from osnerf import result_header
from osnerf.paths import shared_data_dir

ROOT = Path(__file__).resolve().parent.parent
RULE = {"max_loss_db": 0.1, "min_mean_gain_db": 0.2, "ota_max_loss_db": 0.1}
RULE_TEXT = (
    "promote only when no Kodak point (channel, CBR, SNR) is more than {max_loss_db:g} dB "
    "below the default, the mean gain over those points is at least {min_mean_gain_db:g} dB, "
    "and over the air the mean over seeds at each SNR is at most {ota_max_loss_db:g} dB below"
).format(**RULE)
CHANNELS = ("awgn", "rayleigh_fast", "rayleigh")
DRAWS = {"rayleigh": 4}
"""Draws per image where one is too few (block fading: one fade per image)."""
CBRS = ("1/48", "1/16", "1/6", "1/4", "1/3")
SNRS_DB = (1.0, 4.0, 10.0)
OTA_SEEDS = (0, 1, 2, 3, 4)
OTA_SNRS_DB = (1.0, 10.0)
MAX_IMAGES = 12  # Kodak images of the comparison
OTA_SIZE = 256  # over-the-air image side (px)
TABLE_IMAGES = 24  # Kodak images of the README table


def _csv(kind):
    def parse(text: str):
        try:
            return tuple(kind(v) for v in text.split(",") if v) if text != "none" else ()
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"must be a comma-separated list, got {text!r}"
            ) from None

    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("candidate", help="a JSCC checkpoint, or a campaign line (its best)")
    p.add_argument("--baseline", default=None, help="default: the shipped default checkpoint")
    p.add_argument("--images", default=None, help="image folder (default: the shared Kodak)")
    p.add_argument(
        "--max-images", type=int, default=MAX_IMAGES, help=f"first N images (default {MAX_IMAGES})"
    )
    p.add_argument("--channels", type=_csv(str), default=CHANNELS, help=",".join(CHANNELS))
    p.add_argument("--cbrs", type=_csv(str), default=CBRS, help=",".join(CBRS))
    p.add_argument("--snrs-db", type=_csv(float), default=SNRS_DB, help="default 1,4,10")
    p.add_argument("--ota-seeds", type=_csv(int), default=OTA_SEEDS, help="'none' for none")
    p.add_argument("--ota-snrs-db", type=_csv(float), default=OTA_SNRS_DB, help="default 1,10")
    p.add_argument("--ota-size", type=int, default=OTA_SIZE, help="over-the-air image side (px)")
    p.add_argument("--out", default=str(ROOT / "bench-results"), help="folder of the JSON")
    p.add_argument("--campaign", default=str(ROOT / "campaign"), help="campaign folder")
    p.add_argument("--dry-run", action="store_true", help="compare and write the JSON only")
    p.add_argument(
        "--table-images", type=int, default=TABLE_IMAGES, help="Kodak images of the README table"
    )


def decide(kodak: list[dict], ota: list[dict], rule: dict = RULE) -> dict:
    """Apply the promotion rule.

    Args:
        kodak: ``[{"channel", "cbr", "snr_db", "candidate", "baseline"}]`` mean PSNR (dB).
        ota: ``[{"snr_db", "seed", "candidate", "baseline"}]`` mean PSNR (dB).
    Returns:
        ``{"promote", "worst_db", "mean_gain_db", "ota_mean_gain_db", "reasons", "rule"}``.
    """
    if not kodak:
        raise InputError("promotion needs at least one Kodak point")
    deltas = [round(p["candidate"] - p["baseline"], 3) for p in kodak]  # to 0.001 dB
    worst, gain = min(deltas), mean(deltas)
    reasons = []
    if worst < -rule["max_loss_db"]:
        p = kodak[deltas.index(worst)]
        reasons.append(
            f"{p['channel']} CBR {p['cbr']} {p['snr_db']:g} dB is {-worst:.2f} dB below the "
            f"default (at most {rule['max_loss_db']:g})"
        )
    if gain < rule["min_mean_gain_db"]:
        reasons.append(f"mean gain {gain:+.2f} dB < {rule['min_mean_gain_db']:g} dB")
    ota_gain = {}
    for snr in sorted({p["snr_db"] for p in ota}):
        d = mean(p["candidate"] - p["baseline"] for p in ota if p["snr_db"] == snr)
        ota_gain[f"{snr:g}"] = round(d, 3)
        if d < -rule["ota_max_loss_db"]:
            reasons.append(f"over the air at {snr:g} dB the mean is {-d:.2f} dB below")
    return {
        "promote": not reasons,
        "worst_db": round(worst, 3),
        "mean_gain_db": round(gain, 3),
        "ota_mean_gain_db": ota_gain,
        "reasons": reasons,
        "rule": RULE_TEXT,
    }


def osnerf(argv: list[str], what: str) -> None:
    """``osnerf ARGV``, in this process: its Ctrl-C (exit 130, caught by the command) is
    raised again as the interrupt it was; any other failure is a ``RuntimeError``."""
    from osnerf.cli import main

    rc = main(argv)
    if rc == 130:
        raise KeyboardInterrupt
    if rc != 0:
        raise RuntimeError(f"{what} failed (exit {rc})")


def _eval_codec(args, codec: Path, channel: str, cbr: str, out: Path) -> list[dict]:
    argv = ["eval-codec", "--images", args.images, "--channel", channel, "--cbr", cbr]
    argv += ["--snr-db=" + ",".join(f"{s:g}" for s in args.snrs_db), "--schemes", "jscc"]
    argv += ["--draws", str(DRAWS.get(channel, 1)), "--seed", "0", "--no-lpips"]
    argv += ["--max-images", str(args.max_images), "--codec", str(codec), "--out", str(out)]
    osnerf([*argv, "--overwrite"], f"osnerf {' '.join(argv)}")
    return json.loads(out.read_text())["results"]


def _ota(args, codec: Path, snr: float, seed: int, tmp: Path) -> float:
    out = tmp / f"ota_{snr:g}_{seed}.json"
    argv = ["ota", "--schemes", "jscc", "--images", args.images, "--snr-db", f"{snr:g}"]
    argv += ["--seed", str(seed), "--max-images", str(args.max_images), "--codec", str(codec)]
    argv += ["--size", str(args.ota_size), "--out", str(out), "--sigmf-dir", str(tmp / "sigmf")]
    osnerf([*argv, "--overwrite"], f"osnerf {' '.join(argv)}")
    return float(json.loads(out.read_text())["summary"]["schemes"]["jscc"]["mean_psnr"])


def compare(args, candidate: Path, baseline: Path) -> tuple[list[dict], list[dict]]:
    """The Kodak and over-the-air points of both codecs (same images, seeds and draws)."""
    kodak: dict = {}
    ota = []
    with tempfile.TemporaryDirectory(prefix="promote-") as tmp:
        t = Path(tmp)
        for role, ck in (("candidate", candidate), ("baseline", baseline)):
            for ch in args.channels:
                for cbr in args.cbrs:
                    out = t / f"{role}_{ch}_{cbr.replace('/', '_')}.json"
                    for r in _eval_codec(args, ck, ch, cbr, out):
                        key = (ch, cbr, float(r["snr_db"]))
                        kodak.setdefault(key, {"num_images": r["num_images"]})[role] = r["psnr"]
        for snr in args.ota_snrs_db:
            for seed in args.ota_seeds:
                row = {"snr_db": snr, "seed": seed}
                for role, ck in (("candidate", candidate), ("baseline", baseline)):
                    row[role] = _ota(args, ck, snr, seed, t)
                ota.append(row)
    points = [
        {"channel": ch, "cbr": cbr, "snr_db": snr, **v} for (ch, cbr, snr), v in kodak.items()
    ]
    return points, ota


def narrowed(args) -> list[str]:
    """The options that make a comparison narrower than the rule's full one (another
    baseline, images, channels, CBRs, SNRs, seeds or sizes); a promotion needs none."""
    full = {
        "--channels": (args.channels, CHANNELS),
        "--cbrs": (args.cbrs, CBRS),
        "--snrs-db": (tuple(args.snrs_db), SNRS_DB),
        "--max-images": (args.max_images, MAX_IMAGES),
        "--ota-seeds": (tuple(args.ota_seeds), OTA_SEEDS),
        "--ota-snrs-db": (tuple(args.ota_snrs_db), OTA_SNRS_DB),
        "--ota-size": (args.ota_size, OTA_SIZE),
        "--table-images": (args.table_images, TABLE_IMAGES),
    }
    out = [flag for flag, (given, rule) in full.items() if given != rule]
    kodak = (shared_data_dir() / "kodak").resolve()
    if args.images is not None and Path(args.images).resolve() != kodak:
        out.insert(0, "--images")
    if args.baseline is not None and Path(args.baseline).resolve() != default_checkpoint():
        out.insert(0, "--baseline")
    return out


def default_checkpoint() -> Path:
    """The shipped default that a promotion replaces (under :data:`ROOT`)."""
    return (ROOT / "semcodec" / "checkpoints" / "default.safetensors").resolve()


def _checkpoint(text: str, flag: str) -> tuple[Path, dict]:
    path = Path(text)
    try:
        card = card_of(path)
    except ValueError as e:
        raise InputError(f"{flag}: {e}") from None
    if "sha256" not in card:
        raise InputError(f"{flag}: {path} has no model card with a sha256 (not a codec checkpoint)")
    return path, card


def _candidate(args) -> Path:
    """The candidate's file: a path, or a campaign line's best."""
    cand = Path(args.candidate)
    if cand.is_file():
        return cand
    camp = Campaign.open(args.campaign)
    lines = camp.doc["lines"]
    if args.candidate not in lines:
        raise InputError(
            f"candidate not found: {args.candidate} is neither a file nor a campaign line "
            f"({', '.join(lines)})"
        )
    cand = camp.best_path(lines[args.candidate])
    if cand is None:
        raise InputError(f"campaign line {args.candidate} has no best yet")
    return cand


def _resolve(args) -> tuple[Path, Path, dict, dict]:
    """(candidate, baseline, their cards); a line name means that line's best. Every option
    is checked here, before any comparison."""
    import phy
    from semcodec.links import eval_channels

    if not 1 <= args.max_images <= 1000 or not 8 <= args.ota_size <= 1024:
        raise InputError("--max-images must be in [1, 1000] and --ota-size in [8, 1024]")
    if not 1 <= args.table_images <= 1000:
        raise InputError(f"--table-images must be in [1, 1000], got {args.table_images}")
    if not args.channels or not args.cbrs or not args.snrs_db:
        raise InputError("--channels, --cbrs and --snrs-db each need at least one value")
    known = eval_channels()
    for ch in args.channels:
        if ch not in known:
            raise InputError(f"--channels: unknown channel {ch!r}; known: {', '.join(known)}")
    for cbr in args.cbrs:
        try:
            phy.parse_cbr(cbr)
        except ValueError as e:
            raise InputError(f"--cbrs: {e}") from None
    bad = [s for s in (*args.snrs_db, *args.ota_snrs_db) if not -30 <= s <= 40]
    if bad:
        raise InputError(f"--snrs-db and --ota-snrs-db must be in [-30, 40] dB, got {bad[0]:g}")
    cand, cand_card = _checkpoint(str(_candidate(args)), "candidate")
    base, base_card = _checkpoint(str(args.baseline or default_checkpoint()), "--baseline")
    args.images = args.images or str(shared_data_dir() / "kodak")
    if not Path(args.images).exists():
        raise InputError(f"--images not found: {args.images}")
    return cand, base, cand_card, base_card


def record_path(folder: Path, sha: str) -> Path:
    """A new promotion record's path: the candidate's hash and the time, never an earlier
    record's name."""
    stem = f"promotion_{sha[:12]}_{now_utc().replace('-', '').replace(':', '')}"
    path, n = folder / f"{stem}.json", 1
    while path.exists():
        n += 1
        path = folder / f"{stem}_{n}.json"
    return path


def run(args) -> int:
    """Compare, write the JSON, promote when the rule says so (not with ``--dry-run``).

    A promotion needs the rule's full comparison against the shipped default: any narrower
    setting is refused (exit 2) before any work unless ``--dry-run``."""
    import sys

    if not args.dry_run and (flags := narrowed(args)):
        raise InputError(
            f"{', '.join(flags)} narrow the comparison; a promotion is judged on the full one "
            "against the shipped default: add --dry-run to compare only"
        )
    cand, base, cand_card, base_card = _resolve(args)
    kodak, ota = at_work(compare, args, cand, base)
    decision = decide(kodak, ota)
    settings = {k: v for k, v in vars(args).items() if k not in ("verb",)}
    doc = {
        **result_header(settings, 0),
        "candidate": {
            "path": str(cand),
            "name": cand_card.get("name"),
            "sha256": cand_card["sha256"],
        },
        "baseline": {
            "path": str(base),
            "name": base_card.get("name"),
            "sha256": base_card["sha256"],
        },
        "kodak": kodak,
        "ota": ota,
        "decision": decision,
        "promoted": False,
    }
    path = record_path(Path(args.out), cand_card["sha256"])
    if decision["promote"] and not args.dry_run:
        doc["promoted"] = True
        with Campaign.open(args.campaign).locked():  # no stretch saves between stage and swap
            files = at_work(stage_promotion, args, cand, path, decision)
            doc["files"] = [str(p) for p, data in files.items() if data is not None]
            doc["removed"] = [str(p) for p, data in files.items() if data is None]
            files[path] = _json_bytes(doc)  # last: the record says the set is complete
            swap(files)
    else:
        swap({path: _json_bytes(doc)})
    verdict = "promoted" if doc["promoted"] else "not promoted"
    why = "; ".join(decision["reasons"]) or "meets the rule" + (
        " (dry run)" if args.dry_run else ""
    )
    print(
        f"campaign promote: {verdict}: mean gain {decision['mean_gain_db']:+.2f} dB, worst "
        f"{decision['worst_db']:+.2f} dB ({why}); {path}",
        file=sys.stderr,
    )
    return 0


def _json_bytes(doc: dict) -> bytes:
    return (to_json(doc) + "\n").encode()


def _card_json(card: dict) -> str:
    return json.dumps(card, indent=2, sort_keys=True) + "\n"


def recard(src: Path, update: dict) -> tuple[bytes, dict]:
    """A checkpoint's bytes with its model card extended by ``update`` (weights and sha256 as
    stored), and the card."""
    from safetensors.torch import load_file, save

    card = {**card_of(src), **update}
    state = load_file(str(src))
    return save(state, metadata={"model_card": json.dumps(card, sort_keys=True)}), card


def stage_promotion(args, cand: Path, record: Path, decision: dict) -> dict[Path, bytes | None]:
    """Everything a promotion changes, computed before any file is touched: the new default
    and its card, the old default kept beside it, the campaign's lines repointed, the README
    codec table's jscc rows for the new default (the old default's removed), ``README.md`` and
    ``docs/results.md`` regenerated from those. Returns path -> new bytes (None: removed),
    for :func:`swap`."""
    default = default_checkpoint()
    ck = default.parent
    old = card_of(default)
    keep = ck / f"{old['name'].removeprefix(old['architecture']['name'] + '-')}.safetensors"
    data, card = recard(cand, {"promotion": {"comparison": record.name, **decision}})
    files: dict[Path, bytes | None] = {default: data}
    files[ck / "default.card.json"] = _card_json(card).encode()
    if not keep.exists():
        files[keep] = default.read_bytes()
        files[keep.with_name(keep.name.replace(".safetensors", ".card.json"))] = _card_json(
            old
        ).encode()
    camp = Campaign.open(args.campaign)
    for line in camp.doc["lines"].values():
        best = line.get("best") or {}
        if best.get("sha256") == old["sha256"]:
            best["path"] = str(Path("..", keep.relative_to(ROOT)))
        elif best.get("sha256") == card["sha256"]:
            copy = (camp.folder / best["path"]).resolve()
            if copy.is_relative_to(camp.folder.resolve()) and copy != default:
                files[copy] = None  # referenced, not copied
            best["path"] = str(Path("..", default.relative_to(ROOT)))
    files[camp.folder / "campaign.json"] = (to_json(camp.doc) + "\n").encode()
    results = ROOT / "bench-results"
    with tempfile.TemporaryDirectory(prefix="promote-pages-") as tmp:
        staged = Path(tmp) / "default.safetensors"
        staged.write_bytes(data)
        table = _codec_table(args.table_images, staged, Path(tmp), card["sha256"])
        for name, text in table.items():
            files[results / name] = text.encode()
            gone = results / name.replace(card["sha256"][:12], old["sha256"][:12])
            if gone.exists():
                files[gone] = None
        view = _staged_view(Path(tmp) / "view", files)
        doc, head = pages.render(view / "bench-results", view / "checkpoints")
    readme = ROOT / "README.md"
    files[ROOT / "docs" / "results.md"] = doc.encode()
    files[readme] = pages.readme_with(head, readme.read_text(), readme).encode()
    return files


def _staged_view(at: Path, files: dict[Path, bytes | None]) -> Path:
    """``bench-results/`` and the checkpoints' cards as they will be after the swap, as links
    to the files that stay and copies of the new ones (what the pages are rendered from)."""
    dirs = (("bench-results", ROOT / "bench-results"), ("checkpoints", default_checkpoint().parent))
    for sub, src in dirs:
        dst = at / sub
        dst.mkdir(parents=True)
        for p in src.iterdir() if src.is_dir() else ():
            if p not in files:
                (dst / p.name).symlink_to(p.resolve())
        for p, data in files.items():
            if p.parent == src and data is not None:
                (dst / p.name).write_bytes(data)
    return at


def _codec_table(images: int, codec: Path, folder: Path, new_sha: str) -> dict[str, str]:
    """The README codec table's jscc rows for the new default ``codec`` (what ``python -m
    benchmarks codec`` writes for it), evaluated into ``folder``: file name -> JSON text."""
    from benchmarks.bench_codec import CHANNELS as TABLE_CHANNELS
    from benchmarks.bench_codec import TABLE_SNRS

    out = {}
    for channel, draws in TABLE_CHANNELS:
        argv = ["--images", str(shared_data_dir() / "kodak")]
        argv += ["--snr-db=" + ",".join(f"{s:g}" for s in TABLE_SNRS), "--cbr", "1/16"]
        argv += ["--seed", "0", "--max-images", str(images), "--no-lpips", "--threads", "1"]
        argv += ["--channel", channel, "--draws", str(draws), "--schemes", "jscc"]
        name = f"codec_{channel}_jscc_{new_sha[:12]}.json"
        run = ["eval-codec", *argv, "--codec", str(codec), "--out", str(folder / name)]
        osnerf([*run, "--overwrite"], f"eval-codec for the README table on {channel}")
        doc = json.loads((folder / name).read_text())
        doc["argv"] = argv  # the command as it reads once the candidate is the default
        out[name] = json.dumps(doc)
    return out
