"""Training any registered codec through a channel: random crops, per-image SNR and rate.

The loop works on a :class:`semcodec.TrainableCodec` (``semcodec.CODECS`` name in
``TrainConfig.codec``): the codec's ``forward_train`` is the differentiable link, its
``module`` holds the parameters, its ``save`` writes the checkpoint.

Wall-clock driven: the learning rate follows the fraction of ``max_minutes`` spent (or of
``max_steps`` when set), so a run stopped and resumed (``last_state.pt``) continues on the
same schedule.

Scale: run under ``torchrun --nproc-per-node N`` and :func:`train` joins the process group
(:mod:`semcodec.distributed`), wraps the codec in DistributedDataParallel and gives rank r
the images ``[r * B / N, (r + 1) * B / N)`` of each global batch of ``B = batch_size``
crops. Only rank 0 writes files.

Random streams (what makes a run resumable at another world size): step k's global batch
(crops, flips, SNRs, rates, channel) is drawn from ``numpy.random.default_rng([seed, k])``
whatever the world size, and rank r's channel noise from a torch generator seeded with
``SeedSequence([seed, k, r])``. A training state therefore needs no RNG state: the step
number and the weights define the rest. Runs at different world sizes see the same images,
SNRs and rates in the same order; they differ in the noise draws and in the order of the
gradient reduction's float sums.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from common import write_torch
from semcodec import distributed
from semcodec.channel_layers import parse_train_channels
from semcodec.contract import CODEC_MEMBERS, TRAINABLE_MEMBERS, missing_members
from semcodec.jscc_train import forward_train, load_compatible
from semcodec.model import make_model
from semcodec.registry import make_codec, parse_codec_spec
from semcodec.training_data import list_images, load_data, random_crops

__all__ = [
    "TrainConfig",
    "build_codec",
    "forward_train",
    "list_images",
    "load_compatible",
    "load_train_state",
    "make_model",
    "train",
    "validate",
]


@dataclass(frozen=True)
class TrainConfig:
    """One training run.

    Attributes:
        codec: the codec to train, a name in ``semcodec.CODECS`` (a :class:`TrainableCodec`),
            or ``NAME:CHECKPOINT`` to start from that checkpoint's weights (as ``init``).
        model: the codec's architecture, one of its ``architectures`` (None: its default;
            the default value is the JSCC's ``adjscc_s4_w96``, so other codecs name theirs or
            None).
        channel: training channel in ``semcodec.TRAIN_CHANNELS``, or a comma-separated
            mixture of them (one drawn uniformly per step).
        crop_px: side of the square random crops.
        batch_size: crops per step.
        lr: peak Adam learning rate.
        max_minutes: wall-clock budget; the LR decays over its last ``decay_fraction``.
        decay_fraction: fraction of the budget with cosine decay to lr/20.
        snr_min_db, snr_max_db: wide SNR range drawn with probability ``p_wide_snr``.
        focus_snr_min_db, focus_snr_max_db: range drawn otherwise.
        p_wide_snr: probability of drawing from the wide range.
        focus_m: 1-based index into the codec's ``rate_levels`` drawn with probability
            ``p_focus_m`` (the JSCC: m = 3 complex channels, CBR 1/16).
        p_focus_m: probability of ``focus_m``; otherwise a rate level drawn uniformly.
        warmup_steps: steps of linear learning-rate warm-up (Adam's first steps move every
            weight by about ``lr`` whatever its gradient, which dents a warm start).
        save_every_s: seconds between checkpoints.
        eval_every_s: seconds between validation runs.
        seed: seed of crops, SNRs, rates and noise.
        num_threads: torch CPU threads (per process).
        max_steps: stop after this many optimiser steps and schedule the LR by steps
            (0: by ``max_minutes`` only).
        device: "cpu", "cuda" or "cuda:N" (under torchrun, "cuda" is GPU ``LOCAL_RANK``).
        ddp_backend: the process group's backend under torchrun: auto (gloo on CPU, nccl on
            CUDA), gloo or nccl.
    """

    codec: str = "jscc"
    model: str | None = "adjscc_s4_w96"
    channel: str = "awgn"
    crop_px: int = 96
    batch_size: int = 12
    lr: float = 1e-3
    max_minutes: float = 60.0
    decay_fraction: float = 0.35
    snr_min_db: float = -5.0
    snr_max_db: float = 20.0
    focus_snr_min_db: float = -2.0
    focus_snr_max_db: float = 14.0
    p_wide_snr: float = 0.25
    focus_m: int = 3
    p_focus_m: float = 0.5
    warmup_steps: int = 0
    save_every_s: float = 180.0
    eval_every_s: float = 300.0
    seed: int = 0
    num_threads: int = 2
    max_steps: int = 0
    device: str = "cpu"
    ddp_backend: str = "auto"

    def __post_init__(self):
        checks = [
            (
                "crop_px",
                16 <= self.crop_px <= 512 and self.crop_px % 4 == 0,
                "a multiple of 4 in [16, 512]",
            ),
            ("batch_size", 1 <= self.batch_size <= 256, "in [1, 256]"),
            ("lr", 0 < self.lr <= 0.1, "in (0, 0.1]"),
            ("max_minutes", 0 < self.max_minutes <= 10000, "in (0, 10000]"),
            ("decay_fraction", 0 <= self.decay_fraction <= 1, "in [0, 1]"),
            (
                "snr_min_db",
                -30 <= self.snr_min_db < self.snr_max_db <= 60,
                "< snr_max_db, both in [-30, 60]",
            ),
            (
                "focus_snr_min_db",
                self.focus_snr_min_db < self.focus_snr_max_db,
                "< focus_snr_max_db",
            ),
            ("p_wide_snr", 0 <= self.p_wide_snr <= 1, "in [0, 1]"),
            ("p_focus_m", 0 <= self.p_focus_m <= 1, "in [0, 1]"),
            ("focus_m", 1 <= self.focus_m <= 24, "in [1, 24]"),
            ("num_threads", 1 <= self.num_threads <= 64, "in [1, 64]"),
            ("max_steps", 0 <= self.max_steps <= 10**9, "in [0, 1e9]"),
            ("warmup_steps", 0 <= self.warmup_steps <= 10**6, "in [0, 1e6]"),
            ("ddp_backend", self.ddp_backend in distributed.BACKENDS, str(distributed.BACKENDS)),
        ]
        for name, ok, allowed in checks:
            if not ok:
                raise ValueError(f"{name} must be {allowed}, got {getattr(self, name)!r}")
        parse_train_channels(self.channel)
        distributed.check_device(self.device)


def lr_at(cfg: TrainConfig, elapsed_s: float, step: int = 0) -> float:
    """Linear warm-up over the first ``warmup_steps`` steps, constant, then cosine to lr/20
    over the last ``decay_fraction`` of the budget (of ``max_steps`` when set, else of
    ``max_minutes``)."""
    warm = min(1.0, (step + 1) / cfg.warmup_steps) if cfg.warmup_steps else 1.0
    return warm * _scheduled_lr(cfg, elapsed_s, step)


def _scheduled_lr(cfg: TrainConfig, elapsed_s: float, step: int) -> float:
    if cfg.max_steps:
        frac = min(step / cfg.max_steps, 1.0)
    else:
        frac = min(elapsed_s / (cfg.max_minutes * 60.0), 1.0)
    start = 1.0 - cfg.decay_fraction
    if frac <= start or cfg.decay_fraction == 0:
        return cfg.lr
    t = (frac - start) / cfg.decay_fraction
    return cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * t)))


def nearest_level(levels, cbr: float) -> float:
    """The value of ``levels`` nearest ``cbr``."""
    return float(min(levels, key=lambda v: abs(v - cbr)))


@torch.no_grad()
def validate(
    codec,
    images: torch.Tensor,
    channel: str,
    snrs_db=(1.0, 10.0),
    cbr: float = 1 / 16,
    seed: int = 1234,
) -> dict:
    """Mean PSNR (dB) on fixed images at a few SNRs, per training channel, at the codec's
    rate level nearest ``cbr`` (fixed noise seed).

    Args:
        codec: a :class:`semcodec.TrainableCodec`.
        images: [batch, 3, height, width] float32 in [0, 1] on the codec's device.
    Returns:
        ``{"psnr_<snr>db": float}`` (``"<channel>_psnr_<snr>db"`` for a mixture).
    """
    module = codec.module
    was_training = module.training
    module.eval()
    out = {}
    names = parse_train_channels(channel)
    b = images.shape[0]
    level = torch.full((b,), nearest_level(codec.rate_levels, cbr), device=images.device)
    for ch in names:
        g = torch.Generator(device=images.device).manual_seed(seed)
        for s in snrs_db:
            snr = torch.full((b,), float(s), device=images.device)
            y = codec.forward_train(images, snr, level, ch, g)
            mse = ((y - images) ** 2).mean(dim=(1, 2, 3))
            key = f"psnr_{s:g}db" if len(names) == 1 else f"{ch}_psnr_{s:g}db"
            out[key] = float((-10 * torch.log10(mse)).mean())
    module.train(was_training)
    return out


def build_codec(cfg: TrainConfig, init: Path | None = None):
    """A fresh :class:`semcodec.TrainableCodec` of ``cfg.codec`` / ``cfg.model``, weights drawn
    from ``torch.manual_seed(cfg.seed)`` (every rank the same), optionally started from the
    checkpoint ``init`` of the same codec (``cfg.codec = "NAME:CHECKPOINT"`` names one too). ValueError (one line) when the codec is not
    trainable."""
    name, checkpoint = parse_codec_spec(cfg.codec)
    init = init if init is not None else checkpoint
    base = make_codec(name)
    missing = missing_members(base, CODEC_MEMBERS + TRAINABLE_MEMBERS)
    if missing:
        raise ValueError(
            f"codec {name} cannot be trained here: it lacks {', '.join(missing)} "
            "(semcodec.TrainableCodec)"
        )
    if cfg.model is not None and cfg.model not in base.architectures:
        raise KeyError(
            f"unknown architecture {cfg.model!r} of codec {name}; known: "
            f"{', '.join(base.architectures)}"
        )
    torch.manual_seed(cfg.seed)
    codec = base.untrained(cfg.model)
    if init is not None:
        codec.load_compatible(make_codec(f"{name}:{init}"))
    return codec


def draw_batch(cfg: TrainConfig, images, levels, channels, step: int, rank: int, world: int):
    """Step ``step``'s global batch, drawn from ``default_rng([seed, step])``, and rank
    ``rank``'s share of it.

    Returns:
        (crops [batch_size / world, 3, crop_px, crop_px] float32, SNR [batch_size / world]
        float32 dB, CBR [batch_size / world] float32, channel name).
    """
    rng = np.random.default_rng([cfg.seed, step])
    b = cfg.batch_size
    x = random_crops(images, b, cfg.crop_px, rng)
    wide = rng.random(b) < cfg.p_wide_snr
    snr = np.where(
        wide,
        rng.uniform(cfg.snr_min_db, cfg.snr_max_db, b),
        rng.uniform(cfg.focus_snr_min_db, cfg.focus_snr_max_db, b),
    )
    k = len(levels)
    idx = np.where(rng.random(b) < cfg.p_focus_m, min(cfg.focus_m, k) - 1, rng.integers(0, k, b))
    channel = channels[int(rng.integers(len(channels)))] if len(channels) > 1 else channels[0]
    lo, hi = rank * b // world, (rank + 1) * b // world
    cbr = torch.tensor(np.asarray(levels)[idx], dtype=torch.float32)
    return x[lo:hi], torch.tensor(snr, dtype=torch.float32)[lo:hi], cbr[lo:hi], channel


def noise_generator(cfg: TrainConfig, step: int, rank: int, device) -> torch.Generator:
    """Rank ``rank``'s channel-noise generator at step ``step``: seeded by
    ``SeedSequence([seed, step, rank])``."""
    s = int(np.random.SeedSequence([cfg.seed, step, rank]).generate_state(1, np.uint64)[0])
    return torch.Generator(device=device).manual_seed(s & (2**63 - 1))


class _TrainForward(nn.Module):
    """The codec's ``forward_train`` as a module's forward, for DistributedDataParallel (its
    parameters are the codec's ``module``'s)."""

    def __init__(self, codec):
        super().__init__()
        self.net = codec.module
        self._codec = [codec]  # a list: not a submodule

    def forward(self, x, snr_db, cbr, channel, generator):
        return self._codec[0].forward_train(x, snr_db, cbr, channel, generator)


class _Run:
    """What :func:`train` carries between steps: codec, optimiser, counters, files."""

    def __init__(self, cfg, codec, place, out_dir, card):
        self.cfg, self.codec, self.place, self.out_dir, self.card = cfg, codec, place, out_dir, card
        self.opt = torch.optim.Adam(codec.module.parameters(), lr=cfg.lr)
        self.step, self.elapsed, self.best = 0, 0.0, -math.inf
        self.state_path = out_dir / "last_state.pt"

    def resume(self) -> None:
        """Continue from ``last_state.pt`` (written at any world size)."""
        st = load_train_state(self.state_path)
        try:
            self.codec.module.load_state_dict(st["model"])
        except RuntimeError:  # another architecture: one line, not torch's key-by-key dump
            raise ValueError(
                f"{self.state_path} was trained with {st['config'].get('codec', 'jscc')} "
                f"architecture {st['config'].get('model')!r}, not {self.cfg.model!r}: resume it "
                "with that architecture or train into a new folder"
            ) from None
        if st["config"] != dataclasses.asdict(self.cfg) | {
            "max_minutes": st["config"].get("max_minutes"),
            "max_steps": st["config"].get("max_steps", 0),
        }:
            if self.place.rank == 0:
                print("train-codec: resuming with a changed config", file=sys.stderr)
        self.opt.load_state_dict(st["optimizer"])
        self.step, self.elapsed, self.best = st["step"], st["elapsed_s"], st["best"]
        if self.place.rank == 0:
            print(
                f"train-codec: resumed at step {self.step}, {self.elapsed / 60:.1f} min "
                f"(written by {st.get('world_size', 1)} process(es), now {self.place.world_size})",
                file=sys.stderr,
            )

    def checkpoint(self, best_now: bool, metrics: dict | None = None) -> None:
        """Rank 0: ``last.safetensors`` (and ``best.safetensors``), then ``last_state.pt``."""
        if self.place.rank != 0:
            return
        c = {**self.card}
        c["training"] = {**c["training"], "steps": self.step, "minutes": self.elapsed / 60}
        if metrics:
            c["metrics"] = {"validation": metrics}
        self.codec.save(self.out_dir / "last.safetensors", c)
        if best_now:
            self.codec.save(self.out_dir / "best.safetensors", c)
        state = {
            "config": dataclasses.asdict(self.cfg),
            "model": self.codec.module.state_dict(),
            "optimizer": self.opt.state_dict(),
            "step": self.step,
            "elapsed_s": self.elapsed,
            "best": self.best,
            "world_size": self.place.world_size,
        }
        write_torch(self.state_path, state)

    def done(self) -> bool:
        cfg = self.cfg
        return self.elapsed >= cfg.max_minutes * 60.0 or 0 < cfg.max_steps <= self.step


def train_step(run: _Run, forward, data) -> tuple[float, float] | None:
    """One optimiser step on rank's share of the global batch; returns the global mean
    (loss, PSNR) or None when the loss is not finite anywhere (the step is skipped)."""
    cfg, place = run.cfg, run.place
    levels, channels, images = data
    x, snr, cbr, channel = draw_batch(
        cfg, images, levels, channels, run.step, place.rank, place.world_size
    )
    dev = place.device
    x, snr, cbr = x.to(dev), snr.to(dev), cbr.to(dev)
    for group in run.opt.param_groups:
        group["lr"] = lr_at(cfg, run.elapsed, run.step)
    y = forward(x, snr, cbr, channel, noise_generator(cfg, run.step, place.rank, dev))
    mse_per = ((y - x) ** 2).mean(dim=(1, 2, 3))
    loss = mse_per.mean()
    psnr = float((-10 * torch.log10(mse_per.detach())).mean())
    total, total_psnr = distributed.all_reduce([float(loss.detach()), psnr], "sum", place)
    run.opt.zero_grad(set_to_none=True)
    if not math.isfinite(total):
        return None
    loss.backward()  # DDP averages the gradients over the ranks here
    torch.nn.utils.clip_grad_norm_(run.codec.module.parameters(), 1.0)
    run.opt.step()
    run.step += 1
    return total / place.world_size, total_psnr / place.world_size


def train(
    cfg: TrainConfig,
    train_dirs: list[Path],
    out_dir: Path,
    val_dir: Path | None = None,
    resume: bool = True,
    card_extra: dict | None = None,
    init: Path | None = None,
) -> dict:
    """Train ``cfg.codec`` until ``max_minutes`` of training time (or ``max_steps``) are spent.

    Alone or under ``torchrun`` (see the module docstring). Rank 0 writes
    ``out_dir/last.safetensors``, ``best.safetensors`` (by mean validation PSNR),
    ``last_state.pt`` (weights, optimizer, counters) and ``log.jsonl``. Returns a summary dict.
    """
    place = distributed.setup(cfg.device, cfg.ddp_backend)
    if cfg.batch_size % place.world_size:
        raise ValueError(
            f"batch_size must be a multiple of the world size {place.world_size}, got {cfg.batch_size}"
        )
    torch.set_num_threads(cfg.num_threads)
    images, paths, data_hash, val = load_data(cfg.crop_px, train_dirs, val_dir)
    codec = build_codec(cfg, init)
    codec.module.to(place.device).train()
    card = {
        **(card_extra or {}),
        "training": {
            "config": dataclasses.asdict(cfg),
            "data": [str(d) for d in train_dirs],
            "num_images": len(paths),
            "data_sha256": data_hash,
            "world_size": place.world_size,
        },
    }
    if place.rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
    run = _Run(cfg, codec, place, out_dir, card)
    if resume and run.state_path.exists():
        run.resume()
    val = val.to(place.device) if val is not None else None
    forward = _TrainForward(codec)
    if place.distributed:
        from torch.nn.parallel import DistributedDataParallel

        ids = [place.device.index] if place.device.type == "cuda" else None
        forward = DistributedDataParallel(forward, device_ids=ids)
    data = (codec.rate_levels, parse_train_channels(cfg.channel), images)
    metrics = _loop(run, forward, data, val)
    return {
        "steps": run.step,
        "minutes": run.elapsed / 60,
        "validation": metrics,
        "out_dir": str(out_dir),
    }


def _loop(run: _Run, forward, data, val) -> dict:
    """Steps until the budget is spent; logs every 50 steps, validates and saves (rank 0)."""
    from tqdm import tqdm

    cfg, place = run.cfg, run.place
    lead = place.rank == 0
    log = open(run.out_dir / "log.jsonl", "a") if lead else None
    budget = cfg.max_minutes * 60.0
    bar = tqdm(
        total=int(budget),
        initial=int(run.elapsed),
        unit="s",
        desc="train-codec",
        file=sys.stderr,
        disable=not lead,
    )
    last_save = last_eval = run.elapsed
    acc = [0.0, 0.0, 0]
    while not run.done():
        t0 = time.perf_counter()
        out = train_step(run, forward, data)
        (dt,) = distributed.all_reduce([time.perf_counter() - t0], "max", place)
        run.elapsed += dt
        if out is None:
            if lead:
                print(
                    f"train-codec: non-finite loss at step {run.step}, batch skipped",
                    file=sys.stderr,
                )
            continue
        acc = [acc[0] + out[0], acc[1] + out[1], acc[2] + 1]
        bar.update(int(run.elapsed) - bar.n)
        if run.step % 50 == 0:
            rec = {
                "step": run.step,
                "elapsed_s": round(run.elapsed, 1),
                "lr": lr_at(cfg, run.elapsed, run.step),
                "loss": acc[0] / acc[2],
                "train_psnr": acc[1] / acc[2],
                "crops_per_s": cfg.batch_size / dt,
            }
            bar.set_postfix(psnr=f"{acc[1] / acc[2]:.2f}")
            acc = [0.0, 0.0, 0]
            if val is not None and (run.elapsed - last_eval >= cfg.eval_every_s or run.done()):
                rec.update(_validate_and_save(run, val))
                last_eval = last_save = run.elapsed
            if lead:
                log.write(json.dumps(rec) + "\n")
                log.flush()
        if run.elapsed - last_save >= cfg.save_every_s:
            run.checkpoint(False)
            last_save = run.elapsed
    metrics = _validate_and_save(run, val, final=True)
    bar.close()
    if lead:
        log.close()
    return metrics


def _validate_and_save(run: _Run, val, final: bool = False) -> dict:
    """Rank 0: validate, track the best score and write the checkpoints; {} elsewhere."""
    if run.place.rank != 0:
        return {}
    metrics = validate(run.codec, val, run.cfg.channel) if val is not None else {}
    score = float(np.mean(list(metrics.values()))) if metrics else -math.inf
    is_best = score > run.best or (final and not (run.out_dir / "best.safetensors").exists())
    run.best = max(run.best, score)
    run.checkpoint(is_best, metrics)
    return metrics


STATE_KEYS = ("config", "model", "optimizer", "step", "elapsed_s", "best")


def load_train_state(path: Path) -> dict:
    """Read ``last_state.pt`` (what :func:`train` resumes from).

    Raises:
        ValueError: naming the file when it is corrupt, truncated or not a training state.
    """
    try:
        st = torch.load(path, weights_only=False, map_location="cpu")
    except Exception as e:  # noqa: BLE001 - torch/pickle raise many kinds for a bad file
        first = (str(e).strip().splitlines() or [type(e).__name__])[0][:120]
        raise ValueError(
            f"{path}: cannot resume from it, corrupt or truncated ({type(e).__name__}: {first})"
        ) from None
    missing = [k for k in STATE_KEYS if not isinstance(st, dict) or k not in st]
    if missing:
        raise ValueError(f"{path}: cannot resume from it, not a training state (no {missing[0]!r})")
    return st
