"""Training-time pieces of semcodec's own JSCC: the differentiable link and warm starts.

:class:`semcodec.jscc.Codec` exposes them as its :class:`semcodec.TrainableCodec` methods.
"""

from __future__ import annotations

import dataclasses

import torch

from semcodec.jscc.channels import masked_transmit
from semcodec.jscc.model import JSCCModel, side_info


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
