"""One training run of a stretch: ``python -m campaign.worker SPEC.json`` (or
:func:`train_one` in-process). Writes ``OUT/result.json`` beside the run's checkpoints."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from campaign.store import card_of
from semcodec import TrainConfig, train


def train_one(spec: dict) -> dict:
    """Train ``spec["config"]`` (a :class:`semcodec.TrainConfig`'s fields) from ``spec["init"]``
    into a fresh ``spec["out"]``; returns ``{"out", "lr", "sha256", "wall_s", "summary"}``."""
    import torch

    cfg = TrainConfig(**spec["config"])
    out = Path(spec["out"])
    for name in ("last_state.pt", "best.safetensors", "last.safetensors", "log.jsonl"):
        (out / name).unlink(missing_ok=True)  # a new run, never a resume
    t0 = time.perf_counter()
    threads = torch.get_num_threads()
    try:
        summary = train(
            cfg,
            [Path(d) for d in spec["data"]],
            out,
            val_dir=Path(spec["val"]),
            resume=False,
            card_extra=spec["card"],
            init=Path(spec["init"]) if spec["init"] else None,
        )
    finally:
        torch.set_num_threads(threads)  # train sets them for its process; a caller keeps its own
    result = {
        "out": str(out),
        "lr": cfg.lr,
        "sha256": card_of(out / "best.safetensors")["sha256"],
        "wall_s": time.perf_counter() - t0,
        "summary": summary,
    }
    (out / "result.json").write_text(json.dumps(result))
    return result


def main(argv: list[str]) -> int:
    spec = json.loads(Path(argv[0]).read_text())
    train_one(spec)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
