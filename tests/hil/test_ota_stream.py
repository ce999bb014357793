"""Streaming over the air: the ring buffer's exact drop counts, the paced emulated HackRF's
overruns and underruns, frame search in blocks with carry-over (each frame found exactly
once, whatever the block boundaries), and `osnerf ota --stream` end to end at 2 MS/s,
with a decoder that keeps up and one that does not."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import phy
from hil import EmulatedPluto, Emulator, HackRF, OtaConfig, build_views
from hil.emulation.pacing import StreamPacer
from hil.hackrf import protocol
from hil.ota import PhyFrames, RingBuffer, StreamReceiver, StreamView
from hil.ota.burst import build_burst
from hil.ota.header import MAX_FRAMES, decode_header
from osnerf.cli import main

CFG = OtaConfig(sample_rate_hz=2e6, symbols_per_frame=256, gap_samples=400)


# ----------------------------------------------------------------------------- ring buffer
def test_ring_drops_whole_blocks_and_counts_every_sample():
    ring = RingBuffer(1000)
    x = np.arange(3000, dtype=np.float32).astype(np.complex64)
    assert ring.push(x[:600]) and not ring.push(x[600:1100])  # 1100 > 1000: dropped whole
    assert ring.dropped_samples == 500 and ring.drop_events == 1
    assert not ring.push(x[1100:1300])  # still no room: the gap grows, one more event
    assert ring.gaps == [(600, 1300)] and ring.drop_events == 2
    np.testing.assert_array_equal(ring.read(0, 600), x[:600])
    ring.release(1300)
    assert ring.push(x[1300:2000])
    ring.release(1900)
    assert ring.push(x[2000:2250])  # slots 0..249: wraps around
    np.testing.assert_array_equal(ring.read(1900, 2250), x[1900:2250])
    assert ring.received_samples == 2250 and ring.dropped_samples == 700
    assert ring.next_gap(0) == (600, 1300) and ring.next_gap(1300) is None
    with pytest.raises(ValueError, match="not held"):
        ring.read(100, 200)  # released


# ----------------------------------------------------------------------------- pacing
class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_pacer_counts_an_overrun_exactly_when_the_host_reads_too_late(monkeypatch):
    clock = FakeClock()
    monkeypatch.setattr(time, "sleep", lambda s: setattr(clock, "now", clock.now + s))
    pacer = StreamPacer(1e6, start_sample=50, buffer_samples=1000, clock=clock)
    assert pacer.before_read(50, 500) == 50  # waits for the samples to be taken
    assert clock.now == pytest.approx(100.0005) and pacer.shortfalls == 0
    clock.now += 0.0008  # 800 samples behind: within the buffer
    assert pacer.before_read(550, 500) == 550 and pacer.shortfalls == 0
    clock.now = 100.0 + 0.004  # the board has taken 4000 samples, the host read 1000
    assert pacer.before_read(1050, 500) == 1050 + 2000  # the 2000 that did not fit are lost
    assert (pacer.shortfalls, pacer.lost_samples, pacer.longest_shortfall_bytes) == (1, 2000, 4000)


def test_pacer_charges_the_host_only_for_its_own_lateness_not_the_emulators(monkeypatch):
    """A transfer the emulator renders late moves the host's next request as late; a real
    board would have had it out at its due time, so the request counts from there."""
    clock = FakeClock()
    monkeypatch.setattr(time, "sleep", lambda s: setattr(clock, "now", clock.now + s))
    pacer = StreamPacer(1e6, start_sample=0, buffer_samples=1000, clock=clock)
    assert pacer.before_read(0, 500) == 0  # due at 100.0005
    clock.now += 0.003  # the emulator took 3 ms to render it
    pacer.after_read()
    assert pacer.late_s == pytest.approx(0.003)
    clock.now += 0.0001  # the host asks again at once: 2600 behind by the wall clock
    assert pacer.before_read(500, 500) == 500 and pacer.shortfalls == 0
    pacer.after_read()  # a real board: out at 100.001 (due); here at 100.0036
    assert pacer.late_s == pytest.approx(0.0026)
    clock.now += 0.004  # the host itself stalls 4 ms: charged from 100.005, not 100.0076
    assert pacer.before_read(1000, 500) == 1000 + 3000
    assert (pacer.shortfalls, pacer.lost_samples) == (1, 3000)
    assert pacer.longest_late_s == pytest.approx(0.003)


def test_a_stream_says_so_when_its_emulated_boards_fell_behind_real_time():
    from osnerf.commands.ota_stream import emulator_lag_warning

    assert emulator_lag_warning(None, 1.0) is None  # a real board, or a Pluto
    assert emulator_lag_warning(0.041, 1.0) is None  # a stall the ring absorbs
    warning = emulator_lag_warning(1.157, 1.0)
    assert warning is not None and "1.157 s later" in warning
    assert emulator_lag_warning(0.041, 0.2) is not None  # a fifth of a small ring


def test_pacer_counts_an_underrun_when_the_host_writes_too_late(monkeypatch):
    clock = FakeClock()
    monkeypatch.setattr(time, "sleep", lambda s: setattr(clock, "now", clock.now + s))
    pacer = StreamPacer(1e6, start_sample=0, buffer_samples=1000, clock=clock)
    assert pacer.before_write(0, 3000) == 0  # the first write starts the DAC
    assert clock.now == pytest.approx(100.002)  # back-pressure: 2000 over the buffer
    clock.now += 0.0015  # 3500 played out, 3000 written: 500 of silence
    assert pacer.before_write(3000, 100) == 500 and pacer.shortfalls == 1
    clock.now += 0.01
    assert pacer.before_write(3600, 100, silent=True) == 0  # a late flush is silence anyway
    assert pacer.shortfalls == 1


def test_pluto_dma_blocks_lose_whole_blocks_to_a_late_reader_counted_exactly():
    from hil.emulation.pacing import BlockQueue

    clock = FakeClock()
    q = BlockQueue(1e6, block_samples=1000, num_blocks=4, clock=clock)
    assert q.take() == 0  # the first block is still being filled: the reader waits for it
    clock.now += 0.0025  # blocks 0 and 1 are full: 1 waits for the reader
    assert q.take() == 1 and (q.lost_blocks, q.overruns) == (0, 0)
    clock.now = 100.0205  # 20 blocks taken; the reader holds 1, so blocks 2..4 fill the rest
    assert q.take() == 2
    assert (q.lost_blocks, q.overruns) == (20 - 5, 1)  # 5..19 had nowhere to go: lost whole
    assert [q.take(), q.take()] == [3, 4]  # the late reader gets the old ones first
    assert q.take() == 20 and q.lost_blocks == 15  # then the block being filled now


def test_a_late_reader_of_an_emulated_pluto_skips_the_lost_blocks_and_the_board_says_so():
    from hil.pluto.context import OVERRUN_ATTR, PHY, RX_DEV

    board = EmulatedPluto.for_link(30.0, seed=0)
    board.write_attr(PHY, "voltage0", False, "", "sampling_frequency", "2500000")
    board.open_rx(block_samples=2500, num_blocks=4)  # 1 ms blocks, as libiio opens a buffer
    start = board.rx_cursor
    assert len(board.read_rx(4000)) == 2 * 2500  # one block per refill, no more
    time.sleep(0.03)  # the reader is late by about 30 blocks: 4 fit (one of them its own)
    for _ in range(4):  # the three kept behind the reader's, then one after the lost ones
        assert len(board.read_rx(2500)) == 2 * 2500
    q = board.rx_blocks
    lost = q.lost_blocks * 2500
    assert q.overruns == 1 and q.lost_blocks >= 20  # whole blocks, at 1 ms each
    assert board.rx_cursor == start + 5 * 2500 + lost  # the lost blocks were skipped
    text = board.read_attr(RX_DEV, None, False, "DEBUG", OVERRUN_ATTR)
    assert text == f"{q.overruns} {q.lost_blocks} {lost}"


def test_emulated_hackrfs_in_their_own_process_pace_and_count_a_late_reader(monkeypatch):
    """The boards' process paces them and counts the samples a stalled host lost, and the
    host's driver reads the M0's overrun count across the process boundary."""
    from hil import EmulatorProcess
    from hil.hackrf.usb_transport import UsbTransport

    read, calls = UsbTransport.read, []

    def stalling_read(self, num_bytes, timeout_ms):  # the 12th read comes 0.5 s late
        calls.append(num_bytes)
        if len(calls) == 12:
            time.sleep(0.5)  # longer than the board's buffer lasts at 2 MS/s (0.27 s)
        return read(self, num_bytes, timeout_ms)

    with EmulatorProcess(ppm=(0.0, 0.0), paced=True) as emu:
        assert emu.process.pid != os.getpid()
        with HackRF.open(emu.serials[1], backend=emu.backend) as rx:
            rx.sample_rate_hz = 2e6
            t = time.monotonic()
            rx.rx(400_000)  # 0.2 s of air, in 2 transfers and the stale one
            assert time.monotonic() - t >= 0.2 and emu.radios[1].overrun_samples == 0
            monkeypatch.setattr(UsbTransport, "read", stalling_read)
            with pytest.warns(UserWarning, match="receive overruns"):
                rx.rx(3_000_000)
            stats = rx.last_stats
        lost = emu.radios[1].overrun_samples
    assert stats.device_shortfalls == 1 and 0.2 * 2e6 <= lost <= 0.5 * 2e6
    assert stats.longest_shortfall_bytes == 2 * lost  # one overrun, counted exactly


def test_a_transmitter_that_starts_while_the_receiver_streams_is_heard_after_the_silence():
    """A streaming receiver hears silence while there is no transmitter; a burst sent then
    goes on the air after what was heard, not at the start of the transmitter's timeline,
    which the receiver has already passed."""
    from types import SimpleNamespace

    from hil import AirChannel, Medium

    def radio(index):
        return SimpleNamespace(
            index=index,
            ppm=0.0,
            sample_rate_hz=4e6,
            center_freq_hz=2.4e9,
            rx_gain_db=40.0,
            tx_gain_db=30.0,
        )

    medium, tx, rx = Medium(AirChannel(snr_db=100), seed=0), radio(0), radio(1)
    silence = medium.render_iq(rx, 0, 40_000, lambda: True)  # no transmitter yet
    medium.start_tx(tx)
    medium.append_tx_iq(tx, np.full(1000, 0.5, np.complex64))
    medium.end_tx(tx)
    y = medium.render_iq(rx, 40_000, 40_000, lambda: True)
    power = np.abs(y) ** 2
    floor = np.mean(np.abs(silence) ** 2)
    assert np.mean(power[:1000]) > 1e6 * floor  # the burst, right after the silence
    assert np.mean(power[2000:]) < 10 * floor


def test_paced_emulated_hackrf_streams_at_its_rate_and_reports_overruns():
    """Receive and transmit take the air time they carry; a stalled host loses samples."""
    emu = Emulator(ppm=(0.0, 0.0), paced=True)
    with HackRF.open(emu.serials[1], backend=emu.backend) as rx:
        rx.sample_rate_hz = 2e6
        t = time.monotonic()
        rx.rx(400_000)  # 0.2 s of air
        assert time.monotonic() - t >= 0.2  # not faster than the sample rate
        assert rx.last_stats.clean and emu.radios[1].overrun_samples == 0
    with HackRF.open(emu.serials[0], backend=emu.backend) as tx:
        tx.sample_rate_hz = 2e6
        t = time.monotonic()
        tx.tx(np.zeros(200_000, np.complex64))  # 0.1 s of air; the M0 holds 8 ms of it
        assert time.monotonic() - t >= (200_000 - 16384) / 2e6
    board = emu.radios[1]
    board.control(protocol.OUT, protocol.SET_TRANSCEIVER_MODE, protocol.MODE_RECEIVE, 0, b"")
    board.bulk_read(1024)  # the stale buffer
    cursor = board.rx_cursor
    board.bulk_read(1024)
    time.sleep(0.4)  # the host stalls longer than the board's buffer lasts (0.27 s)
    board.bulk_read(1024)
    lost = board.overrun_samples
    assert lost > 0 and board.rx_cursor == cursor + 512 + lost + 512  # skipped exactly
    assert board.m0["shortfalls"] == 1 and board.m0["longest"] == 2 * lost


# ----------------------------------------------------------------------------- frame search
def test_burst_headers_number_on_from_first_number():
    frames = PhyFrames(sample_rate_hz=2e6)
    block = np.ones(3 * CFG.symbols_per_frame, np.complex64)
    burst, reports, _ = build_burst([block], CFG, frames, first_number=MAX_FRAMES - 1)
    assert [r.number for r in reports] == [0, 1, 2]
    for k, want in zip(frames.find(burst), (MAX_FRAMES - 1, 0, 1)):
        seg = burst[k - 100 : k + reports[0].num_samples + 100]
        res = frames.receive(seg, CFG.header_symbols + CFG.symbols_per_frame)
        assert decode_header(np.asarray(res.symbols).reshape(-1), CFG.header_repeat) == want


def _air(views, rng, pause=(700, 3000)):
    """The views' bursts one after another with pauses, through mild noise: [n] complex64."""
    parts = []
    for v in views:
        parts += [v.burst, np.zeros(int(rng.integers(*pause)), np.complex64)]
    x = np.concatenate(parts) * np.float32(0.3)
    noise = rng.standard_normal(2 * len(x)).astype(np.float32).view(np.complex64)
    return (x + np.float32(0.003) * noise).astype(np.complex64)


