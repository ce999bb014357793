"""The digital baseline: bytes -> CRC -> 5G LDPC -> scrambling -> QAM -> link -> back.

Every block is sionna.phy's: ``CRCEncoder/CRCDecoder("CRC24B")`` per codeword,
``LDPC5GEncoder/LDPC5GDecoder`` (rate matching and the 38.212 bit interleaver for the
modulation order), ``TB5GScrambler`` over the whole block (so zero padding still gives
random-looking symbols of mean power ~1), ``Mapper/Demapper("app", "qam")`` with the
link's per-symbol ``noise_var``. See :mod:`phy.digital.layout` for the codeword sizes.

Below the LDPC code's mother rate 1/5 (which sionna's encoder does not go under) a
codeword is the rate-1/5 mother codeword repeated cyclically to its length
(:func:`rate_match`), and the receiver adds the LLRs of every copy of a bit before decoding
(:func:`combine_repeats`, chase combining): ``r`` copies of a bit at Es/N0 ``s`` give the
LLR of one copy at ``r * s``.

Decoding: belief propagation ("boxplus-phi", flooding) for at most ``num_iter`` iterations
(default 20, sionna's default). Codewords stop early once their CRC checks, tested after
2, 4, 6, 8, 12, 16, 20, ... iterations, so at a comfortable SNR most codewords cost 2-4
iterations; resuming from the decoder state makes this identical to one long run.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from phy.digital.layout import (
    CRC_POLY,
    CodewordLayout,
    codeword_layout,
    min_num_symbols,
    mother_bits,
)
from phy.digital.mcs import MCS, get_mcs

DEFAULT_NUM_ITER = 20


@dataclass
class DigitalResult:
    """What the receiver of the digital chain got.

    Attributes:
        payload: the decoded bytes when every codeword holding payload bits passed its CRC,
            else ``None``.
        ok: True when ``payload`` is not None.
        num_codewords: codewords in the block.
        failed_codewords: indices (in transmission order) of codewords whose CRC failed,
            including pure-padding codewords (those do not make ``ok`` False).
        num_symbols: channel symbols the block used.
        raw_payload: the hard-decided payload bytes even where CRCs failed (for analysis).
        num_payload_codewords: codewords that hold at least one payload bit (the first ones).
    """

    payload: bytes | None
    ok: bool
    num_codewords: int
    failed_codewords: list[int]
    num_symbols: int
    raw_payload: bytes = b""
    num_payload_codewords: int = 0
    extra: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- sionna blocks
@functools.lru_cache(maxsize=64)
def _code(k: int, n: int, bits_per_symbol: int | None, device: str):
    """CRC and LDPC blocks of a codeword of ``k`` information bits and ``n`` distinct coded
    bits (the mother codeword below rate 1/5, which has no output interleaver: its repeats
    are what the rate matcher sends)."""
    from sionna.phy.fec.crc import CRCDecoder, CRCEncoder
    from sionna.phy.fec.ldpc import LDPC5GDecoder, LDPC5GEncoder

    crc_enc = CRCEncoder(CRC_POLY, k=k - 24, device=device)
    crc_dec = CRCDecoder(crc_enc, device=device)
    enc = LDPC5GEncoder(k, n, num_bits_per_symbol=bits_per_symbol, device=device)
    dec = LDPC5GDecoder(enc, hard_out=True, return_infobits=True, return_state=True, device=device)
    return crc_enc, crc_dec, enc, dec


@functools.lru_cache(maxsize=8)
def _modem(bits_per_symbol: int, device: str):
    from sionna.phy.fec.scrambling import Descrambler, TB5GScrambler
    from sionna.phy.mapping import Demapper, Mapper

    mapper = Mapper("qam", bits_per_symbol, device=device)
    demapper = Demapper("app", "qam", bits_per_symbol, device=device)
    scrambler = TB5GScrambler(binary=True, device=device)
    descrambler = Descrambler(scrambler, binary=False, device=device)
    return mapper, demapper, scrambler, descrambler


def codeword_code(k: int, coded_bits: int, bits_per_symbol: int, device: str = "cpu"):
    """(CRC encoder, CRC decoder, LDPC encoder, LDPC decoder) of a codeword of ``k``
    information bits (CRC included) sent in ``coded_bits`` bits; the LDPC blocks work on the
    :func:`phy.digital.layout.mother_bits` distinct bits."""
    n = mother_bits(k, coded_bits)
    return _code(k, n, bits_per_symbol if n == coded_bits else None, device)


def rate_match(coded: Tensor, coded_bits: int) -> Tensor:
    """[count, n] distinct coded bits -> [count, coded_bits]: the bits repeated cyclically
    (unchanged when ``coded_bits == n``)."""
    n = coded.shape[-1]
    if n == coded_bits:
        return coded
    return coded[..., torch.arange(coded_bits) % n]


def combine_repeats(llr: Tensor, n: int) -> Tensor:
    """[count, coded_bits] LLRs -> [count, n]: each distinct bit's copies added up (the
    inverse of :func:`rate_match`; exact for independent noise on the copies)."""
    e = llr.shape[-1]
    if n == e:
        return llr
    out = torch.zeros(*llr.shape[:-1], n, dtype=llr.dtype, device=llr.device)
    return out.index_add_(-1, torch.arange(e, device=llr.device) % n, llr)


# ----------------------------------------------------------------------------- checks
def _check_payload(payload) -> bytes:
    if not isinstance(payload, bytes | bytearray | memoryview):
        raise ValueError(f"payload must be bytes, got {type(payload).__name__}")
    payload = bytes(payload)
    if not payload:
        raise ValueError("payload must hold at least 1 byte, got b''")
    return payload


def _check_num_iter(num_iter) -> int:
    if isinstance(num_iter, bool) or not isinstance(num_iter, int) or not 1 <= num_iter <= 200:
        raise ValueError(f"num_iter must be an integer in [1, 200], got {num_iter!r}")
    return num_iter


def _as_symbols(x_hat) -> Tensor:
    x = torch.as_tensor(x_hat)
    if not x.is_complex():
        raise ValueError(f"x_hat must be [num_symbols] complex64, got dtype {x.dtype}")
    if x.dim() == 2 and x.shape[0] == 1:
        x = x[0]
    if x.dim() != 1 or x.numel() == 0:
        raise ValueError(f"x_hat must be [num_symbols] complex64, got shape {tuple(x.shape)}")
    return x.to(torch.complex64)


def _as_noise_var(noise_var, num_symbols: int, device) -> Tensor:
    nv = torch.as_tensor(noise_var, device=device)
    if nv.is_complex() or nv.dtype == torch.bool:
        raise ValueError(f"noise_var must be a float or [num_symbols] float32, got {nv.dtype}")
    nv = nv.to(torch.float32)
    if nv.dim() == 2 and nv.shape[0] == 1:
        nv = nv[0]
    if nv.dim() > 1 or (nv.dim() == 1 and nv.numel() not in (1, num_symbols)):
        raise ValueError(
            f"noise_var must be a float or [num_symbols={num_symbols}] float32, "
            f"got shape {tuple(nv.shape)}"
        )
    if not bool(torch.isfinite(nv).all()) or bool((nv < 0).any()):
        raise ValueError("noise_var must be finite and >= 0")
    return nv.expand(num_symbols)


# ----------------------------------------------------------------------------- encode
def encode_bytes(payload: bytes, mcs: str | MCS, num_symbols: int | None = None) -> Tensor:
    """Channel symbols carrying ``payload`` at ``mcs``.

    Args:
        payload: the bytes (at least one).
        mcs: a name of :data:`MCS_TABLE` or an :class:`MCS`.
        num_symbols: block length; default the fewest that hold the payload
            (:func:`min_num_symbols`). Must satisfy
            ``len(payload) * 8 <= payload_capacity_bits(num_symbols, mcs)``.
    Returns:
        [num_symbols] complex64, unit-energy QAM (mean |x|^2 ~ 1, scrambled).
    """
    payload = _check_payload(payload)
    m = get_mcs(mcs)
    if num_symbols is None:
        num_symbols = min_num_symbols(len(payload), m)
    layout = codeword_layout(num_symbols, m)
    bits_needed = 8 * len(payload)
    if bits_needed > layout.capacity_bits:
        raise ValueError(
            f"payload of {len(payload)} bytes does not fit num_symbols={num_symbols} at mcs "
            f"{m.name!r}: at most {layout.capacity_bits // 8} bytes"
        )
    device = "cpu"
    bits = np.zeros(layout.capacity_bits, dtype=np.float32)
    bits[:bits_needed] = np.unpackbits(np.frombuffer(payload, dtype=np.uint8))
    bits_t = torch.from_numpy(bits)
    coded, offset = [], 0
    for _, count, k, e in layout.groups():
        crc_enc, _, enc, _ = codeword_code(k, e, m.bits_per_symbol, device)
        u = bits_t[offset : offset + count * (k - 24)].reshape(count, k - 24)
        offset += count * (k - 24)
        coded.append(rate_match(enc(crc_enc(u)), e).reshape(-1))  # [count * e]
    c = torch.cat(coded)[None]  # [1, num_symbols * bits_per_symbol]
    mapper, _, scrambler, _ = _modem(m.bits_per_symbol, device)
    return mapper(scrambler(c))[0].to(torch.complex64)


# ----------------------------------------------------------------------------- decode
def _checkpoints(num_iter: int) -> list[int]:
    """Iteration counts after which CRCs are checked: 2, 4, 6, 8, 12, 16, ..., num_iter."""
    points, it = [], 0
    while it < num_iter:
        it = min(num_iter, it + (2 if it < 8 else 4))
        points.append(it)
    return points


def _decode_group(llr: Tensor, k: int, e: int, bits_per_symbol: int, num_iter: int):
    """BP-decode ``llr`` [count, e] (codewords of ``e`` coded bits, repeats combined first)
    with CRC early stopping.

    Returns: (info bits [count, k - 24] float32, crc_ok [count] bool, iterations [count]).
    """
    _, crc_dec, enc, dec = codeword_code(k, e, bits_per_symbol, str(llr.device))
    llr = combine_repeats(llr, enc.n)
    count = llr.shape[0]
    info = torch.zeros(count, k - 24)
    ok = torch.zeros(count, dtype=torch.bool)
    iters = torch.full((count,), num_iter, dtype=torch.int32)
    active = torch.arange(count)
    state, done = None, 0
    for point in _checkpoints(num_iter):
        u_hat, state = dec(llr[active], num_iter=point - done, msg_v2c=state)
        done = point
        u, valid = crc_dec(u_hat)
        valid = valid.reshape(-1).bool()
        info[active] = u.to(info.dtype)
        ok[active] = valid
        iters[active[valid]] = point
        if bool(valid.all()):
            break
        active, state = active[~valid], state[~valid]
    return info, ok, iters


def decode_symbols(
    x_hat,
    noise_var,
    mcs: str | MCS,
    num_bytes: int,
    num_iter: int = DEFAULT_NUM_ITER,
) -> DigitalResult:
    """Recover ``num_bytes`` payload bytes from equalised symbols.

    Args:
        x_hat: [num_symbols] complex64 (or [1, num_symbols]) equalised symbols, the whole
            block that :func:`encode_bytes` emitted; unbiased (ZF-like) for 16/64-QAM.
        noise_var: float, or [num_symbols] float32 effective noise variance per symbol
            (what a link's ``LinkOutput.noise_var`` holds).
        mcs: the scheme the transmitter used.
        num_bytes: payload length the transmitter sent.
        num_iter: most BP iterations per codeword (early stop on CRC).
    Returns:
        :class:`DigitalResult`; ``extra["mean_iterations"]`` is the mean BP iterations used.
    """
    m = get_mcs(mcs)
    x = _as_symbols(x_hat)
    num_iter = _check_num_iter(num_iter)
    nv = _as_noise_var(noise_var, x.numel(), x.device)
    layout: CodewordLayout = codeword_layout(int(x.numel()), m)
    if isinstance(num_bytes, bool) or not isinstance(num_bytes, int) or num_bytes < 1:
        raise ValueError(f"num_bytes must be an integer >= 1, got {num_bytes!r}")
    if 8 * num_bytes > layout.capacity_bits:
        raise ValueError(
            f"num_bytes={num_bytes} exceeds what {x.numel()} symbols carry at mcs {m.name!r}: "
            f"at most {layout.capacity_bits // 8} bytes"
        )
    device = str(x.device)
    _, demapper, _, descrambler = _modem(m.bits_per_symbol, device)
    with torch.no_grad():
        llr = descrambler(demapper(x[None], nv[None]))[0]  # [num_symbols * bits_per_symbol]
        infos, oks, iters, offset = [], [], [], 0
        for _, count, k, n in layout.groups():
            block = llr[offset : offset + count * n].reshape(count, n)
            offset += count * n
            info, ok, it = _decode_group(block, k, n, m.bits_per_symbol, num_iter)
            infos.append(info.reshape(-1))
            oks.append(ok)
            iters.append(it)
    bits = torch.cat(infos)[: 8 * num_bytes].to(torch.uint8).numpy()
    raw = np.packbits(bits).tobytes()
    ok_all = torch.cat(oks)
    failed = torch.nonzero(~ok_all).reshape(-1).tolist()
    # codewords holding payload bits: the first ones, until 8 * num_bytes bits are covered
    num_payload_cw, covered = 0, 0
    for i in range(layout.num_codewords):
        if covered >= 8 * num_bytes:
            break
        covered += layout.payload_bits(i)
        num_payload_cw += 1
    ok = all(i >= num_payload_cw for i in failed)
    return DigitalResult(
        payload=raw if ok else None,
        ok=ok,
        num_codewords=layout.num_codewords,
        failed_codewords=failed,
        num_symbols=layout.num_symbols,
        raw_payload=raw,
        num_payload_codewords=num_payload_cw,
        extra={"mean_iterations": float(torch.cat(iters).float().mean())},
    )


def transmit_bytes(
    payload: bytes,
    mcs: str | MCS,
    link,
    snr_db,
    generator: torch.Generator | None = None,
    num_symbols: int | None = None,
    num_iter: int = DEFAULT_NUM_ITER,
) -> DigitalResult:
    """Send ``payload`` over ``link`` at ``mcs`` and decode it.

    Args:
        payload: bytes to send.
        mcs: name in :data:`MCS_TABLE` or an :class:`MCS`.
        link: ``link(x [1, num_symbols] complex64, snr_db, generator) -> LinkOutput`` with
            ``x_hat`` [1, num_symbols] complex64 and ``noise_var`` [1, num_symbols] float32
            (e.g. ``phy.FlatLink``, ``phy.OFDMLink``). For 16/64-QAM give the link a ZF
            equaliser: an MMSE output is scaled towards 0 by ``|h|^2 / (|h|^2 + N0)`` and the
            demapper assumes the unscaled constellation (QPSK LLRs come out exact either way).
        snr_db: Es/N0 per complex symbol in dB, passed to the link.
        generator: torch.Generator for the link's noise and fading.
        num_symbols: block length (default the fewest that hold the payload).
        num_iter: most BP iterations per codeword.
    Returns:
        :class:`DigitalResult`.
    """
    x = encode_bytes(payload, mcs, num_symbols)
    with torch.no_grad():
        out = link(x[None], snr_db, generator=generator)
    return decode_symbols(out.x_hat, out.noise_var, mcs, len(bytes(payload)), num_iter)
