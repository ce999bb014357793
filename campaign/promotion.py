"""``python -m campaign promote CANDIDATE``: a candidate against the shipped default, promoted
only by :data:`RULE`.

The comparison: Kodak (first 12) through ``osnerf eval-codec`` on AWGN, fast and block
Rayleigh (4 draws) at every CBR of :data:`CBRS` and SNR of :data:`SNRS_DB`, plus over the air
(``osnerf ota``, emulated boards) on seeds 0-4; both codecs see the same images and seeds.
It is written to ``bench-results/promotion_<sha12>.json`` whatever the decision. A promotion
keeps the old default as ``semcodec/checkpoints/<its name's suffix>.safetensors``, writes the
candidate as ``default.safetensors`` (weights as stored, card extended), repoints the
campaign's lines, re-runs the README codec table's jscc rows for the new default and
regenerates the table (``python -m benchmarks.results``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path
from statistics import mean

from common import InputError, write_bytes, write_text

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
    p.add_argument("--max-images", type=int, default=12, help="first N images (default 12)")
    p.add_argument("--channels", type=_csv(str), default=CHANNELS, help=",".join(CHANNELS))
    p.add_argument("--cbrs", type=_csv(str), default=CBRS, help=",".join(CBRS))
    p.add_argument("--snrs-db", type=_csv(float), default=SNRS_DB, help="default 1,4,10")
    p.add_argument("--ota-seeds", type=_csv(int), default=OTA_SEEDS, help="'none' for none")
    p.add_argument("--ota-snrs-db", type=_csv(float), default=OTA_SNRS_DB, help="default 1,10")
    p.add_argument("--ota-size", type=int, default=256, help="over-the-air image side (px)")
    p.add_argument("--out", default=str(ROOT / "bench-results"), help="folder of the JSON")
    p.add_argument("--campaign", default=str(ROOT / "campaign"), help="campaign folder")
    p.add_argument("--dry-run", action="store_true", help="compare and write the JSON only")
    p.add_argument("--table-images", type=int, default=24, help="Kodak images of the README table")


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


def _eval_codec(args, codec: Path, channel: str, cbr: str, out: Path) -> list[dict]:
    from osnerf.cli import main

    argv = ["eval-codec", "--images", args.images, "--channel", channel, "--cbr", cbr]
    argv += ["--snr-db=" + ",".join(f"{s:g}" for s in args.snrs_db), "--schemes", "jscc"]
    argv += ["--draws", str(DRAWS.get(channel, 1)), "--seed", "0", "--no-lpips"]
    argv += ["--max-images", str(args.max_images), "--codec", str(codec), "--out", str(out)]
    if main([*argv, "--overwrite"]) != 0:
        raise RuntimeError(f"osnerf {' '.join(argv)} failed")
    return json.loads(out.read_text())["results"]


def _ota(args, codec: Path, snr: float, seed: int, tmp: Path) -> float:
    from osnerf.cli import main

    out = tmp / f"ota_{snr:g}_{seed}.json"
    argv = ["ota", "--schemes", "jscc", "--images", args.images, "--snr-db", f"{snr:g}"]
    argv += ["--seed", str(seed), "--max-images", str(args.max_images), "--codec", str(codec)]
    argv += ["--size", str(args.ota_size), "--out", str(out), "--sigmf-dir", str(tmp / "sigmf")]
    if main([*argv, "--overwrite"]) != 0:
        raise RuntimeError(f"osnerf {' '.join(argv)} failed")
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


def _resolve(args) -> tuple[Path, Path, dict, dict]:
    """(candidate, baseline, their cards); a line name means that line's best."""
    from campaign.store import Campaign, card_of
    from osnerf.paths import shared_data_dir
    from semcodec import DEFAULT_CHECKPOINT

    cand = Path(args.candidate)
    if not cand.is_file():
        camp = Campaign.open(args.campaign)
        _, line = camp.line(args.candidate)
        cand = camp.best_path(line)
        if cand is None:
            raise InputError(f"campaign line {args.candidate} has no best yet")
    base = Path(args.baseline) if args.baseline else DEFAULT_CHECKPOINT
    args.images = args.images or str(shared_data_dir() / "kodak")
    if not Path(args.images).exists():
        raise InputError(f"--images not found: {args.images}")
    if not 1 <= args.max_images <= 1000 or not 8 <= args.ota_size <= 1024:
        raise InputError("--max-images must be in [1, 1000] and --ota-size in [8, 1024]")
    if not args.channels or not args.cbrs or not args.snrs_db:
        raise InputError("--channels, --cbrs and --snrs-db each need at least one value")
    return cand, base, card_of(cand), card_of(base)