@pytest.mark.parametrize("block", [1500, 4999, 20000])
def test_each_frame_is_found_exactly_once_across_block_boundaries(block):
    rng = np.random.default_rng(block)
    sent = [
        np.exp(2j * np.pi * rng.integers(0, 4, n) / 4).astype(np.complex64)
        for n in (300, 700, 256, 520)
    ]
    views = build_views(sent, CFG)
    air = _air(views, rng)
    ring, handed = RingBuffer(len(air) + 1), []
    for k in range(0, len(air), block):  # the driver's blocks, cutting through frames
        ring.push(air[k : k + block])
    ring.close()
    counts = StreamReceiver(
        ring, views, CFG, PhyFrames(sample_rate_hz=2e6), handed.append, block
    ).run()
    frames_sent = sum(len(v.reports) for v in views)
    assert (counts.frames_found, counts.frames_decoded, counts.duplicates) == (
        frames_sent,
        frames_sent,
        0,
    )
    assert [v.index for v in handed] == [0, 1, 2, 3] and all(v.complete for v in handed)
    for v, x in zip(views, sent):
        assert np.mean(np.abs(v.x_hat - x) ** 2) < 0.05


def test_frame_numbers_carry_on_across_the_headers_12_bit_wrap():
    rng = np.random.default_rng(3)
    frames = PhyFrames(sample_rate_hz=2e6)
    sent = [
        np.exp(2j * np.pi * rng.integers(0, 4, 2 * 256) / 4).astype(np.complex64) for _ in range(2)
    ]
    views, number = [], MAX_FRAMES - 3  # headers 4093, 4094 | 4095, 0
    for v, block in enumerate(sent):
        burst, reports, layout = build_burst([block], CFG, frames, first_number=number % MAX_FRAMES)
        views.append(StreamView(v, number, reports, layout, len(block), burst))
        number += len(reports)
    ring, handed = RingBuffer(1 << 20), []
    ring.push(_air(views, rng))
    ring.close()
    counts = StreamReceiver(ring, views, CFG, frames, handed.append, 4000).run()
    assert (counts.frames_decoded, counts.header_errors) == (4, 0)
    assert [v.complete for v in handed] == [True, True]
    for v, x in zip(views, sent):
        assert np.mean(np.abs(v.x_hat - x) ** 2) < 0.05


