"""`osnerf train-nerf`: train a radiance field on a nerfstudio/Blender folder.

Trains on the ``train`` split, evaluates the ``test`` split, and writes
``RUN_DIR/metrics.json`` ({config, seed, git_commit, versions, train_seconds, steps,
test: {psnr, ssim, num_views[, masked_psnr]}, curve: [{seconds, step, psnr}]}; PSNR and
SSIM are means of per-view values), the rendered test views ``RUN_DIR/test/NNN.png`` and
the model ``RUN_DIR/model.pt`` (for `osnerf render`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from common import write_png
from osnerf.cli import UsageError, inputs_checked
from osnerf.commands import args as checks
from osnerf.provenance import result_header, write_json_atomic

FIELDS = ("grid", "mlp")
CLOCKS = ("wall", "cpu")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--data", required=True, help="dataset folder (transforms_train.json / transforms.json)"
    )
    p.add_argument("--out", required=True, help="run folder for metrics.json, test views, model.pt")
    checks.add_overwrite(p, "the model, metrics and test views of an --out folder")
    p.add_argument(
        "--resolution",
        type=checks.resolution,
        default=100,
        help="image width in pixels, 16..512 (default 100)",
    )
    p.add_argument(
        "--max-seconds",
        type=checks.seconds,
        default=120.0,
        help=f"training budget in seconds, up to {checks.MAX_BUDGET_S:g} (default 120)",
    )
    p.add_argument("--seed", type=checks.seed, default=0, help="random seed (default 0)")
    p.add_argument(
        "--field", default="grid", help=f"radiance field: {' | '.join(FIELDS)} (default grid)"
    )
    p.add_argument(
        "--clock",
        default="wall",
        help="budget clock: wall | cpu (CPU seconds / threads; default wall)",
    )
    p.add_argument(
        "--background",
        default=None,
        help="RGB in [0,1] as r,g,b for RGBA images (default: file's or white)",
    )
    p.add_argument(
        "--eval-every-seconds",
        type=checks.seconds,
        default=10.0,
        help="curve spacing in training seconds (default 10)",
    )
    p.add_argument(
        "--threads", type=checks.threads, default=2, help="torch CPU threads (default 2)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")


def _background(text: str | None):
    if text is None:
        return None
    try:
        rgb = tuple(float(v) for v in text.split(","))
    except ValueError as e:
        raise UsageError(f"--background must be r,g,b with values in [0, 1], got {text!r}") from e
    if len(rgb) != 3 or not all(0 <= v <= 1 for v in rgb):
        raise UsageError(f"--background must be r,g,b with values in [0, 1], got {text!r}")
    return rgb


def run(args: argparse.Namespace) -> int:
    import torch

    from renderer import (
        TrainConfig,
        image_metrics,
        load_dataset,
        render_views,
        train,
    )

    if args.field not in FIELDS:
        raise UsageError(f"--field must be one of {', '.join(FIELDS)}, got {args.field!r}")
    if args.clock not in CLOCKS:
        raise UsageError(f"--clock must be one of {', '.join(CLOCKS)}, got {args.clock!r}")
    run_dir = checks.output_dir(
        args.out, "--out", overwrite=args.overwrite, inputs={"--data": args.data}
    )
    data = Path(args.data)
    if not data.is_dir():
        raise FileNotFoundError(f"--data {data}: folder not found")
    background = _background(args.background)
    torch.set_num_threads(args.threads)

    train_set = load_dataset(data, "train", args.resolution, background)
    test_set = load_dataset(
        data, "test", args.resolution, train_set.background, aabb=train_set.aabb
    )
    config = TrainConfig.for_resolution(
        train_set.width,
        field=args.field,
        max_seconds=args.max_seconds,
        clock=args.clock,
        eval_every_seconds=args.eval_every_seconds,
        progress=not args.no_progress,
    )
    print(
        f"train-nerf: {train_set.num_views} train / {test_set.num_views} test views at "
        f"{train_set.width}x{train_set.height}, field {args.field}, {args.max_seconds:g} s",
        file=sys.stderr,
    )
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    result = train(
        train_set, config, torch.Generator().manual_seed(args.seed), eval_dataset=test_set
    )
    out = render_views(result.model, test_set.poses, test_set.intrinsics)
    metrics = image_metrics(out["rgb"], test_set.images, test_set.masks)

    record = _write_run(run_dir, args, data, train_set, config, result, out, metrics)
    test = record["test"]
    path = write_json_atomic(run_dir / "metrics.json", record)
    print(
        f"train-nerf: test PSNR {test['psnr']:.2f} dB, SSIM {test['ssim']:.3f} -> {path}",
        file=sys.stderr,
    )
    return 0


def _write_run(run_dir: Path, args, data: Path, train_set, config, result, out, metrics) -> dict:
    """Write the test renders and ``model.pt``; return the ``metrics.json`` record."""
    from renderer import save_model, to_uint8

    (run_dir / "test").mkdir(parents=True, exist_ok=True)
    for i, img in enumerate(out["rgb"]):
        write_png(run_dir / "test" / f"{i:03d}.png", to_uint8(img))
    save_model(result.model, run_dir / "model.pt")
    test = {"psnr": metrics["psnr"], "ssim": metrics["ssim"], "num_views": metrics["num_views"]}
    if "masked_psnr" in metrics:
        test["masked_psnr"] = metrics["masked_psnr"]
    test["psnr_per_view"] = metrics["psnr_per_view"]
    cfg = {
        "data": str(data.resolve()),
        "resolution": args.resolution,
        "max_seconds": args.max_seconds,
        "field": args.field,
        "threads": args.threads,
        "background": list(train_set.background),
        "aabb": train_set.aabb.tolist(),
        "num_train_views": train_set.num_views,
        "train": config.as_dict(),
        "metric_note": (
            "psnr/ssim are means of per-view values; psnr peak 1.0; ssim scikit-image "
            "data_range=1.0"
        ),
    }
    record = result_header(cfg, args.seed)
    record.update(
        {
            "train_seconds": result.seconds,
            "steps": result.steps,
            "test": test,
            "curve": result.curve,
            "model": "model.pt",
        }
    )
    return record
