"""`osnerf render`: render a camera path from a trained field to PNGs and an MP4 or GIF.

The path is an orbit around the scene centre (radius, up axis and intrinsics default to
the training cameras') or the ``frames[].transform_matrix`` of a JSON file (``--path``).
``--renderer`` names one of ``renderer.RENDERERS``: ``full`` volume rendering or
``features`` (the lightweight renderer: a learned feature field at low resolution + decoder),
which is distilled first around the cameras the field stores; that time is
``setup_seconds`` (and ``setup_cpu_seconds``, ``peak_memory_mb``), not part of the time per view.
Writes ``OUT/frames/NNN.png``, ``OUT/path.mp4`` or ``OUT/path.gif`` (OpenCV), and
``OUT/render.json`` (config, ``seconds_per_view``, the renderer's settings and setup stats).
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import sys
import time
from pathlib import Path

from common import atomic_path, write_png
from osnerf.cli import UsageError, inputs_checked
from osnerf.commands import args as checks
from osnerf.provenance import result_header, write_json_atomic

VIDEOS = ("mp4", "gif", "none")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options, in ``--help`` order: the field and the output, the camera path, the
    renderer, the video."""
    p.add_argument(
        "--run",
        required=True,
        help="run folder of `osnerf train-nerf` (with model.pt), or a model .pt file",
    )
    p.add_argument("--out", required=True, help="output folder (frames/, video, render.json)")
    checks.add_overwrite(p, "the frames, video and render.json of an --out folder")
    _add_path_arguments(p)
    _add_renderer_arguments(p)
    p.add_argument(
        "--video", default="mp4", help=f"video format: {' | '.join(VIDEOS)} (default mp4)"
    )
    p.add_argument(
        "--fps",
        type=checks.number(0.0, 240.0, "frames/s", low_open=True),
        default=24.0,
        help="video frame rate, (0, 240] (default 24)",
    )
    p.add_argument(
        "--threads", type=checks.threads, default=2, help="torch CPU threads (default 2)"
    )


def _add_path_arguments(p: argparse.ArgumentParser) -> None:
    """The camera path: an orbit (views, size, elevation, radius, arc) or a JSON file."""
    p.add_argument(
        "--num-views",
        type=checks.count(1, checks.MAX_VIEWS),
        default=60,
        help=f"views on the orbit, 1..{checks.MAX_VIEWS} (default 60)",
    )
    p.add_argument(
        "--resolution",
        type=checks.resolution,
        default=None,
        help="image width in pixels, 16..512 (default: training width)",
    )
    p.add_argument(
        "--elevation-deg",
        type=checks.number(-90.0, 90.0, "deg"),
        default=30.0,
        help="orbit elevation above the horizon, -90..90 (default 30)",
    )
    p.add_argument(
        "--radius-m",
        type=checks.number(0.0, 1e4, "m", low_open=True),
        default=None,
        help="orbit radius (default: mean training camera distance)",
    )
    p.add_argument(
        "--arc-deg",
        type=checks.number(0.0, 360.0, "deg", low_open=True),
        default=360.0,
        help="orbit arc, (0, 360] (default 360)",
    )
    p.add_argument(
        "--path",
        default=None,
        help="JSON with frames[].transform_matrix to render instead of an orbit",
    )


def _add_renderer_arguments(p: argparse.ArgumentParser) -> None:
    """Which renderer, and a learned renderer's setup: steps, budget, refinement, seed."""
    p.add_argument(
        "--renderer",
        default="full",
        help="a renderer of renderer.RENDERERS: full (default) or features (the lightweight "
        "renderer: learned feature field at low resolution + decoder)",
    )
    p.add_argument(
        "--renderer-steps",
        type=checks.count(1, 1_000_000),
        default=None,
        help="features renderer: distillation steps (default: the rendered size's, "
        "renderer.FeatureConfig.for_resolution)",
    )
    p.add_argument(
        "--renderer-cpu-seconds",
        type=checks.seconds,
        default=None,
        help="features renderer: setup budget in CPU seconds (baking, teachers, training; "
        "default: the rendered size's, renderer.FeatureConfig.for_resolution)",
    )
    p.add_argument(
        "--renderer-refine",
        type=checks.number(0.0, 1.0, low_open=True),
        default=None,
        help="features renderer: render again with the field, at full resolution, the pixels "
        "whose decoded 3 x 3 neighbourhood spans more than this in a colour channel, (0, 1] "
        "(renderer.refine: slower, closer to the full render; default: the rendered size's, "
        "off; 1 renders none again)",
    )
    p.add_argument(
        "--seed",
        type=checks.seed,
        default=0,
        help="learned renderers' seed (default 0); the full renderer draws nothing and records "
        "no seed",
    )


