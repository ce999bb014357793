"""A semantic codec from outside semcodec, installed the way a package would be: its own
module (an orthonormal 4x4 block transform, not a subclass of anything of ours) on a tmp
``sys.path`` with ``semcodec.codecs`` entry points (``demo``, and two broken ones)."""

import sys
import textwrap

from semcodec import CODECS

PLUGIN = '''
"""A codec from outside semcodec: a fixed orthonormal 4x4 block transform (block means
first), the first 2 m coefficients sent as m complex symbols; LMMSE at the receiver."""
import math
from dataclasses import dataclass

import torch
from torch import nn


@dataclass(frozen=True)
class Meta:
    height: int
    width: int
    num_symbols: int
    cbr: float
    codec_sha256: str
    scale: torch.Tensor  # [batch] power normalisation, sent as side information

    def side_info_bits(self):
        return 32


class BlockTransform(nn.Module):
    def __init__(self, num_complex=8):
        super().__init__()
        g = torch.Generator().manual_seed(1)
        dc = torch.zeros(3, 48)
        for c in range(3):
            dc[c, c * 16 : (c + 1) * 16] = 0.25
        rest = torch.randn(48, 48, generator=g)
        q, _ = torch.linalg.qr(torch.cat([dc.T, rest], 1))
        basis = q.T[: 2 * num_complex] * torch.sign(q.T[: 2 * num_complex, :1] + 1e-9)
        basis[:3] = dc
        self.register_buffer("basis", basis)  # [2 * num_complex, 48]
        self.num_complex = num_complex


class DemoCodec:
    name = "demo"
    supports_focus = False
    snr_range_db = (-10.0, 30.0)

    def __init__(self, checkpoint=None):
        self.module = BlockTransform()
        self.cbr_range = (1 / 48, self.module.num_complex / 48)
        self.sha256 = "d" * 64 if checkpoint is None else "e" * 64

    def encode(self, images, snr_db, cbr, mask=None, demand_weights=None):
        from semcodec import Encoded
        b, _, h, w = images.shape
        m = max(1, min(self.module.num_complex, round(cbr * 48)))
        blocks = nn.functional.unfold(images * 2 - 1, 4, stride=4)  # [b, 48, positions]
        coef = self.module.basis[: 2 * m] @ blocks  # [b, 2m, positions]
        sym = torch.view_as_complex(coef.reshape(b, m, 2, -1).transpose(2, 3).contiguous())
        sym = sym.reshape(b, -1)
        scale = sym.abs().pow(2).mean(1).sqrt()
        sym = (sym / scale[:, None]).to(torch.complex64)
        n = sym.shape[1]
        return Encoded(sym, Meta(h, w, n, n / (3 * h * w), self.sha256, scale))

    def decode(self, x_hat, meta, snr_db, expected_sha256=None, noise_var=None):
        from semcodec import KnowledgeBaseMismatch
        if expected_sha256 not in (None, self.sha256) or meta.codec_sha256 != self.sha256:
            raise KnowledgeBaseMismatch(f"{expected_sha256} != {self.sha256}")
        b = x_hat.shape[0]
        if noise_var is None:
            noise_var = 10 ** (-torch.as_tensor(snr_db, dtype=torch.float32) / 10)
        nv = torch.as_tensor(noise_var, dtype=torch.float32)
        nv = nv.reshape(-1, 1) if nv.dim() <= 1 else nv
        z = x_hat / (1 + nv) * meta.scale[:, None]
        pos = (meta.height // 4) * (meta.width // 4)
        m = x_hat.shape[1] // pos
        coef = torch.view_as_real(z.reshape(b, m, pos)).transpose(2, 3).reshape(b, 2 * m, pos)
        blocks = self.module.basis[: 2 * m].T @ coef  # [b, 48, positions]
        y = nn.functional.fold(blocks, (meta.height, meta.width), 4, stride=4)
        return ((y + 1) / 2).clamp(0, 1)


def make(checkpoint=None):
    return DemoCodec(checkpoint)


def broken(checkpoint=None):
    raise RuntimeError("weights server unreachable")


def not_a_codec(checkpoint=None):
    return object()
'''


def install(tmp_path, monkeypatch) -> None:
    """Put ``semcodec_plugin_demo`` and its entry points on a tmp sys.path and load them."""
    site = tmp_path / "site"
    info = site / "semcodec_plugin_demo-0.1.dist-info"
    info.mkdir(parents=True)
    (site / "semcodec_plugin_demo.py").write_text(textwrap.dedent(PLUGIN))
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: semcodec-plugin-demo\nVersion: 0.1\n"
    )
    (info / "entry_points.txt").write_text(
        "[semcodec.codecs]\n"
        "demo = semcodec_plugin_demo:make\n"
        "demo_broken = semcodec_plugin_demo:broken\n"
        "demo_object = semcodec_plugin_demo:not_a_codec\n"
    )
    monkeypatch.syspath_prepend(str(site))
    CODECS.load_entry_points(force=True)


def uninstall(before: dict) -> None:
    for name in [n for n in CODECS if n not in before]:
        CODECS.unregister(name)
    sys.modules.pop("semcodec_plugin_demo", None)
