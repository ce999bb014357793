"""What a training run carries between steps and writes to resume from
(:class:`TrainRun`: codec, optimiser, counters, checkpoints), and the reader of its
``last_state.pt`` (:func:`load_train_state`, written at any world size)."""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import torch

from common import write_torch


class TrainRun:
    """What :func:`semcodec.training.train` carries between steps: codec, optimiser, counters,
    files."""

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
