"""What a training run is told (:class:`TrainConfig`) and the learning-rate schedule it
implies (:func:`lr_at`): wall-clock driven, the learning rate follows the fraction of
``max_minutes`` spent (or of ``max_steps`` when set), so a run stopped and resumed continues
on the same schedule."""

from __future__ import annotations

import math
from dataclasses import dataclass

from semcodec.jscc.channels import parse_train_channels
from semcodec.training import distributed


@dataclass(frozen=True)
class TrainConfig:
    """One training run.

    Attributes:
        codec: the codec to train, a name in ``semcodec.CODECS`` (a :class:`TrainableCodec`),
            or ``NAME:CHECKPOINT`` to start from that checkpoint's weights (as ``init``).
        model: the codec's architecture, one of its ``architectures`` (None: the codec's
            first, its default; :func:`semcodec.training.loop.with_architecture` fills it in).
        channel: training channel in ``semcodec.training.TRAIN_CHANNELS``, or a comma-separated
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
    model: str | None = None
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