def _path_poses(path: Path):
    import torch

    from renderer import pose_problem

    if not path.is_file():
        raise FileNotFoundError(f"--path {path}: file not found")
    try:
        frames = json.loads(path.read_text())["frames"]
        poses = torch.tensor([f["transform_matrix"] for f in frames], dtype=torch.float32)
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"--path {path}: needs frames[].transform_matrix (4x4 each)") from e
    if len(frames) == 0:
        raise ValueError(f"--path {path}: no frames to render (frames[] is empty)")
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"--path {path}: frames[].transform_matrix must be 4x4 matrices")
    for i, pose in enumerate(poses):
        problem = pose_problem(pose)
        if problem:
            raise ValueError(f"--path {path}: frames[{i}].transform_matrix {problem}")
    return poses


def run(args: argparse.Namespace) -> int:
    import torch

    from renderer import make_renderer

    model_path, model = _checked_model(args)
    intr, poses = _camera_path(args, model)

    config = renderer_config(args, intr.width)
    inputs_checked()  # from here on a failure is a runtime failure (exit 1)
    t0, c0 = time.perf_counter(), time.process_time()
    rend, setup_stats = make_renderer(
        args.renderer, model, None, config, torch.Generator().manual_seed(args.seed)
    )
    setup_seconds, setup_cpu = time.perf_counter() - t0, time.process_time() - c0
    if _learned(args.renderer) and (setup_stats or {}).get("steps") == 0:
        raise UsageError(
            f"--renderer-cpu-seconds {args.renderer_cpu_seconds} ran out before the first "
            f"distillation step ({setup_stats.get('teacher_views', 0)} teacher views rendered "
            f"in {setup_cpu:.1f} CPU-s): the renderer learnt nothing; give a larger budget or "
            "--renderer-steps"
        )
    rendered = rend.render_path(poses, intr)
    payoff = _payoff(rend, model, poses, intr, rendered["seconds_per_view"], setup_seconds)

    out_dir = Path(args.out)
    frames = _write_frames(out_dir, rendered["rgb"], model_path)
    video = _write_video(frames, out_dir, args.video, args.fps, intr.width, intr.height)
    cfg = {k: v for k, v in vars(args).items() if k != "func"}
    if not _learned(args.renderer):
        cfg["seed"] = None  # nothing is drawn; kept as a flag since sweeps pass one to every point
    record = result_header(cfg, None)
    record.update(
        {
            "num_views": len(frames),
            "width": intr.width,
            "height": intr.height,
            "seconds_per_view": rendered["seconds_per_view"],
            "seconds_per_view_note": "rendering only, no file I/O",
            "setup_seconds": setup_seconds,
            "setup_cpu_seconds": setup_cpu,
            "setup_stats": setup_stats,
            "peak_memory_mb": peak_memory_mb(),
            **payoff,
            "renderer": rend.settings(),
            "video": None if video is None else video.name,
        }
    )
    write_json_atomic(out_dir / "render.json", record)
    print(
        f"render: {len(frames)} views, {args.renderer} renderer, "
        f"{rendered['seconds_per_view']:.3f} s/view, setup {setup_seconds:.1f} s, break-even "
        f"{_views(payoff['break_even_views'])} -> {out_dir}",
        file=sys.stderr,
    )
    return 0


def _checked_model(args: argparse.Namespace):
    """(model path, model): every option and the field checked before any work."""
    import torch

    from renderer import RENDERERS, load_model

    if args.renderer not in RENDERERS:
        raise UsageError(f"--renderer must be one of {', '.join(RENDERERS)}, got {args.renderer!r}")
    if args.video not in VIDEOS:
        raise UsageError(f"--video must be one of {', '.join(VIDEOS)}, got {args.video!r}")
    for flag in ("renderer_steps", "renderer_cpu_seconds", "renderer_refine"):
        if not _learned(args.renderer) and getattr(args, flag) is not None:
            raise UsageError(
                f"--{flag.replace('_', '-')} applies only to a learned renderer (features): "
                f"--renderer {args.renderer} renders the field directly, with no setup"
            )
    run_path = Path(args.run)
    model_path = run_path / "model.pt" if run_path.is_dir() else run_path
    if not model_path.is_file():
        raise FileNotFoundError(
            f"--run {run_path}: no model.pt (train one with `osnerf train-nerf`)"
        )
    checks.output_dir(args.out, "--out", overwrite=args.overwrite)  # refused before any work
    torch.set_num_threads(args.threads)
    try:
        model = load_model(model_path)
    except ValueError as e:
        raise UsageError(f"--run: {e}; train it again with `osnerf train-nerf`") from None
    return model_path, model


def _write_frames(out_dir: Path, rgbs, model_path: Path) -> list:
    """``OUT/frames/NNN.png`` of each view (an earlier render's frames removed); returns the
    frames in BGR for OpenCV's video writers."""
    import torch

    from renderer import to_uint8

    for old in sorted((out_dir / "frames").glob("[0-9][0-9][0-9].png")):
        old.unlink()  # --overwrite: no frame of an earlier render stays beside the new ones
    frames = []
    for i, rgb in enumerate(rgbs):
        if not torch.isfinite(rgb).all():
            raise RuntimeError(
                f"view {i} rendered non-finite colours: the model {model_path} is broken"
            )
        frame = to_uint8(rgb)
        write_png(out_dir / "frames" / f"{i:03d}.png", frame)
        frames.append(frame[..., ::-1])  # BGR for OpenCV's video writers
    return frames