def run(args) -> int:
    """Compare, write the JSON, promote when the rule says so (not with ``--dry-run``)."""
    import sys

    from campaign.__main__ import at_work
    from osnerf import result_header, write_json_atomic

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
    path = Path(args.out) / f"promotion_{cand_card['sha256'][:12]}.json"
    if decision["promote"] and not args.dry_run:
        doc["promoted"] = True
        doc["files"] = at_work(promote, args, cand, path.name, decision)
    write_json_atomic(path, doc)
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


def recard(src: Path, dst: Path, update: dict) -> dict:
    """Copy a checkpoint with its model card extended by ``update`` (weights and sha256 as
    stored); writes ``dst`` and its ``.card.json`` beside it. Returns the card."""
    from safetensors.torch import load_file, save

    from campaign.store import card_of

    card = {**card_of(src), **update}
    state = load_file(str(src))
    write_bytes(dst, save(state, metadata={"model_card": json.dumps(card, sort_keys=True)}))
    write_text(dst.with_name(dst.name.replace(".safetensors", ".card.json")), _card_json(card))
    return card


def _card_json(card: dict) -> str:
    return json.dumps(card, indent=2, sort_keys=True) + "\n"


def promote(args, cand: Path, comparison: str, decision: dict) -> list[str]:
    """Install ``cand`` as the shipped default (the old one kept beside it), repoint the
    campaign, regenerate the README codec table. Returns the files written."""
    from campaign.store import Campaign, card_of
    from semcodec import DEFAULT_CHECKPOINT

    ck = DEFAULT_CHECKPOINT.parent
    old = card_of(DEFAULT_CHECKPOINT)
    keep = ck / f"{old['name'].removeprefix(old['architecture']['name'] + '-')}.safetensors"
    if not keep.exists():
        shutil.copyfile(DEFAULT_CHECKPOINT, keep)
        write_text(keep.with_name(keep.name.replace(".safetensors", ".card.json")), _card_json(old))
    staged = DEFAULT_CHECKPOINT.with_name("default.promoting.safetensors")
    card = recard(cand, staged, {"promotion": {"comparison": comparison, **decision}})
    staged.replace(DEFAULT_CHECKPOINT)
    staged.with_name("default.promoting.card.json").replace(ck / "default.card.json")
    camp = Campaign.open(args.campaign)
    for line in camp.doc["lines"].values():
        best = line.get("best") or {}
        if best.get("sha256") == old["sha256"]:
            best["path"] = str(Path("..", keep.relative_to(ROOT)))
        elif best.get("sha256") == card["sha256"]:
            copy = camp.folder / best["path"]
            if copy.resolve().is_relative_to(camp.folder.resolve()):
                copy.unlink(missing_ok=True)  # referenced, not copied
            best["path"] = str(Path("..", DEFAULT_CHECKPOINT.relative_to(ROOT)))
    camp.save()
    tables = _codec_table(args.table_images, old["sha256"], card["sha256"])
    from benchmarks.results import main as regenerate

    if regenerate([]) != 0:
        raise RuntimeError("python -m benchmarks.results failed")
    return [str(DEFAULT_CHECKPOINT), str(keep), *tables, "README.md", "docs/results.md"]


def _codec_table(images: int, old_sha: str, new_sha: str) -> list[str]:
    """The README codec table's jscc rows for the new default (what ``python -m benchmarks
    codec`` writes for it), the old default's files removed."""
    from benchmarks.bench_codec import CHANNELS as TABLE_CHANNELS
    from benchmarks.bench_codec import TABLE_SNRS
    from osnerf.cli import main
    from osnerf.paths import shared_data_dir

    results = ROOT / "bench-results"
    written = []
    for channel, draws in TABLE_CHANNELS:
        argv = ["--images", str(shared_data_dir() / "kodak")]
        argv += ["--snr-db=" + ",".join(f"{s:g}" for s in TABLE_SNRS), "--cbr", "1/16"]
        argv += ["--seed", "0", "--max-images", str(images), "--no-lpips", "--threads", "1"]
        argv += ["--channel", channel, "--draws", str(draws), "--schemes", "jscc"]
        path = results / f"codec_{channel}_jscc_{new_sha[:12]}.json"
        if main(["eval-codec", *argv, "--out", str(path), "--overwrite"]) != 0:
            raise RuntimeError(f"eval-codec for the README table failed on {channel}")
        doc = json.loads(path.read_text())
        doc["argv"] = argv
        write_text(path, json.dumps(doc))
        (results / f"codec_{channel}_jscc_{old_sha[:12]}.json").unlink(missing_ok=True)
        written.append(str(path))
    return written
