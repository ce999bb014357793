"""Rate by channel truncation, what semcodec's learned codecs share: the encoder's output
holds importance-ordered complex channels per 4x4 block, and keeping the first ``m`` gives
CBR ``m/48`` (the encoder downsamples by 4: 48 real values per position). A requested CBR
is served by the nearest such m; ``Encoded.meta.cbr`` is the CBR actually used."""

from __future__ import annotations

import math
from pathlib import Path

from torch import Tensor
from torch.nn import functional as F

from semcodec.contract.checkpoint import KnowledgeBaseMismatch


def pad4(x: Tensor) -> Tensor:
    """Replicate-pad height and width up to multiples of 4. [b, c, H, W] -> [b, c, H4, W4]."""
    h, w = x.shape[-2:]
    ph, pw = (-h) % 4, (-w) % 4
    return F.pad(x, (0, pw, 0, ph), mode="replicate") if ph or pw else x


class ChannelTruncationCodec:
    """What semcodec's codecs share: a network whose encoder output holds
    ``num_complex_channels`` importance-ordered complex channels per 4x4 block (CBR m/48 for
    the first m), loaded with its model card and hash."""

    def __init__(self, model, card: dict, path: Path | None = None):
        self.model = model.eval()
        self.card = card
        self.path = path
        self.sha256: str = card["sha256"]
        self.trained = path is not None
        """The contract's optional ``trained``: False for freshly initialised weights (no
        checkpoint file; :func:`semcodec.contract.protocol.is_trained`)."""

    @property
    def name(self) -> str:
        return self.card.get("name", self.model.cfg.name)

    @property
    def module(self):
        """The network (every trained parameter)."""
        return self.model

    @property
    def cbr_range(self) -> tuple[float, float]:
        """(smallest, largest) CBR: (1/48, num_complex_channels/48)."""
        return self.model.cfg.cbr_range

    @property
    def snr_range_db(self) -> tuple[float, float]:
        """SNR range (Es/N0, dB) the model was trained for."""
        return (self.model.cfg.snr_min_db, self.model.cfg.snr_max_db)

    @property
    def rate_levels(self) -> tuple[float, ...]:
        """CBRs m/48 for m = 1 .. num_complex_channels."""
        c = self.model.cfg.num_complex_channels
        return tuple(k * self.model.cfg.cbr_per_channel for k in range(1, c + 1))

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(name={self.name!r}, sha256={self.sha256[:12]}, "
            f"cbr_range={self.cbr_range}, snr_range_db={self.snr_range_db})"
        )

    def check_knowledge_base(self, expected_sha256: str | None, meta_sha256: str | None) -> None:
        """Raise :class:`KnowledgeBaseMismatch` unless both hashes (where given) are ours."""
        for label, sha in (
            ("expected_sha256", expected_sha256),
            ("meta.codec_sha256", meta_sha256),
        ):
            if sha is not None and sha != self.sha256:
                raise KnowledgeBaseMismatch(
                    f"knowledge base mismatch: transmitter codec {str(sha)[:12]} ({label}) != "
                    f"receiver codec {self.sha256[:12]}; load the same checkpoint on both ends"
                )

    def channels_for_cbr(self, cbr: float) -> int:
        """Kept complex channels m for a CBR (nearest multiple of 1/48); ValueError outside the
        range."""
        lo, hi = self.cbr_range
        try:
            c = float(cbr)
        except (TypeError, ValueError):
            raise ValueError(f"cbr must be a number in [{lo:.4g}, {hi:.4g}], got {cbr!r}") from None
        if not math.isfinite(c) or not lo * 0.999 <= c <= hi * 1.001:
            raise ValueError(
                f"cbr must be in the codec's range [1/48, {round(hi * 48)}/48] = [{lo:.4g}, "
                f"{hi:.4g}], got {cbr!r}"
            )
        return int(
            min(
                max(round(c / self.model.cfg.cbr_per_channel), 1),
                self.model.cfg.num_complex_channels,
            )
        )
