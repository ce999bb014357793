"""What a training run carries between steps and writes to resume from
(:class:`TrainRun`: codec, optimiser, counters, checkpoints), the reader of its
``last_state.pt`` (:func:`load_train_state`, written at any world size), and what a resume
may change (:data:`RESUMABLE_FIELDS`, :func:`check_resume`).

A resume continues the same training: it may run longer (more ``max_steps``, a later
``max_minutes``), save and validate at other intervals, or run on other devices and world
sizes; each such change is kept as a history in the model card (``card["resumes"]``:
``[{"step": 300, "changed": {"max_steps": [300, 600]}}]``). Any other change (learning rate,
seed, batch, crops, channel, architecture, training data, init checkpoint) would make the
card describe a run that never happened: :class:`ResumeRefused`.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import torch

from common import write_torch

RESUMABLE_FIELDS = (
    "max_steps",
    "max_minutes",
    "save_every_s",
    "eval_every_s",
    "num_threads",
    "device",
    "ddp_backend",
)
"""The :class:`semcodec.TrainConfig` fields a resume may change (recorded in the card's
``resumes``): how long the run goes on, how often it saves and validates (which checkpoint
is ``best``), and where it runs. Every other field, and the inputs (``data``: the training
files' sha256; ``init``: the starting checkpoint), is the same run's or refused."""

TRAINING_FILES = (
    "last_state.pt",
    "last.safetensors",
    "best.safetensors",
    "log.jsonl",
    "summary.json",
)
"""What a training writes into its folder: replaced together when it starts over, removed
when it dies before its first checkpoint (nothing to resume from)."""


class ResumeRefused(ValueError):
    """A resume that would change what the training is (not only how long it runs).

    Attributes:
        changes: ``{field: [old, new]}`` of the fields that may not change (empty when a
            ``max_steps`` / ``max_minutes`` was refused for being already passed).
    """

    def __init__(self, message: str, changes: dict[str, list] | None = None):
        super().__init__(message)
        self.changes = dict(changes or {})


class TrainRun:
    """What :func:`semcodec.training.loop.train` carries between steps: codec, optimiser, counters,
    files."""

    def __init__(self, cfg, codec, place, out_dir, card, inputs: dict | None = None):
        self.cfg, self.codec, self.place, self.out_dir, self.card = cfg, codec, place, out_dir, card
        self.opt = torch.optim.Adam(codec.module.parameters(), lr=cfg.lr)
        self.step, self.elapsed, self.best = 0, 0.0, -math.inf
        self.state_path = out_dir / "last_state.pt"
        self.inputs = dict(inputs or {})  # {"data": sha256, "init": path or None}
        self.resumes: list[dict] = []  # what each resume changed, at which step
        self.saved = False  # a checkpoint of this run is on disk

    def resume(self) -> None:
        """Continue from ``last_state.pt`` (written at any world size).

        Raises:
            ResumeRefused: the state is of another training (:func:`check_resume`).
        """
        st = load_train_state(self.state_path)
        changed = check_resume(st, self.cfg, self.inputs, self.state_path)
        try:
            self.codec.module.load_state_dict(st["model"])
        except RuntimeError:  # another architecture: one line, not torch's key-by-key dump
            raise ValueError(
                f"{self.state_path} was trained with {st['config'].get('codec', 'jscc')} "
                f"architecture {st['config'].get('model')!r}, not {self.cfg.model!r}: resume it "
                "with that architecture or train into a new folder"
            ) from None
        self.opt.load_state_dict(st["optimizer"])
        self.step, self.elapsed, self.best = st["step"], st["elapsed_s"], st["best"]
        self.resumes = list(st.get("resumes", []))
        if changed:
            self.resumes.append({"step": self.step, "changed": changed})
        self.saved = True
        if self.place.rank == 0:
            what = f"; changed {describe_changes(changed)}" if changed else ""
            print(
                f"train-codec: resumed at step {self.step}, {self.elapsed / 60:.1f} min "
                f"(written by {st.get('world_size', 1)} process(es), now "
                f"{self.place.world_size}){what}",
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
        if self.resumes:
            c["resumes"] = self.resumes
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
            "inputs": self.inputs,
            "resumes": self.resumes,
        }
        write_torch(self.state_path, state)
        self.saved = True

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


def resume_changes(state: dict, cfg, inputs: dict) -> dict[str, list]:
    """``{field: [old, new]}`` for every config field and input that differs between a
    training state and this run (a field the state predates counts as its default; an input
    it did not record is not compared)."""
    defaults = {f.name: f.default for f in dataclasses.fields(cfg)}
    old = {**defaults, **state["config"]}
    changed = {k: [old.get(k), v] for k, v in dataclasses.asdict(cfg).items() if old.get(k) != v}
    recorded = state.get("inputs") or {}
    for k, v in inputs.items():
        if k in recorded and recorded[k] != v and k not in DESCRIBING_INPUTS:
            changed[k] = [recorded[k], v]
    if "data" in changed:  # the folders as typed, beside their files' hash
        was = recorded.get("data_dirs")
        changed["data"] = [
            f"{', '.join(was) if was else 'the earlier folders'} (sha256 "
            f"{_short(recorded['data'])})",
            f"{', '.join(inputs.get('data_dirs') or ['?'])} (sha256 {_short(inputs['data'])})",
        ]
    return changed


DESCRIBING_INPUTS = ("data_dirs",)
"""Inputs recorded to name a change, never compared themselves: the training folders as
typed (the same files under another path are the same training)."""


def check_resume(state: dict, cfg, inputs: dict, path: Path) -> dict[str, list]:
    """The changes a resume of ``state`` by ``cfg`` makes, all in :data:`RESUMABLE_FIELDS`.

    Raises:
        ResumeRefused: one line naming every other changed field (old -> new), or a
            ``max_steps`` / ``max_minutes`` that this training has already passed.
    """
    changed = resume_changes(state, cfg, inputs)
    fixed = {k: v for k, v in changed.items() if k not in RESUMABLE_FIELDS}
    if fixed:
        what = describe_changes(fixed)
        raise ResumeRefused(f"{path} is another training: resuming it would change {what}", fixed)
    step, elapsed = state["step"], state["elapsed_s"]
    if "max_steps" in changed and 0 < cfg.max_steps < step:
        raise ResumeRefused(
            f"max_steps {cfg.max_steps} is below the {step} steps already taken by {path}; "
            "give more steps to continue it"
        )
    if "max_minutes" in changed and cfg.max_minutes * 60.0 < elapsed:
        raise ResumeRefused(
            f"max_minutes {cfg.max_minutes:g} is below the {elapsed / 60:.2f} min already "
            f"trained by {path}; give a later deadline to continue it"
        )
    return changed


def _short(v) -> str:
    text = str(v)
    return text[:12] if len(text) == 64 else text  # a sha256: its first 12 hex digits


def describe_changes(changed: dict[str, list], names: dict[str, str] | None = None) -> str:
    """``lr (0.001 -> 0.002), seed (0 -> 1)``."""
    names = names or {}
    return ", ".join(
        f"{names.get(k, k)} ({_short(a)} -> {_short(b)})" for k, (a, b) in changed.items()
    )