def test_a_block_of_frames_is_decoded_by_one_receive_frames_call_with_the_per_frame_bits(
    monkeypatch,
):
    rng = np.random.default_rng(11)
    sent = [np.exp(2j * np.pi * (rng.integers(0, 4, 4 * 256) + 0.5) / 4).astype(np.complex64)]
    frames = PhyFrames(sample_rate_hz=2e6)
    views = build_views(sent, CFG, frames)
    air = _air(views, rng)
    n, pre = CFG.header_symbols + CFG.symbols_per_frame, CFG.gap_samples // 2
    want = []  # the per-frame path: a search, then each frame on its own segment
    for k in frames.find(air):
        res = frames.receive(air[max(0, k - pre) : k + views[0].reports[0].num_samples + pre], n)
        want.append(np.asarray(res.symbols).reshape(-1)[CFG.header_symbols :])
    calls = {"receive_frames": 0, "receive_frame": 0}
    for name in calls:
        real = getattr(phy, name)
        monkeypatch.setattr(
            phy,
            name,
            lambda *a, _f=real, _n=name, **k: calls.update({_n: calls[_n] + 1}) or _f(*a, **k),
        )
    ring, handed = RingBuffer(len(air)), []
    ring.push(air)
    ring.close()
    counts = StreamReceiver(ring, views, CFG, frames, handed.append, len(air)).run()
    assert calls == {"receive_frames": 1, "receive_frame": 0}
    assert (len(want), counts.frames_found, counts.frames_decoded) == (4, 4, 4)
    (view,) = handed
    for (_, offset, length), w in zip(view.layout, want):
        got = view.x_hat[offset : offset + length]
        assert np.array_equal(got.real > 0, w[:length].real > 0)
        assert np.array_equal(got.imag > 0, w[:length].imag > 0)
    assert np.array_equal(view.x_hat.real > 0, sent[0].real > 0)