PAYOFF_VIEWS = 4
"""Views of the path the full render is timed on to price a learned renderer's setup."""


def _payoff(rend, model, poses, intr, seconds_per_view: float, setup_seconds: float) -> dict:
    """The full render's time per view (measured on the path's first :data:`PAYOFF_VIEWS`
    views; the renderer's own when it is the full one) and the break-even view count
    (``renderer.break_even_views``: setup seconds over the seconds saved per view)."""
    from renderer import FullRenderer, break_even_views

    if isinstance(rend, FullRenderer):  # nothing to pay off
        full, even = seconds_per_view, 0.0
    else:
        full = FullRenderer(model).render_path(poses[:PAYOFF_VIEWS], intr)["seconds_per_view"]
        even = break_even_views(setup_seconds, seconds_per_view, full)
    return {
        "full_seconds_per_view": full,
        "break_even_views": even,
        "break_even_note": "setup_seconds / (full_seconds_per_view - seconds_per_view); "
        "null: it saves no time per view",
    }


def _views(n) -> str:
    return "never" if n is None else f"{n:,.0f} views"


def _camera_path(args: argparse.Namespace, model):
    """(intrinsics, poses) of the views to render: the field's stored camera, resized to
    ``--resolution``; the poses of ``--path`` or an orbit around the stored centre."""
    import torch

    from renderer import Intrinsics, orbit_path

    cam = model.spec.get("camera", {})
    k = cam.get(
        "intrinsics", {"fl_x": 100.0, "fl_y": 100.0, "cx": 50.0, "cy": 50.0, "w": 100, "h": 100}
    )
    intr = Intrinsics(k["fl_x"], k["fl_y"], k["cx"], k["cy"], int(k["h"]), int(k["w"]))
    if args.resolution is not None:
        intr = intr.resized(
            max(1, round(intr.height * args.resolution / intr.width)), args.resolution
        )
    if args.path is not None:
        poses = _path_poses(Path(args.path))
    else:
        center = torch.tensor(cam.get("center", model.aabb.mean(0).tolist()))
        radius = args.radius_m or cam.get("radius_m", 4.0)
        up = torch.tensor(cam.get("up", [0.0, 0.0, 1.0]))
        poses = orbit_path(
            args.num_views, radius, args.elevation_deg, center, 0.0, args.arc_deg, up
        )
    return intr, poses


def _write_video(frames, out_dir: Path, kind: str, fps: float, width: int, height: int):
    """``path.mp4`` or ``path.gif`` of the BGR frames (atomically), or None for no video."""
    import cv2

    video = None
    if kind == "mp4":
        video = out_dir / "path.mp4"
        with atomic_path(video) as tmp:
            writer = cv2.VideoWriter(
                str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), fps, (width, height)
            )
            if not writer.isOpened():
                raise RuntimeError(f"OpenCV could not write {video}")
            for f in frames:
                writer.write(f)
            writer.release()
            if os.path.getsize(tmp) == 0:
                raise OSError(errno.EIO, "OpenCV wrote an empty video", str(video))
    elif kind == "gif":
        video = out_dir / "path.gif"
        anim = cv2.Animation()
        anim.frames = frames
        anim.durations = [int(round(1000 / fps))] * len(frames)
        with atomic_path(video) as tmp:
            if not cv2.imwriteanimation(str(tmp), anim):
                raise OSError(errno.EIO, "OpenCV could not write the animation", str(video))
    return video


def renderer_config(args: argparse.Namespace, width_px: int):
    """The learned renderer's settings for views ``width_px`` wide, with --renderer-steps,
    --renderer-cpu-seconds and --renderer-refine (None for the full renderer)."""
    from renderer import FeatureConfig

    if not _learned(args.renderer):
        return None
    budget: dict = {}
    if args.renderer_steps is not None:  # the steps are the budget; no time cap
        budget = {
            "train_steps": args.renderer_steps,
            "train_seconds": checks.MAX_BUDGET_S,
            "setup_cpu_seconds": None,
        }
    if args.renderer_cpu_seconds is not None:  # a CPU budget (steps, when given, cap it)
        budget["setup_cpu_seconds"] = args.renderer_cpu_seconds
        budget.setdefault("train_steps", None)
    if getattr(args, "renderer_refine", None) is not None:
        budget["refine_contrast"] = args.renderer_refine
    return FeatureConfig.for_resolution(width_px, width_px=width_px, progress=True, **budget)


def _learned(renderer: str) -> bool:
    """Whether ``renderer`` is distilled before it renders (it takes --renderer-steps)."""
    return renderer == "features"


def peak_memory_mb() -> float:
    """This process's peak resident memory so far (MB; Linux reports ru_maxrss in kB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
