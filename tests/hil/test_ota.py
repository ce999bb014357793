"""Over-the-air plumbing around the frame layer: headers, PAPR scaling, threads, reassembly,
lost frames, SigMF annotations. A small single-carrier frame layer stands in for phy's here
(test double); the end-to-end runs with phy's frames are in test_ota_cli.py."""

from types import SimpleNamespace

import numpy as np
import pytest

from hil import AirChannel, Emulator, HackRF, OtaConfig, read_sigmf, save_sigmf, send_blocks
from hil.ota.burst import build_burst
from hil.ota.header import decode_header, header_mismatch, header_symbols
from hil.ota.receiver import ERASED_NOISE_VAR, assign_frames, receive_burst

PRE = np.exp(2j * np.pi * np.random.default_rng(99).integers(0, 4, 64) / 4).astype(np.complex64)


class ToyFrames:
    """Two copies of a 64-symbol QPSK preamble, then the symbols at 1 sample per symbol;
    one-tap LS channel from the preamble. Enough for an ideal-clock test link."""

    def __init__(self, drop=()):
        self.drop = set(drop)

    def build(self, symbols):
        return np.concatenate([PRE, PRE, symbols]).astype(np.complex64)

    def _metric(self, iq):
        c = np.abs(np.correlate(iq, PRE, "valid")) ** 2
        e = np.convolve(np.abs(iq) ** 2, np.ones(64), "valid")
        return c / (64 * e + 1e-12)

    def find(self, iq):
        m, starts, k = self._metric(iq), [], 0
        while k < len(m):
            if m[k] > 0.7:
                k = k + int(np.argmax(m[k : k + 8]))
                starts.append(k)
                k += 400  # past the second preamble copy, before the next frame
            else:
                k += 1
        return [s for i, s in enumerate(starts) if i not in self.drop]

    def receive(self, seg, n):
        k0 = int(np.argmax(self._metric(seg) > 0.7))
        h = np.vdot(PRE, seg[k0 : k0 + 64]) / 64
        nv_raw = np.mean(np.abs(seg[k0 : k0 + 128] - h * np.tile(PRE, 2)) ** 2)
        sym = seg[k0 + 128 : k0 + 128 + n] / h
        return SimpleNamespace(
            symbols=sym,
            noise_var=np.full(n, nv_raw / abs(h) ** 2, np.float32),
            start_index=k0,
            snr_db_estimate=10 * np.log10(abs(h) ** 2 / nv_raw),
            cfo_hz=0.0,
            detected=True,
        )


def qpsk(n, seed):
    return (np.exp(2j * np.pi * (np.random.default_rng(seed).integers(0, 4, n) + 0.5) / 4)).astype(
        np.complex64
    )


def pair(snr_db=20.0, seed=0):
    cfg = OtaConfig(
        sample_rate_hz=2e6, symbols_per_frame=256, gap_samples=300, rx_margin_samples=2000
    )
    emu = Emulator(
        AirChannel(snr_db=snr_db, reference_power_dbfs=cfg.tx_power_dbfs, delay_s=1e-6),
        ppm=(0.0, 0.0),
        seed=seed,
        wait_for_bursts=1,
    )
    tx = HackRF.open(emu.serials[0], backend=emu.backend)
    rx = HackRF.open(emu.serials[1], backend=emu.backend, rx_chunk_bytes=16384)
    return cfg, tx, rx


def test_header_round_trip_soft_combining_and_check():
    rng = np.random.default_rng(0)
    for n in (0, 1, 777, 4095):
        h = header_symbols(n, 4)
        assert h.shape == (64,) and decode_header(h, 4) == n
        noisy = h + (rng.standard_normal(64) + 1j * rng.standard_normal(64)) * 0.5  # 3 dB, 4 copies
        assert decode_header(noisy, 4) == n
    h = header_symbols(5, 1)
    h[0] = -h[0]  # one flipped bit: the check nibble catches it
    assert decode_header(h, 1) is None
    # weighting by 1/noise_var: a loud wrong copy on a faded carrier loses to two good ones
    h3 = header_symbols(9, 3)
    h3[:16] = -3 * h3[:16]
    nv = np.r_[np.full(16, 100.0), np.full(32, 1.0)]
    assert decode_header(h3, 3) != 9 and decode_header(h3, 3, nv) == 9
    with pytest.raises(ValueError, match="frame_number must be in"):
        header_symbols(4096, 4)


