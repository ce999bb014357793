"""The knowledge base on disk: safetensors weights + a model card JSON, identified by a hash.

The hash (``sha256``) covers the architecture config and every tensor (name, dtype, shape,
bytes) in sorted order, not the card's metrics, so re-scoring a checkpoint keeps its
identity; transmitter and receiver compare it before decoding.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import torch
from safetensors import safe_open
from safetensors.torch import load_file, save

from common import InputError, write_bytes

CARD_KEY = "model_card"
JSCC_CODEC = "jscc"
"""Registry name of semcodec's own JSCC; cards without a ``codec`` field are of it."""
FORMAT_VERSIONS = ("1", "2")
"""Knowledge-base versions this code reads: 1 = the decoder sees LMMSE symbols and one SNR;
2 = it also sees each symbol's reliability (``JSCCConfig.decoder_reliability``)."""


class KnowledgeBaseMismatch(InputError):
    """The receiver's codec is not the one the transmitter used (hashes differ)."""


class _Unsupported(Exception):
    pass


def weights_sha256(state: dict[str, torch.Tensor], cfg) -> str:
    """sha256 hex of the architecture (a config with ``to_dict()``, or its dict) and the
    weights (names, dtypes, shapes, bytes)."""
    h = hashlib.sha256()
    arch = dict(cfg) if isinstance(cfg, dict) else cfg.to_dict()
    if arch.get("decoder_reliability") is False:  # version 1 architectures hash as they did
        del arch["decoder_reliability"]
    h.update(json.dumps(arch, sort_keys=True).encode())
    for name in sorted(state):
        t = state[name].detach().cpu().contiguous()
        h.update(f"{name}|{t.dtype}|{tuple(t.shape)}|".encode())
        h.update(t.view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    return h.hexdigest()


def save_checkpoint(
    path: str | os.PathLike, model, card: dict | None = None, codec: str | None = None
) -> str:
    """Write weights + card atomically; returns the sha256. The card gets the codec's
    registry name, the architecture and the hash.

    Args:
        path: ``*.safetensors`` target.
        model: the trained ``nn.Module`` with ``cfg`` (``to_dict()``, ``cbr_range``,
            ``snr_min_db``, ``snr_max_db``; ``decoder_reliability`` for the JSCC).
        card: extra model-card fields (training data, metrics, ...).
        codec: the name in ``semcodec.CODECS`` whose factory loads the file (None: the
            card's ``codec``, which the trainer fills in, else ``jscc``).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    sha = weights_sha256(state, model.cfg)
    full = {
        **(card or {}),
        "codec": codec or (card or {}).get("codec") or JSCC_CODEC,
        "format_version": "2" if getattr(model.cfg, "decoder_reliability", False) else "1",
        "architecture": model.cfg.to_dict(),
        "cbr_range": list(model.cfg.cbr_range),
        "snr_range_db": [model.cfg.snr_min_db, model.cfg.snr_max_db],
        "sha256": sha,
    }
    write_bytes(path, save(state, metadata={CARD_KEY: json.dumps(full, sort_keys=True)}))
    return sha


def check_checkpoint_file(path: str | os.PathLike) -> Path:
    """``path`` as a Path when it is a file; FileNotFoundError when missing, ValueError when
    it is a folder (each naming the path as what it is)."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"checkpoint {path} is a folder, not a checkpoint file")
    if not path.exists():
        raise FileNotFoundError(f"checkpoint not found: {path} (no such file)")
    return path


def read_card(path: str | os.PathLike) -> dict:
    """The model card of a checkpoint file (its safetensors metadata ``model_card``, a JSON
    object whose ``codec`` names the registry codec that loads it; absent: ``jscc``).

    Raises FileNotFoundError when missing, ValueError (one line) when ``path`` is a folder
    or a file without a readable card.
    """
    path = check_checkpoint_file(path)
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
        card = json.loads(meta[CARD_KEY])
        if not isinstance(card, dict):
            raise TypeError(CARD_KEY)
    except Exception as e:  # noqa: BLE001 - safetensors raises many kinds on garbage
        raise ValueError(
            f"checkpoint {path} is corrupt or not a codec checkpoint: no readable model card "
            f"({type(e).__name__})"
        ) from None
    return card


def read_checkpoint(path: str | os.PathLike, codec: str, config_type) -> tuple[dict, dict, object]:
    """Read a checkpoint of registry codec ``codec``; returns (state dict, card, config).

    The card's architecture becomes ``config_type(**architecture)`` and the stored hash is
    verified. Raises FileNotFoundError when missing, ValueError (one line) when corrupt or
    when the file holds another codec (naming both codecs and the file's architecture and
    hash).
    """
    path = check_checkpoint_file(path)
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
        card = json.loads(meta[CARD_KEY])
        held = str(card.get("codec", JSCC_CODEC))
        if held != codec:
            arch = (card.get("architecture") or {}).get("name", "?")
            raise _Unsupported(
                f"checkpoint {path} holds codec {held!r} (architecture {arch}, sha256 "
                f"{str(card.get('sha256'))[:12]}), not {codec!r}: load it as {held}:{path}"
            )
        version = str(card.get("format_version", "1"))
        if version not in FORMAT_VERSIONS:
            raise _Unsupported(
                f"checkpoint {path} is knowledge-base version {version}; this osnerf reads "
                f"versions {', '.join(FORMAT_VERSIONS)}: update osnerf or use a matching checkpoint"
            )
        cfg = config_type(**card["architecture"])
        state = load_file(str(path))
    except _Unsupported as e:
        raise ValueError(str(e)) from None
    except Exception as e:  # noqa: BLE001 - safetensors raises many kinds on garbage
        raise ValueError(
            f"checkpoint {path} is corrupt or not a {codec} checkpoint ({type(e).__name__})"
        ) from None
    sha = weights_sha256(state, cfg)
    if card.get("sha256") != sha:
        raise ValueError(
            f"checkpoint {path} is corrupt: weights hash {sha[:12]} != card "
            f"{str(card.get('sha256'))[:12]}"
        )
    return state, card, cfg
