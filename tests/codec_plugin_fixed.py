"""A second codec from outside semcodec, written only against docs/bring-your-own-codec.md and
``semcodec.SemanticCodec``: it takes 16x16 px images only (``input_size``), sends symbols in
multiples of 8 (``symbol_multiple``) and has no differentiable decode. Installed like
``tests/codec_plugin.py``: its own module on a tmp ``sys.path`` with a ``semcodec.codecs``
entry point (``fixed16``)."""

import sys
import textwrap

from semcodec import CODECS

PLUGIN = '''
"""A 16x16 px codec: each image averaged over 2x2 pixels, its 8x8 orthonormal DCT per colour,
the lowest frequencies first as complex symbols (8 at a time); LMMSE at the receiver."""
import math
from dataclasses import dataclass

import torch
from torch.nn import functional as F

SIDE = 16
GRID = SIDE // 2  # the pooled image's side
STEP = 8  # symbols per rate step


def _dct_matrix(n):
    k = torch.arange(n, dtype=torch.float32)
    d = torch.cos(math.pi * (2 * k[None, :] + 1) * k[:, None] / (2 * n)) * math.sqrt(2 / n)
    d[0] /= math.sqrt(2)
    return d  # [n, n] orthonormal


@dataclass(frozen=True)
class Meta:
    height: int
    width: int
    num_symbols: int
    cbr: float
    codec_sha256: str
    scale: torch.Tensor  # [batch] RMS of the sent coefficients (side information)

    def side_info_bits(self):
        return 16


class FixedCodec:
    name = "fixed16"
    supports_focus = False
    snr_range_db = (-10.0, 30.0)
    input_size = (SIDE, SIDE)
    symbol_multiple = STEP

    def __init__(self, checkpoint=None):
        total = 3 * GRID * GRID // 2  # complex symbols of every coefficient
        self.cbr_range = (STEP / (3 * SIDE * SIDE), total / (3 * SIDE * SIDE))
        self.sha256 = "f" * 64 if checkpoint is None else "a" * 64
        self.dct = _dct_matrix(GRID)
        u, v = torch.meshgrid(torch.arange(GRID), torch.arange(GRID), indexing="ij")
        order = sorted(range(GRID * GRID), key=lambda i: (int(u.flatten()[i] + v.flatten()[i]), i))
        self.order = torch.tensor([c * GRID * GRID + i for i in order for c in range(3)])

    def encode(self, images, snr_db, cbr, mask=None, demand_weights=None):
        from semcodec import Encoded

        b, _, h, w = images.shape
        if (h, w) != self.input_size:
            raise ValueError(f"images must be {SIDE}x{SIDE} px, got {h}x{w}")
        n = min(max(round(cbr * 3 * h * w) // STEP * STEP, STEP), self.order.numel() // 2)
        pooled = F.avg_pool2d(images - 0.5, 2)  # [b, 3, GRID, GRID]
        coef = (self.dct @ pooled @ self.dct.T).reshape(b, -1)[:, self.order[: 2 * n]]
        sym = torch.view_as_complex(coef.reshape(b, n, 2).contiguous())
        scale = sym.abs().pow(2).mean(1).sqrt().clamp_min(1e-6)
        sym = (sym / scale[:, None]).to(torch.complex64)
        return Encoded(sym, Meta(h, w, n, n / (3 * h * w), self.sha256, scale))

    def decode(self, x_hat, meta, snr_db, expected_sha256=None, noise_var=None):
        from semcodec import KnowledgeBaseMismatch

        if expected_sha256 not in (None, self.sha256) or meta.codec_sha256 != self.sha256:
            raise KnowledgeBaseMismatch(f"{expected_sha256} != {self.sha256}")
        b, n = x_hat.shape
        if noise_var is None:
            noise_var = 10 ** (-torch.as_tensor(snr_db, dtype=torch.float32) / 10)
        nv = torch.as_tensor(noise_var, dtype=torch.float32)
        nv = nv.reshape(-1, 1) if nv.dim() <= 1 else nv
        z = x_hat / (1 + nv) * meta.scale[:, None]  # LMMSE of unit-power symbols
        coef = torch.zeros(b, 3 * GRID * GRID)
        coef[:, self.order[: 2 * n]] = torch.view_as_real(z).reshape(b, 2 * n)
        pooled = self.dct.T @ coef.reshape(b, 3, GRID, GRID) @ self.dct
        y = F.interpolate(pooled, scale_factor=2, mode="nearest") + 0.5
        return y.clamp(0, 1)


def make(checkpoint=None):
    return FixedCodec(checkpoint)
'''


def install(tmp_path, monkeypatch) -> None:
    """Put ``semcodec_plugin_fixed`` and its entry point on a tmp sys.path and load it."""
    site = tmp_path / "site_fixed"
    info = site / "semcodec_plugin_fixed-0.1.dist-info"
    info.mkdir(parents=True)
    (site / "semcodec_plugin_fixed.py").write_text(textwrap.dedent(PLUGIN))
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: semcodec-plugin-fixed\nVersion: 0.1\n"
    )
    (info / "entry_points.txt").write_text(
        "[semcodec.codecs]\nfixed16 = semcodec_plugin_fixed:make\n"
    )
    monkeypatch.syspath_prepend(str(site))
    CODECS.load_entry_points(force=True)


def uninstall(before: dict) -> None:
    for name in [n for n in CODECS if n not in before]:
        CODECS.unregister(name)
    sys.modules.pop("semcodec_plugin_fixed", None)