def test_frames_are_numbered_by_headers_and_layout_together_at_minus_10_db():
    """Headers at -10 dB per symbol (128 BPSK, about 2/3 of single decodes fail) but the
    burst layout is known: every detection is numbered right, a stray one is None."""
    rng = np.random.default_rng(3)
    positions = np.arange(12) * 5000.0 + 2000
    sent = [1, 2, 4, 5, 6, 9, 10, 11]  # frames 0, 3, 7, 8 were lost
    starts, headers, single = [], [], 0
    for i in sent:
        nv = np.full(128, 10.0)
        x = header_symbols(i, 8) + np.sqrt(5.0) * (
            rng.standard_normal(128) + 1j * rng.standard_normal(128)
        )
        headers.append((x, nv))
        starts.append(positions[i] + 777 + rng.integers(-1, 2))
        single += decode_header(x, 8, nv) == i
    assert single < len(sent)  # headers alone lose frames
    starts.append(positions[3] + 777 + 2500)  # between two frames
    headers.append((header_symbols(3, 8), np.ones(128)))
    got = assign_frames(np.array(starts), headers, positions, 8, tolerance=8)
    assert got == sent + [None]


def test_blocks_cross_the_emulated_air(tmp_path):
    cfg, tx, rx = pair(snr_db=20)
    blocks = [qpsk(600, 1), qpsk(256, 2)]
    with tx, rx:
        res = send_blocks(tx, rx, blocks, cfg, frames=ToyFrames())
    assert res.frames_sent == 4 and res.frames_lost == 0  # 600 -> 3 frames, 256 -> 1
    peak = max(np.abs(res.burst.real).max(), np.abs(res.burst.imag).max())
    assert peak <= 1.0

    def power_dbfs(f):  # TX samples of a frame: its RX start minus the 2-sample delay
        seg = res.burst[f.start_index - 2 : f.start_index - 2 + f.num_samples]
        return 10 * np.log10(np.mean(np.abs(seg) ** 2))

    full = [power_dbfs(res.frames[i]) for i in (0, 1, 3)]  # frame 2 is partly zero padding
    assert np.allclose(full, cfg.tx_power_dbfs, atol=0.1)
    assert power_dbfs(res.frames[2]) < cfg.tx_power_dbfs - 1
    for (x_hat, nv), x in zip(res.blocks, blocks):
        evm_db = 10 * np.log10(np.mean(np.abs(x_hat - x) ** 2))
        assert evm_db == pytest.approx(-20, abs=1.0)
        assert np.all(nv < 0.05)
    assert res.snr_db_measured() == pytest.approx(20, abs=1.0)
    meta_paths = save_sigmf(res, tmp_path / "ota", cfg)
    rec = read_sigmf(meta_paths[1])
    assert [a.label for a in rec.annotations] == ["frame 0", "frame 1", "frame 2", "frame 3"]
    assert rec.annotations[0].sample_start == res.frames[0].start_index
    assert rec.annotations[0].snr_db == pytest.approx(res.frames[0].snr_db, abs=1e-3)
    assert np.array_equal(rec.samples, res.capture)


def test_phy_frames_at_minus_10_db_and_the_capture_decodes_again_offline(tmp_path):
    """phy's frames through the emulated air at -10 dB per sample: every frame found, the
    symbols' error matches the reported noise variance; the RX SigMF file decoded again
    offline gives the same symbols."""
    from hil import decode_capture

    cfg, tx, rx = pair(snr_db=-10.0, seed=3)
    blocks = [qpsk(600, 1), qpsk(256, 2)]
    with tx, rx:
        res = send_blocks(tx, rx, blocks, cfg)
    assert res.frames_lost == 0
    for (x_hat, nv), x in zip(res.blocks, blocks):
        assert np.mean(np.abs(x_hat - x) ** 2) == pytest.approx(np.mean(nv), rel=0.3)
    rec = read_sigmf(save_sigmf(res, tmp_path / "ota", cfg)[1])
    again = decode_capture(rec.samples, [len(b) for b in blocks], cfg)
    assert again.frames_lost == 0
    for (a, na), (b, nb) in zip(again.blocks, res.blocks):
        np.testing.assert_allclose(a, b, atol=1e-4)
        np.testing.assert_allclose(na, nb, rtol=1e-4)


def test_lost_frame_is_an_erasure_not_a_crash():
    cfg, tx, rx = pair(snr_db=20)
    blocks = [qpsk(768, 3)]
    with tx, rx:
        res = send_blocks(tx, rx, blocks, cfg, frames=ToyFrames(drop={1}))
    assert res.frames_lost == 1 and [f.detected for f in res.frames] == [True, False, True]
    x_hat, nv = res.blocks[0]
    assert np.all(x_hat[256:512] == 0) and np.all(nv[256:512] == ERASED_NOISE_VAR)
    assert np.mean(np.abs(x_hat[:256] - blocks[0][:256]) ** 2) < 0.05