def test_dropped_samples_lose_their_frames_and_nothing_joins_across_them():
    rng = np.random.default_rng(7)
    sent = [np.exp(2j * np.pi * rng.integers(0, 4, 256) / 4).astype(np.complex64) for _ in range(6)]
    views = build_views(sent, CFG)
    air = _air(views, rng, pause=(3000, 3001))
    block = 2000
    ring, handed = RingBuffer(len(air)), []
    span = len(views[0].burst) + 3000
    hole = range(2 * span // block + 1, 4 * span // block)  # views 2 and 3 fall in it
    for i, k in enumerate(range(0, len(air), block)):
        if i in hole:  # arrived while the ring was full
            ring.drop(len(air[k : k + block]))
        else:
            ring.push(air[k : k + block])
    ring.close()
    counts = StreamReceiver(
        ring, views, CFG, PhyFrames(sample_rate_hz=2e6), handed.append, block
    ).run()
    assert ring.dropped_samples == block * len(hole)
    assert [v.complete for v in handed] == [True, True, False, False, True, True]
    assert counts.frames_decoded == 4 and counts.duplicates == 0


# ----------------------------------------------------------------------------- the command
needs_phy = pytest.mark.skipif(
    not all(hasattr(phy, n) for n in ("FrameConfig", "build_frame", "find_frames")),
    reason="phy's frame API is not in this checkout",
)


@pytest.fixture(scope="module")
def images(tmp_path_factory, shared_data):
    from PIL import Image

    folder = tmp_path_factory.mktemp("stream_images")
    Image.open(sorted((shared_data / "kodak").glob("*.png"))[0]).save(folder / "kodim01.png")
    return folder


def stream(tmp_path, images, *extra):
    out = tmp_path / "stream.json"
    argv = ["ota", "--stream", "--tx", "emulated", "--rx", "emulated", "--schemes", "jscc"]
    argv += ["--snr-db", "10", "--images", str(images), "--out", str(out), "--size", "48"]
    argv += ["--max-images", "1", "--symbols-per-frame", "1024", "--sample-rate-hz", "2e6"]
    rc = main([*argv, *extra])
    return rc, (json.loads(out.read_text()) if out.exists() else None)


@needs_phy
def test_stream_at_10_db_drops_nothing_and_reports_latency_per_view(tmp_path, images):
    rc, d = stream(tmp_path, images, "--views", "5", "--view-interval-s", "0.1")
    assert rc == 0
    s = d["stream"]
    assert d["config"]["stream"] is True and d["config"]["views"] == 5
    assert s["dropped_samples"] == 0 and s["overruns"] == 0 and s["device_overruns"] == 0
    assert s["emulator_overrun_samples"] == 0 and s["samples_received"] >= 0.4 * 2e6  # 4 intervals
    assert s["samples_received"] == s["driver_samples"]
    assert s["samples_received"] - 2 * 2e6 * 0.01 <= s["samples_searched"] <= s["samples_received"]
    assert s["receiver_realtime_factor"] > 1 and s["receiver_cpu_s"] > 0  # 2 MS/s: far ahead
    assert s["emulator_late_max_s"] >= 0
    assert s["frames_found"] == s["frames_decoded"] == s["frames_sent"] == 5
    assert s["frames_lost"] == 0 and s["views_complete"] == 5
    for row in s["views"]:  # a view is out no sooner than its air time after it went in
        assert row["air_s"] < row["latency_s"] < 5.0
    assert [r["psnr"] > 20 for r in d["results"]] == [True] * 5
    assert set(d) >= {"config", "seed", "git_commit", "versions", "codec"}


@needs_phy
def test_a_decoder_that_falls_behind_drops_samples_and_says_so(
    tmp_path, images, monkeypatch, capsys
):
    receive_all = PhyFrames.receive_all

    def slow_receive_all(self, iq, num_symbols):  # a decoder far slower than the air
        time.sleep(0.4)
        return receive_all(self, iq, num_symbols)

    monkeypatch.setattr(PhyFrames, "receive_all", slow_receive_all)
    rc, d = stream(tmp_path, images, "--views", "6", "--view-interval-s", "0.05", "--ring-s", "0.1")
    assert rc == 1  # the result is written, and the run fails
    s = d["stream"]
    assert s["ring_dropped_samples"] > 0 and s["ring_drop_events"] > 0
    assert s["dropped_samples"] >= s["ring_dropped_samples"] and s["overruns"] >= 1
    assert s["frames_lost"] == s["frames_sent"] - s["frames_decoded"] > 0
    err = capsys.readouterr().err
    assert "the stream lost" in err and f"ring {s['ring_dropped_samples']}" in err


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--views", "3"], "--views applies to --stream only"),
        (["--stream", "--tx", "loopback", "--rx", "loopback"], "--stream needs radios that stream"),
        (["--stream", "--schemes", "digital,jscc"], "--stream sends one scheme"),
        (["--stream", "--ring-s", "0"], "--ring-s: must be a number in [0.01, 60] s"),
        (["--stream", "--emulator-cpus", "4096"], "--emulator-cpus: must be CPU numbers"),
        (
            ["--stream", "--emulator-cpus", "0", "--tx", "pluto", "--rx", "pluto"],
            "needs --tx/--rx emulated",
        ),
    ],
)
def test_bad_stream_flags_exit_2_and_create_nothing(tmp_path, images, capsys, extra, message):
    out = tmp_path / "o.json"
    argv = ["ota", "--schemes", "jscc", "--images", str(images), "--out", str(out), *extra]
    assert main(argv) == 2
    assert message in capsys.readouterr().err and not out.exists()
    assert not (tmp_path / "o_sigmf").exists()


