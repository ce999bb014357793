"""Training the JSCC through a channel: random crops of BSDS500, per-image SNR and rate.

Wall-clock driven: the learning rate follows the fraction of ``max_minutes`` spent, so a
run stopped and resumed (``last_state.pt``) continues on the same schedule.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from common import list_images, psnr, read_image, write_torch
from semcodec.channel_layers import masked_transmit, parse_train_channels
from semcodec.checkpoint import load_checkpoint, save_checkpoint
from semcodec.model import JSCCModel, make_model, side_info


@dataclass(frozen=True)
class TrainConfig:
    """One training run.

    Attributes:
        model: architecture name in ``semcodec.MODELS``.
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
        focus_m: complex channels kept with probability ``p_focus_m`` (3 -> CBR 1/16).
        p_focus_m: probability of ``focus_m``; otherwise m is uniform over 1..num_complex_channels.
        save_every_s: seconds between checkpoints.
        eval_every_s: seconds between validation runs.
        seed: seed of crops, SNRs, rates and noise.
        num_threads: torch CPU threads.
    """

    model: str = "adjscc_s4_w96"
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
    save_every_s: float = 180.0
    eval_every_s: float = 300.0
    seed: int = 0
    num_threads: int = 2

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
        ]
        for name, ok, allowed in checks:
            if not ok:
                raise ValueError(f"{name} must be {allowed}, got {getattr(self, name)!r}")
        parse_train_channels(self.channel)


def load_uint8_images(paths: list[Path]) -> list[torch.Tensor]:
    """RGB images (:func:`common.read_image`: 16-bit, palette, EXIF orientation) as
    [3, height, width] uint8 tensors."""
    return [
        torch.from_numpy(np.round(read_image(p) * 255.0).astype(np.uint8)).permute(2, 0, 1)
        for p in paths
    ]


def files_sha256(paths: list[Path]) -> str:
    """sha256 over the names and bytes of the training files (recorded in the model card)."""
    h = hashlib.sha256()
    for p in paths:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def random_crops(
    images: list[torch.Tensor], n: int, crop_px: int, rng: np.random.Generator
) -> torch.Tensor:
    """[n, 3, crop_px, crop_px] float32 in [0, 1]: random image, position and horizontal flip."""
    out = torch.empty(n, 3, crop_px, crop_px)
    for i in range(n):
        img = images[rng.integers(len(images))]
        _, h, w = img.shape
        y, x = rng.integers(h - crop_px + 1), rng.integers(w - crop_px + 1)
        c = img[:, y : y + crop_px, x : x + crop_px]
        if rng.random() < 0.5:
            c = c.flip(-1)
        if rng.random() < 0.5 and crop_px <= min(h, w):
            c = c.transpose(1, 2)
        out[i] = c.float() / 255.0
    return out


def lr_at(cfg: TrainConfig, elapsed_s: float) -> float:
    """Constant, then cosine to lr/20 over the last ``decay_fraction`` of the budget."""
    frac = min(elapsed_s / (cfg.max_minutes * 60.0), 1.0)
    start = 1.0 - cfg.decay_fraction
    if frac <= start or cfg.decay_fraction == 0:
        return cfg.lr
    t = (frac - start) / cfg.decay_fraction
    return cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * t)))


def forward_train(
    model: JSCCModel,
    x: torch.Tensor,
    snr_db: torch.Tensor,
    m: torch.Tensor,
    channel: str,
    generator: torch.Generator | None,
) -> torch.Tensor:
    """Encode, per-image masked power normalisation, channel, decode.

    Args:
        x: [batch, 3, H, W] float32; snr_db: [batch] float32; m: [batch] int64 kept channels.
    Returns:
        [batch, 3, H, W] reconstruction.
    """
    c = model.cfg.num_complex_channels
    side = side_info(snr_db, m, c, x.shape[0])
    feat = model.encoder(x, side)
    z, side_rx, rel = masked_transmit(feat, m, snr_db, channel, generator, c)
    return model.decoder(z, side_rx, rel)


@torch.no_grad()
def validate(
    model: JSCCModel,
    images: torch.Tensor,
    channel: str,
    snrs_db=(1.0, 10.0),
    m: int = 3,
    seed: int = 1234,
) -> dict:
    """Mean PSNR on fixed images at a few SNRs (fixed noise seed), per training channel."""
    model.eval()
    out = {}
    names = parse_train_channels(channel)
    for ch in names:
        g = torch.Generator().manual_seed(seed)
        for s in snrs_db:
            b = images.shape[0]
            y = forward_train(model, images, torch.full((b,), s), torch.full((b,), m), ch, g)
            key = f"psnr_{s:g}db" if len(names) == 1 else f"{ch}_psnr_{s:g}db"
            out[key] = float(np.mean([psnr(a, b) for a, b in zip(y, images)]))
    model.train()
    return out


def load_compatible(model: JSCCModel, init: JSCCModel) -> None:
    """Start ``model`` from ``init``'s weights where the architectures differ only in the
    decoder's reliability input (v1 -> v2) or in more complex channels (a wider rate range).

    The result decodes exactly as ``init`` does at every rate ``init`` serves:
    * new decoder input planes (reliability, channels beyond ``init``'s) start at zero;
    * the encoder's extra output channels start from the default init (they are dropped,
      and so leave the power normalisation alone, at ``m <= init``'s channels);
    * every AF module sees the rate as ``m / num_complex_channels``, so its weight on that
      input is scaled by the ratio of channel counts.

    Raises ValueError naming both architectures when anything else differs.
    """
    a, b = model.cfg, init.cfg
    same = dataclasses.replace(
        b,
        name=a.name,
        snr_min_db=a.snr_min_db,
        snr_max_db=a.snr_max_db,
        decoder_reliability=a.decoder_reliability,
        num_complex_channels=a.num_complex_channels,
    )
    if same != a or a.num_complex_channels < b.num_complex_channels:
        raise ValueError(f"init checkpoint architecture {b.name} does not fit model {a.name}")
    cn, co = a.num_complex_channels, b.num_complex_channels
    state = init.state_dict()
    own = model.state_dict()
    for k, v in own.items():
        src = state[k]
        if k.startswith("decoder.inp."):
            own[k] = (
                _map_decoder_input(src, v, co, cn, b.decoder_reliability)
                if v.dim() == 4
                else src.clone()
            )
        elif k.startswith("encoder.out."):
            new = v.clone()
            new[: src.shape[0]] = src
            own[k] = new
        elif k.endswith("af.fc1.weight"):
            new = src.clone()
            new[:, -1] *= cn / co
            own[k] = new
        else:
            own[k] = src.clone()
    model.load_state_dict(own)


def _map_decoder_input(
    src: torch.Tensor, dst: torch.Tensor, co: int, cn: int, rel: bool
) -> torch.Tensor:
    """The decoder's input conv [width, planes, k, k]: planes are the 2*C feature planes, then
    (with reliability) C reliability planes; copy ``init``'s into their place, zero the rest."""
    new = torch.zeros_like(dst)
    new[:, : 2 * co] = src[:, : 2 * co]
    if rel:
        new[:, 2 * cn : 2 * cn + co] = src[:, 2 * co : 3 * co]
    return new


STATE_KEYS = ("config", "model", "optimizer", "step", "elapsed_s", "best", "rng", "gen")


def load_train_state(path: Path) -> dict:
    """Read ``last_state.pt`` (what :func:`train` resumes from).

    Raises:
        ValueError: naming the file when it is corrupt, truncated or not a training state.
    """
    try:
        st = torch.load(path, weights_only=False)
    except Exception as e:  # noqa: BLE001 - torch/pickle raise many kinds for a bad file
        first = (str(e).strip().splitlines() or [type(e).__name__])[0][:120]
        raise ValueError(
            f"{path}: cannot resume from it, corrupt or truncated ({type(e).__name__}: {first})"
        ) from None
    missing = [k for k in STATE_KEYS if not isinstance(st, dict) or k not in st]
    if missing:
        raise ValueError(f"{path}: cannot resume from it, not a training state (no {missing[0]!r})")
    return st


def train(
    cfg: TrainConfig,
    train_dirs: list[Path],
    out_dir: Path,
    val_dir: Path | None = None,
    resume: bool = True,
    card_extra: dict | None = None,
    init: Path | None = None,
) -> dict:
    """Train until ``max_minutes`` of training time have been spent (resumable).

    Writes ``out_dir/last.safetensors``, ``best.safetensors`` (by mean validation PSNR),
    ``last_state.pt`` (optimizer, counters, RNGs) and ``log.jsonl``. Returns a summary dict.
    """
    from tqdm import tqdm

    torch.set_num_threads(cfg.num_threads)
    paths = [p for d in train_dirs for p in list_images(d, "--data")]
    images = load_uint8_images(paths)
    images = [im for im in images if min(im.shape[1:]) >= cfg.crop_px]
    if not images:
        raise ValueError(
            f"crop_px: no training image is at least {cfg.crop_px}x{cfg.crop_px} px "
            f"(of {len(paths)} images in {', '.join(str(d) for d in train_dirs)})"
        )
    data_hash = files_sha256(paths)
    val = None
    if val_dir is not None:
        vimgs = load_uint8_images(list_images(val_dir, "--val")[:8])
        if vimgs:
            side = min(256, min(min(im.shape[1:]) for im in vimgs) // 4 * 4)
            val = torch.stack([im[:, :side, :side].float() / 255 for im in vimgs])

    model = make_model(cfg.model)
    if init is not None:
        init_model = load_checkpoint(init)[0]
        load_compatible(model, init_model)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    rng = np.random.default_rng(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    step, elapsed, best = 0, 0.0, -math.inf
    state_path = out_dir / "last_state.pt"
    out_dir.mkdir(parents=True, exist_ok=True)
    if resume and state_path.exists():
        st = load_train_state(state_path)
        try:
            model.load_state_dict(st["model"])
        except RuntimeError:  # another architecture: one line, not torch's key-by-key dump
            raise ValueError(
                f"{state_path} was trained with architecture {st['config'].get('model')!r}, "
                f"not {cfg.model!r}: resume it with that architecture or train into a new folder"
            ) from None
        if st["config"] != dataclasses.asdict(cfg) | {"max_minutes": st["config"]["max_minutes"]}:
            print("train-codec: resuming with a changed config", file=sys.stderr)
        opt.load_state_dict(st["optimizer"])
        step, elapsed, best = st["step"], st["elapsed_s"], st["best"]
        rng.bit_generator.state = st["rng"]
        gen.set_state(st["gen"])
        print(f"train-codec: resumed at step {step}, {elapsed / 60:.1f} min", file=sys.stderr)

    card = {
        **(card_extra or {}),
        "training": {
            "config": dataclasses.asdict(cfg),
            "data": [str(d) for d in train_dirs],
            "num_images": len(paths),
            "data_sha256": data_hash,
        },
    }

    def checkpoint(best_now: bool, metrics: dict | None = None) -> None:
        c = {**card, "training": {**card["training"], "steps": step, "minutes": elapsed / 60}}
        if metrics:
            c["metrics"] = {"validation": metrics}
        save_checkpoint(out_dir / "last.safetensors", model, c)
        if best_now:
            save_checkpoint(out_dir / "best.safetensors", model, c)
        write_torch(
            state_path,
            {
                "config": dataclasses.asdict(cfg),
                "model": model.state_dict(),
                "optimizer": opt.state_dict(),
                "step": step,
                "elapsed_s": elapsed,
                "best": best,
                "rng": rng.bit_generator.state,
                "gen": gen.get_state(),
            },
        )

    budget = cfg.max_minutes * 60.0
    log = open(out_dir / "log.jsonl", "a")
    bar = tqdm(
        total=int(budget), initial=int(elapsed), unit="s", desc="train-codec", file=sys.stderr
    )
    last_save = last_eval = elapsed
    acc_loss, acc_psnr, acc_n = 0.0, 0.0, 0
    c = make_model(cfg.model).cfg.num_complex_channels
    channels = parse_train_channels(cfg.channel)
    model.train()
    while elapsed < budget:
        t0 = time.perf_counter()
        for group in opt.param_groups:
            group["lr"] = lr_at(cfg, elapsed)
        x = random_crops(images, cfg.batch_size, cfg.crop_px, rng)
        b = cfg.batch_size
        wide = rng.random(b) < cfg.p_wide_snr
        snr = np.where(
            wide,
            rng.uniform(cfg.snr_min_db, cfg.snr_max_db, b),
            rng.uniform(cfg.focus_snr_min_db, cfg.focus_snr_max_db, b),
        )
        m = np.where(rng.random(b) < cfg.p_focus_m, min(cfg.focus_m, c), rng.integers(1, c + 1, b))
        channel = channels[int(rng.integers(len(channels)))] if len(channels) > 1 else channels[0]
        y = forward_train(
            model, x, torch.tensor(snr, dtype=torch.float32), torch.tensor(m), channel, gen
        )
        mse_per = ((y - x) ** 2).mean(dim=(1, 2, 3))
        loss = mse_per.mean()
        opt.zero_grad(set_to_none=True)
        if not torch.isfinite(loss):
            print(f"train-codec: non-finite loss at step {step}, batch skipped", file=sys.stderr)
            elapsed += time.perf_counter() - t0
            continue
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        step += 1
        acc_loss += float(loss.detach())
        acc_psnr += float(np.mean([psnr(a, b) for a, b in zip(y, x)]))
        acc_n += 1
        dt = time.perf_counter() - t0
        elapsed += dt
        bar.update(int(elapsed) - bar.n)
        if step % 50 == 0:
            rec = {
                "step": step,
                "elapsed_s": round(elapsed, 1),
                "lr": lr_at(cfg, elapsed),
                "loss": acc_loss / acc_n,
                "train_psnr": acc_psnr / acc_n,
                "images_per_s": cfg.batch_size / dt,
            }
            bar.set_postfix(psnr=f"{acc_psnr / acc_n:.2f}")
            acc_loss, acc_psnr, acc_n = 0.0, 0.0, 0
            if val is not None and (elapsed - last_eval >= cfg.eval_every_s or elapsed >= budget):
                metrics = validate(model, val, cfg.channel)
                rec.update(metrics)
                last_eval = elapsed
                score = float(np.mean(list(metrics.values())))
                is_best = score > best
                best = max(best, score)
                checkpoint(is_best, metrics)
                last_save = elapsed
            log.write(json.dumps(rec) + "\n")
            log.flush()
        if elapsed - last_save >= cfg.save_every_s:
            checkpoint(False)
            last_save = elapsed
    metrics = validate(model, val, cfg.channel) if val is not None else {}
    score = float(np.mean(list(metrics.values()))) if metrics else -math.inf
    is_best = score > best or not (out_dir / "best.safetensors").exists()
    best = max(best, score)
    checkpoint(is_best, metrics)
    bar.close()
    log.close()
    return {"steps": step, "minutes": elapsed / 60, "validation": metrics, "out_dir": str(out_dir)}