class TamperedHeader(ToyFrames):
    """ToyFrames that send frame ``victim`` with ``header`` instead of its own."""

    def __init__(self, victim, header):
        super().__init__()
        self.victim, self.header = victim, np.asarray(header, np.complex64)

    def build(self, symbols):
        s = np.array(symbols, np.complex64)
        n = len(self.header)
        if np.all(s[:n].imag == 0) and decode_header(s, n // 16) == self.victim:  # not the probe
            s[:n] = self.header
        return super().build(s)


@pytest.mark.parametrize("tamper", ["another frame's", "one bit flipped"])
def test_a_frame_whose_header_does_not_match_is_lost_with_the_reason(tamper):
    cfg = OtaConfig(
        sample_rate_hz=2e6, symbols_per_frame=256, gap_samples=300, rx_margin_samples=2000
    )
    r = cfg.header_repeat
    if tamper == "another frame's":
        header = header_symbols(5, r)
    else:
        header = header_symbols(1, r) * np.tile(np.where(np.arange(16) == 3, -1, 1), r)
    blocks = [qpsk(768, 3)]
    burst, reports, layout = build_burst(blocks, cfg, TamperedHeader(1, header))
    rng = np.random.default_rng(4)
    capture = np.concatenate([np.zeros(500, np.complex64), burst, np.zeros(500, np.complex64)])
    capture = capture + 0.003 * (
        rng.standard_normal(capture.size) + 1j * rng.standard_normal(capture.size)
    )
    ((x_hat, nv),) = receive_burst(
        capture.astype(np.complex64), reports, layout, [768], cfg, ToyFrames()
    )
    assert [f.detected for f in reports] == [True, False, True]
    assert [f.header_error is None for f in reports] == [True, False, True]
    why = reports[1].header_error
    assert "does not match frame 1" in why
    assert ("decodes as frame 5" if tamper == "another frame's" else "check nibble fails") in why
    assert np.all(x_hat[256:512] == 0) and np.all(nv[256:512] == ERASED_NOISE_VAR)
    assert np.mean(np.abs(x_hat[:256] - blocks[0][:256]) ** 2) < 0.05


def test_header_check_does_not_drop_frames_for_low_snr_alone():
    """At -10 dB per symbol most headers fail to decode on their own, yet hardly any bit
    lies 3 noise deviations against the frame's number; at 20 dB a swapped header does."""
    rng = np.random.default_rng(5)
    nv = np.full(128, 10.0)
    dropped = 0
    for i in range(2000):
        x = header_symbols(i, 8) + np.sqrt(5.0) * (
            rng.standard_normal(128) + 1j * rng.standard_normal(128)
        )
        dropped += header_mismatch(x, 8, i, nv) is not None
    assert dropped <= 3
    quiet = np.full(128, 0.01)
    assert header_mismatch(header_symbols(7, 8), 8, 7, quiet) is None
    assert "decodes as frame 6" in header_mismatch(header_symbols(6, 8), 8, 7, quiet)


def test_ota_config_validation():
    with pytest.raises(ValueError, match="symbols_per_frame must be"):
        OtaConfig(symbols_per_frame=10)
    with pytest.raises(ValueError, match="max_papr_db must be in"):
        OtaConfig(max_papr_db=1)


def test_a_board_gone_on_both_sides_raises_the_receive_error_with_its_capture():
    """When the transmitter and the receiver both fail (the board is gone), the receive
    error, which holds what arrived, is the one raised; alone, a transmit error is raised."""
    from hil.errors import DisconnectedError
    from hil.ota.link import transmit_and_capture

    class Rx:
        receiving = True

        def rx(self, n, max_shortfalls=None):
            e = DisconnectedError("receive: the board is gone")
            e.capture = np.ones(100, np.complex64)
            raise e

    class Tx:
        def tx(self, burst):
            raise DisconnectedError("transmit: the board is gone")

    with pytest.raises(DisconnectedError, match="receive") as err:
        transmit_and_capture(Tx(), Rx(), np.zeros(10, np.complex64), 10)
    assert len(err.value.capture) == 100 and "transmit" in str(err.value.__cause__)

    class RxFine:
        receiving = True

        def rx(self, n, max_shortfalls=None):
            return [np.zeros(n, np.complex64)]

    with pytest.raises(DisconnectedError, match="transmit"):
        transmit_and_capture(Tx(), RxFine(), np.zeros(10, np.complex64), 10)