@needs_phy
def test_a_stalled_usb_reader_overruns_the_board_and_the_run_says_so(
    tmp_path, images, monkeypatch, capsys
):
    from hil.hackrf.usb_transport import UsbTransport

    read, calls = UsbTransport.read, []

    def stalling_read(self, num_bytes, timeout_ms):  # a host too busy to read for 0.5 s
        calls.append(num_bytes)
        if len(calls) == 4:
            time.sleep(0.5)  # longer than the board's buffer lasts at 2 MS/s (0.27 s)
        return read(self, num_bytes, timeout_ms)

    monkeypatch.setattr(UsbTransport, "read", stalling_read)
    rc, d = stream(tmp_path, images, "--views", "6", "--view-interval-s", "0.1")
    s = d["stream"]
    assert rc == 1 and s["device_overruns"] >= 1 and s["emulator_overrun_samples"] > 0
    assert s["dropped_samples"] == s["emulator_overrun_samples"] and s["ring_dropped_samples"] == 0
    # the stall outlasted the buffer by about 0.23 s: that much was lost at once
    longest = s["device_longest_overrun_bytes"]
    assert 2 * 0.2 * 2e6 <= longest <= 2 * s["emulator_overrun_samples"]
    err = capsys.readouterr().err
    assert "receive overruns" in err and "the stream lost" in err


