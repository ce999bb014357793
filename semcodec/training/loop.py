"""Training any registered codec through a channel: random crops, per-image SNR and rate.

The loop works on a :class:`semcodec.TrainableCodec` (``semcodec.CODECS`` name in
``TrainConfig.codec``): the codec's ``forward_train`` is the differentiable link, its
``module`` holds the parameters, its ``save`` writes the checkpoint.

Wall-clock driven: the learning rate follows the fraction of ``max_minutes`` spent (or of
``max_steps`` when set), so a run stopped and resumed (``last_state.pt``) continues on the
same schedule.

Scale: run under ``torchrun --nproc-per-node N`` and :func:`train` joins the process group
(:mod:`semcodec.training.distributed`), wraps the codec in DistributedDataParallel and gives rank r
the images ``[r * B / N, (r + 1) * B / N)`` of each global batch of ``B = batch_size``
crops. Only rank 0 writes files.

Random streams: :mod:`semcodec.training.batches` (a training state needs no RNG state).
The configuration and its learning-rate schedule: :mod:`semcodec.training.config`; the
state a run resumes from: :mod:`semcodec.training.state`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from semcodec.contract.protocol import CODEC_MEMBERS, TRAINABLE_MEMBERS, missing_members
from semcodec.contract.registry import make_codec, parse_codec_spec
from semcodec.jscc.channels import parse_train_channels, train_channel_records
from semcodec.jscc.model import make_model
from semcodec.jscc.train_link import forward_train, load_compatible
from semcodec.training import distributed
from semcodec.training.batches import draw_batch, noise_generator
from semcodec.training.config import TrainConfig, lr_at
from semcodec.training.data import files_sha256, list_images, load_data
from semcodec.training.state import TRAINING_FILES, TrainRun, load_train_state

__all__ = [
    "TrainConfig",
    "build_codec",
    "forward_train",
    "list_images",
    "load_compatible",
    "load_train_state",
    "make_model",
    "train",
    "train_inputs",
    "validate",
    "with_architecture",
]


def train_inputs(train_dirs: list[Path], init: Path | None, data_sha256: str | None = None):
    """What a training's weights depend on besides its config, as its state records them:
    ``{"data": sha256 of the training files, "init": the starting checkpoint or None}``
    (``data_sha256`` when already computed)."""
    if data_sha256 is None:
        data_sha256 = files_sha256([p for d in train_dirs for p in list_images(d, "--data")])
    return {
        "data": data_sha256,
        "data_dirs": [str(d) for d in train_dirs],
        "init": str(Path(init).resolve()) if init is not None else None,
    }


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


def _trainable(name: str):
    """The registry codec ``name``'s default instance; ValueError (one line) when it is not
    a :class:`semcodec.TrainableCodec`."""
    base = make_codec(name)
    missing = missing_members(base, CODEC_MEMBERS + TRAINABLE_MEMBERS)
    if missing:
        raise ValueError(
            f"codec {name} cannot be trained here: it lacks {', '.join(missing)} "
            "(semcodec.TrainableCodec)"
        )
    return base


def with_architecture(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with ``model`` named: None becomes the codec's first architecture (its
    default), so cards and training states record what was trained."""
    if cfg.model is not None:
        return cfg
    base = _trainable(parse_codec_spec(cfg.codec)[0])
    return dataclasses.replace(cfg, model=base.architectures[0])


def build_codec(cfg: TrainConfig, init: Path | None = None):
    """A fresh :class:`semcodec.TrainableCodec` of ``cfg.codec`` / ``cfg.model`` (None: the
    codec's first architecture), weights drawn from ``torch.manual_seed(cfg.seed)`` (every
    rank the same), optionally started from the checkpoint ``init`` of the same codec
    (``cfg.codec = "NAME:CHECKPOINT"`` names one too). ValueError (one line) when the codec
    is not trainable."""
    name, checkpoint = parse_codec_spec(cfg.codec)
    init = init if init is not None else checkpoint
    base = _trainable(name)
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