def pluto_process(port: int) -> subprocess.Popen:
    """``osnerf hil emulate pluto`` in its own process (this checkout's code), as a board
    is: its rendering does not compete with the decoder."""
    root = Path(__file__).resolve().parents[2]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
    }
    code = "import sys; from osnerf.cli import main; sys.exit(main(sys.argv[1:]))"
    argv = ["hil", "emulate", "pluto", "--address", "127.0.0.9", "--port", str(port)]
    emu = subprocess.Popen(
        [sys.executable, "-c", code, *argv], stderr=subprocess.PIPE, text=True, env=env
    )
    assert "osnerf hil emulate: pluto at" in emu.stderr.readline()
    return emu


def pluto_stream(tmp_path, images, *extra):
    pytest.importorskip("adi", reason="pyadi-iio (and libiio0) are not installed")
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.9", 0))
        port = s.getsockname()[1]
    emu = pluto_process(port)
    try:
        out = tmp_path / "pluto.json"
        argv = [
            "ota",
            "--stream",
            "--tx",
            "pluto",
            "--rx",
            "pluto",
            "--uri",
            f"ip:127.0.0.9:{port}",
        ]
        argv += ["--schemes", "jscc", "--snr-db", "10", "--images", str(images), "--out"]
        argv += [str(out), "--size", "48", "--max-images", "1", "--symbols-per-frame", "1024"]
        argv += ["--sample-rate-hz", "4e6", *extra]
        rc = main(argv)
    finally:
        emu.terminate()
        emu.wait(10)
    return rc, json.loads(out.read_text())["stream"]