class _TrainForward(nn.Module):
    """The codec's ``forward_train`` as a module's forward, for DistributedDataParallel (its
    parameters are the codec's ``module``'s)."""

    def __init__(self, codec):
        super().__init__()
        self.net = codec.module
        self._codec = [codec]  # a list: not a submodule

    def forward(self, x, snr_db, cbr, channel, generator):
        return self._codec[0].forward_train(x, snr_db, cbr, channel, generator)


def train_step(run: TrainRun, forward, data) -> tuple[float, float] | None:
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
    ``last_state.pt`` (weights, optimizer, counters) and ``log.jsonl``. Returns a summary dict
    (``nothing_to_do``: a resumed training that had already finished; no file was written).

    A training in ``out_dir`` is resumed when ``resume`` (else started over, its files
    replaced); one that dies before its first checkpoint removes what it wrote.

    Raises:
        ResumeRefused: resuming would change more than ``RESUMABLE_FIELDS`` (nothing written).
    """
    place = distributed.setup(cfg.device, cfg.ddp_backend)
    if cfg.batch_size % place.world_size:
        raise ValueError(
            f"batch_size must be a multiple of the world size {place.world_size}, "
            f"got {cfg.batch_size}"
        )
    cfg = with_architecture(cfg)
    torch.set_num_threads(cfg.num_threads)
    images, paths, data_hash, val = load_data(cfg.crop_px, train_dirs, val_dir)
    codec = build_codec(cfg, init)
    codec.module.to(place.device).train()
    card = {
        **(card_extra or {}),
        "codec": parse_codec_spec(cfg.codec)[0],  # the registry name that loads the file
        "training": {
            "config": dataclasses.asdict(cfg),
            "channels": train_channel_records(cfg.channel),
            "data": [str(d) for d in train_dirs],
            "num_images": len(paths),
            "data_sha256": data_hash,
            "world_size": place.world_size,
        },
    }
    run = TrainRun(cfg, codec, place, out_dir, card, train_inputs(train_dirs, init, data_hash))
    resuming = resume and run.state_path.exists()
    if resuming:
        run.resume()  # ResumeRefused (nothing written) when it would change the training
    created = not out_dir.exists()
    if place.rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
        if not resuming:  # a fresh start replaces every file of an earlier training
            _remove_training_files(out_dir)
    summary = {"steps": run.step, "minutes": run.elapsed / 60, "out_dir": str(out_dir)}
    if resuming and run.done():
        if place.rank == 0:
            print(
                f"train-codec: {out_dir} has finished its training at step {run.step} "
                f"({run.elapsed / 60:.1f} min); nothing to do (give more max_steps or a later "
                "max_minutes to continue it)",
                file=sys.stderr,
            )
        return {**summary, "validation": None, "nothing_to_do": True}
    val = val.to(place.device) if val is not None else None
    forward = _TrainForward(codec)
    if place.distributed:
        from torch.nn.parallel import DistributedDataParallel

        ids = [place.device.index] if place.device.type == "cuda" else None
        forward = DistributedDataParallel(forward, device_ids=ids)
    data = (codec.rate_levels, parse_train_channels(cfg.channel), images)
    try:
        metrics = _loop(run, forward, data, val)
    except BaseException:
        if place.rank == 0 and not run.saved:  # died before its first checkpoint
            _remove_training_files(out_dir, rmdir=created)
        raise
    return {**summary, "steps": run.step, "minutes": run.elapsed / 60, "validation": metrics}


def _remove_training_files(out_dir: Path, rmdir: bool = False) -> None:
    """Remove the files a training writes (``TRAINING_FILES``), and the folder itself when
    ``rmdir`` and nothing else is left in it: nothing that would block a rerun."""
    for name in TRAINING_FILES:
        (out_dir / name).unlink(missing_ok=True)
    if rmdir and not any(out_dir.iterdir()):
        out_dir.rmdir()


LOG_EVERY_STEPS = 50
LOG_EVERY_S = 30.0
"""``log.jsonl`` gets a record every ``LOG_EVERY_STEPS`` steps or ``LOG_EVERY_S`` seconds of
training, whichever comes first, at every validation and at the end: a short or slow
training is logged as it goes too."""


def _loop(run: TrainRun, forward, data, val) -> dict:
    """Steps until the budget is spent; logs (:data:`LOG_EVERY_STEPS`), validates and saves
    (rank 0)."""
    from tqdm import tqdm

    lead = run.place.rank == 0
    done, total, unit = progress(run)
    # both are closed on the way out, by an error too: the bar never redraws after its line
    with (
        open(run.out_dir / "log.jsonl", "a") if lead else contextlib.nullcontext() as log,
        tqdm(
            total=total,
            initial=done,
            unit=unit,
            desc="train-codec",
            file=sys.stderr,
            disable=not lead,
        ) as bar,
    ):
        return _steps(run, forward, data, val, log, bar)


def progress(run: TrainRun) -> tuple[int, int, str]:
    """(done, total, unit) of the progress bar: steps when ``max_steps`` is the budget, else
    seconds of ``max_minutes``."""
    if run.cfg.max_steps:
        return run.step, run.cfg.max_steps, "step"
    return int(run.elapsed), int(run.cfg.max_minutes * 60.0), "s"


def _steps(run: TrainRun, forward, data, val, log, bar) -> dict:
    """The loop of :func:`_loop` (``log``: the open ``log.jsonl`` on rank 0, else None)."""
    cfg, place = run.cfg, run.place
    lead = place.rank == 0
    last_save = last_eval = last_log = run.elapsed
    acc = [0.0, 0.0, 0, 0.0]  # loss, PSNR, steps, seconds since the last record
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
        acc = [acc[0] + out[0], acc[1] + out[1], acc[2] + 1, acc[3] + dt]
        bar.update(progress(run)[0] - bar.n)
        evaluate = val is not None and run.elapsed - last_eval >= cfg.eval_every_s
        if evaluate or run.step % LOG_EVERY_STEPS == 0 or run.elapsed - last_log >= LOG_EVERY_S:
            rec = _record(run, acc)
            bar.set_postfix(psnr=f"{rec['train_psnr']:.2f}")
            acc, last_log = [0.0, 0.0, 0, 0.0], run.elapsed
            if evaluate and not run.done():  # the end is validated below
                rec.update(_validate_and_save(run, val))
                last_eval = last_save = run.elapsed
            _write(log, rec)
        if run.elapsed - last_save >= cfg.save_every_s:
            run.checkpoint(False)
            last_save = run.elapsed
    metrics = _validate_and_save(run, val, final=True)
    if acc[2] or metrics:
        _write(log, {**(_record(run, acc) if acc[2] else _record_head(run)), **metrics})
    return metrics


def _record(run: TrainRun, acc: list) -> dict:
    """One ``log.jsonl`` record: the mean loss and PSNR of the ``acc[2]`` steps since the
    last one (``acc``: summed loss, summed PSNR, steps, seconds)."""
    cfg = run.cfg
    return {
        **_record_head(run),
        "lr": lr_at(cfg, run.elapsed, run.step),
        "loss": acc[0] / acc[2],
        "train_psnr": acc[1] / acc[2],
        "crops_per_s": cfg.batch_size * acc[2] / max(acc[3], 1e-9),
    }


def _record_head(run: TrainRun) -> dict:
    return {"step": run.step, "elapsed_s": round(run.elapsed, 1)}


def _write(log, rec: dict) -> None:
    """Append ``rec`` to the open ``log.jsonl`` (None: not rank 0) and flush it."""
    if log is not None:
        log.write(json.dumps(rec) + "\n")
        log.flush()


def _validate_and_save(run: TrainRun, val, final: bool = False) -> dict:
    """Rank 0: validate, track the best score and write the checkpoints; {} elsewhere."""
    if run.place.rank != 0:
        return {}
    metrics = validate(run.codec, val, run.cfg.channel) if val is not None else {}
    score = float(np.mean(list(metrics.values()))) if metrics else -math.inf
    is_best = score > run.best or (final and not (run.out_dir / "best.safetensors").exists())
    run.best = max(run.best, score)
    run.checkpoint(is_best, metrics)
    return metrics