@needs_phy
def test_stream_over_an_emulated_pluto_at_4_msps(tmp_path, images):
    rc, s = pluto_stream(tmp_path, images, "--views", "4", "--view-interval-s", "0.2")
    assert rc == 0
    assert s["dropped_samples"] == 0 and s["device_overruns"] == -1  # libiio 0.x: unknown
    assert (s["emulator_overruns"], s["emulator_lost_buffers"]) == (0, 0)  # the board's own
    assert s["frames_found"] == s["frames_decoded"] == s["frames_sent"] == 4
    assert s["samples_received"] == s["driver_samples"]
    assert all(r["air_s"] < r["latency_s"] < 5.0 for r in s["views"])


@needs_phy
def test_a_late_pluto_reader_loses_whole_buffers_and_the_run_says_so(
    tmp_path, images, monkeypatch, capsys
):
    push, calls = RingBuffer.push, []

    def stalling_push(self, x):  # the host's reader stalls once, longer than 4 buffers last
        calls.append(len(x))
        if len(calls) == 3:
            time.sleep(0.5)
        return push(self, x)

    monkeypatch.setattr(RingBuffer, "push", stalling_push)
    rc, s = pluto_stream(tmp_path, images, "--views", "6", "--view-interval-s", "0.2")
    assert rc == 1 and s["device_overruns"] == -1  # libiio says nothing; the board does
    assert s["emulator_overruns"] >= 1 and s["emulator_lost_buffers"] >= 1
    assert s["emulator_overrun_samples"] == s["emulator_lost_buffers"] * calls[0]  # whole
    assert s["dropped_samples"] == s["emulator_overrun_samples"] and s["overruns"] >= 1
    err = capsys.readouterr().err
    assert "the stream lost" in err and f"{s['emulator_lost_buffers']} buffer(s)" in err
