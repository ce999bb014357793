"""`osnerf ota --stream`: views sent one after another, as a flying drone sends them, to a
receiver that streams without pause and decodes each frame as it arrives
(:func:`hil.stream_over_the_air`).

    osnerf ota --stream --tx emulated --rx emulated --schemes jscc --snr-db 10 \\
        --images DIR --views 600 --view-interval-s 0.1 --out stream.json

``--views`` views go out (the images in turn), one every ``--view-interval-s`` seconds;
the receiver's ring buffer holds ``--ring-s`` seconds of samples. HackRFs and a Pluto
stream (real or emulated). Emulated HackRFs stream
at the configured rate against the wall clock (``hil.Emulator(paced=True)``, served from a
process of their own, ``hil.EmulatorProcess``, on ``--emulator-cpus``), and an emulated
Pluto's receive buffers are DMA blocks, so a receiver that falls behind loses samples as a
real one would. The result file has the
usual per-view rows (PSNR, frames, SNR) and a ``stream`` section: samples received and
dropped (by the board, the driver, the ring), frames found, decoded and lost, and each
view's end-to-end latency, from the moment its transmission started to its image out of
the decoder. A run that lost samples says so on stderr and exits 1 once the result is
written, unless ``--max-overruns`` allows as many overruns. A stream that stops early
(Ctrl-C or SIGTERM: exit 130; a board gone: exit 1) stops sending at once and writes the
views decoded so far, its ``stopped`` section saying why, with the ring's last samples
saved as SigMF (``<sigmf-dir>/ota_rx_partial``), as a burst keeps its capture.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import hil
from common import Registry
from hil import EmulatorProcess, HackRF, HilError, build_views, save_partial_capture
from hil.ota import BurstResult, StreamReceiver
from osnerf.commands import args as checks
from osnerf.commands.ota_args import parse_multipath, parse_ppm, usage_error
from osnerf.commands.ota_config import OtaRunConfig
from osnerf.commands.ota_radios import device_kinds, open_pair
from osnerf.commands.ota_record import ota_record
from osnerf.ota_link import air_channel, received_blocks
from osnerf.provenance import write_json_atomic
from semcodec import LINK_SCHEMES

STREAM_KINDS = ("emulated", "hackrf", "pluto")  # radios whose driver streams
MAX_VIEWS = 10_000  # every view is framed before the stream starts
LAG_WARN_RING_SHARE = 0.1  # emulated boards later than this share of the ring: a warning

# dest -> (flag, its default under --stream)
STREAM_FLAGS = Registry[tuple[str, object]](
    "ota stream flag",
    {
        "views": ("--views", None),  # None: one view per image
        "view_interval_s": ("--view-interval-s", 0.1),
        "ring_s": ("--ring-s", 1.0),
        "emulator_cpus": ("--emulator-cpus", None),  # None: the CPUs of this process
    },
)


def add_stream_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--stream",
        action="store_true",
        help="keep the receiver streaming and send the images as views one after another, "
        "decoding each frame as it arrives (HackRFs or a Pluto, real or emulated; one "
        "scheme)",
    )
    p.add_argument(
        "--views",
        type=checks.count(1, MAX_VIEWS),
        default=None,
        help=f"--stream: views to send, the images in turn, 1..{MAX_VIEWS} (default: one per "
        "image)",
    )
    p.add_argument(
        "--view-interval-s",
        type=checks.number(0.0, 60.0, "s"),
        default=None,
        help="--stream: a view every this many seconds, 0..60 (0: back to back; default 0.1)",
    )
    p.add_argument(
        "--ring-s",
        type=checks.number(0.01, 60.0, "s"),
        default=None,
        help="--stream: the receiver's ring buffer, seconds of samples, 0.01..60 (default 1)",
    )
    p.add_argument(
        "--emulator-cpus",
        type=cpu_list,
        default=None,
        help="--stream with --tx/--rx emulated: CPUs the emulated boards' own process runs on, "
        "e.g. 0 (default: those of this process)",
    )


def cpu_list(text: str) -> tuple[int, ...]:
    """argparse type of ``--emulator-cpus``: CPU numbers ``0,1`` or a range ``0-1``, each one
    of the machine's (this process may be pinned to others)."""
    allowed = list(range(os.cpu_count() or 1))
    try:
        cpus = set()
        for part in text.split(","):
            lo, _, hi = part.strip().partition("-")
            cpus.update(range(int(lo), int(hi or lo) + 1))
    except ValueError:
        cpus = set()
    if not cpus or not cpus <= set(allowed):
        raise argparse.ArgumentTypeError(
            f"must be CPU numbers such as 0 or 0,1 or 0-1, each one of {allowed}, got {text!r}"
        )
    return tuple(sorted(cpus))


def check_stream_flags(args: argparse.Namespace, kind: str) -> dict[str, object]:
    """Refuse stream flags without ``--stream``, and ``--stream`` where it cannot run.
    Returns each stream flag's value: as given, its default where ``--stream`` leaves it out."""
    given = vars(args)
    if not args.stream:
        for dest, (flag, _) in STREAM_FLAGS.items():
            if given[dest] is not None:
                raise usage_error(f"{flag} applies to --stream only: add --stream or leave it out")
        return {dest: given[dest] for dest in STREAM_FLAGS}
    if kind not in STREAM_KINDS:
        raise usage_error(
            f"--stream needs radios that stream (--tx/--rx {', '.join(STREAM_KINDS)}), got {kind}"
        )
    if len(args.schemes) != 1:
        raise usage_error(
            f"--stream sends one scheme, got --schemes {','.join(args.schemes)}: run once each"
        )
    if args.fault:
        raise usage_error("--fault rehearses a burst's faults: leave it out with --stream")
    if args.emulator_cpus is not None and kind != "emulated":
        raise usage_error("--emulator-cpus places emulated boards: it needs --tx/--rx emulated")
    return {
        dest: default if given[dest] is None else given[dest]
        for dest, (_, default) in STREAM_FLAGS.items()
    }


def _open_radios(opts: OtaRunConfig, cfg):
    """(tx, rx, emulator or None): paced emulated HackRFs on the air of the air flags, in a
    process of their own (``hil.EmulatorProcess``: rendering the air does not compete with
    the decoder for the interpreter), or the --tx/--rx boards (an emulated Pluto's air set
    from the air flags, as for a burst)."""
    kind = device_kinds(opts)[0]
    if kind != "emulated":
        return open_pair(opts, cfg)
    channel = air_channel(
        "emulated", opts.snr_db, cfg, opts.delay_us * 1e-6, parse_multipath(opts.multipath)
    )
    emu = EmulatorProcess(
        channel, ppm=parse_ppm(opts.ppm), seed=opts.seed, paced=True, cpus=opts.emulator_cpus
    )
    try:
        tx = HackRF.open(emu.serials[0], backend=emu.backend)
        try:
            return tx, HackRF.open(emu.serials[1], backend=emu.backend), emu
        except BaseException:
            tx.close()
            raise
    except BaseException:
        emu.close()
        raise


def run_stream(
    opts: OtaRunConfig, cfg, settings, names, images, out, t0: float, probe: list
) -> int:
    """Stream ``--views`` views of ``images`` and write the result; 1 when samples were
    lost beyond ``--max-overruns``."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the decoder keeps to one core; the driver's threads get the rest
    try:
        return _stream(opts, cfg, settings, names, images, out, t0, probe)
    finally:
        torch.set_num_threads(threads)


def _stream(opts: OtaRunConfig, cfg, settings, names, images, out, t0: float, probe: list) -> int:
    scheme_name = opts.schemes[0]
    scheme = LINK_SCHEMES[scheme_name].framed
    num_views = opts.views or len(names)
    pick = [v % len(names) for v in range(num_views)]
    first = scheme.transmit(images[pick[0] : pick[0] + 1], settings)  # (blocks, state)
    check_ring(build_views([first[0][0]], cfg), cfg, opts.ring_s)  # before the others
    encoded = [first, *(scheme.transmit(images[i : i + 1], settings) for i in pick[1:])]
    views = build_views([blocks[0] for blocks, _ in encoded], cfg)
    print(
        f"ota: streaming {num_views} view(s) of scheme {scheme_name}, one every "
        f"{opts.view_interval_s:g} s, {sum(len(v.reports) for v in views)} frames",
        file=sys.stderr,
    )
    recs: dict[int, object] = {}
    latency: dict[int, float] = {}

    def on_view(view):
        i = pick[view.index]
        rec = scheme.receive(
            received_blocks(view.result()), encoded[view.index][1], images[i : i + 1], settings
        )[0]
        for frame, crc_ok in zip(view.reports, rec.frames_crc_ok):
            frame.crc_ok = crc_ok
        recs[view.index] = rec
        latency[view.index] = time.monotonic() - view.sent_at if view.sent_at else None

    # the decoder's one-off set-up before the stream: the first view is as quick as the rest
    first = pick[0]
    scheme.receive(
        received_blocks(views[0].result()), encoded[0][1], images[first : first + 1], settings
    )
    stopped = None
    with _sigterm_as_interrupt():
        tx, rx, emu = _open_radios(opts, cfg)
        try:
            run = hil.stream_over_the_air(
                tx,
                rx,
                views,
                cfg,
                on_view,
                interval_s=opts.view_interval_s,
                ring_s=opts.ring_s,
                emulator=emu,
            )
        except (KeyboardInterrupt, HilError) as e:
            if getattr(e, "stream_run", None) is None or not recs:
                raise
            stopped, run = e, e.stream_run
        finally:
            tx.close()
            rx.close()
            if isinstance(emu, EmulatorProcess):  # the emulated boards' own process
                emu.close()
    record = _stream_record(opts, cfg, settings, names, pick, views, recs, latency, run, t0)
    record["sigmf"][:0] = [str(p) for p in probe]
    if stopped is not None:
        return _write_stopped(opts, cfg, out, record, stopped, len(recs), len(views))
    write_json_atomic(out, record)
    return _tell_finished(opts, out, record, run)


def _tell_finished(opts: OtaRunConfig, out, record: dict, run) -> int:
    """A finished stream's lines on stderr (counts, warnings, lost samples); 1 when it lost
    more overruns than ``--max-rx-overruns`` allows."""
    stream, lat = record["stream"], record["stream"]["latency_s"]
    print(
        f"ota: stream: {stream['samples_received']} samples, {stream['dropped_samples']} "
        f"dropped; frames {stream['frames_decoded']}/{stream['frames_sent']} decoded; latency "
        f"mean {lat['mean'] or 0:.3f} s, max {lat['max'] or 0:.3f} s",
        file=sys.stderr,
    )
    for line in run.warnings:
        print(f"ota: warning: {line}", file=sys.stderr)
    print(f"ota: wrote {out}", file=sys.stderr)
    lag = emulator_lag_warning(run.emulator_late_max_s, opts.ring_s)
    if lag:
        print(f"ota: warning: {lag}", file=sys.stderr)
    allowed = opts.max_rx_overruns or 0  # None with a Pluto: libiio 0.x counts none
    if run.overruns > allowed:  # every lost sample is part of an overrun
        print(
            f"ota: the stream lost {run.dropped_samples} samples in {run.overruns} overrun(s) "
            f"(ring {run.ring_dropped_samples}, driver {run.driver_dropped_samples}, board "
            f"{_board_overruns(run)}), allowed {allowed}: see 'stream' in {out}",
            file=sys.stderr,
        )
        return 1
    return 0


def check_ring(views: list, cfg, ring_s: float) -> None:
    """Refuse a ``--ring-s`` that cannot hold one frame with its search window (nothing
    could ever be decoded), before any radio opens."""
    fs = cfg.sample_rate_hz
    need = StreamReceiver.ring_samples_needed(views, cfg)
    if ring_s * fs < need:
        raise usage_error(
            f"--ring-s {ring_s:g} holds less than one frame with its search window: at least "
            f"{math.ceil(need / fs * 1000) / 1000:g} s at --sample-rate-hz {fs:g}"
        )


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """SIGTERM stops the stream as Ctrl-C does (the views decoded so far are written)."""
    import signal

    def stop(signum, frame):
        raise KeyboardInterrupt("SIGTERM")

    try:
        old = signal.signal(signal.SIGTERM, stop)
    except ValueError:  # not the main thread: leave SIGTERM as it is
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def _write_stopped(
    opts: OtaRunConfig, cfg, out, record: dict, stopped: BaseException, decoded: int, sent: int
):
    """Write the result of a stream that stopped early, marked as such, and its capture; 130
    for an interrupt, 1 for a failure."""
    interrupted = isinstance(stopped, KeyboardInterrupt)
    by = (
        f"interrupted ({stopped.args[0] if stopped.args else 'Ctrl-C'})"
        if interrupted
        else "failed"
    )
    sigmf_dir = Path(opts.sigmf_dir) if opts.sigmf_dir else out.with_name(out.stem + "_sigmf")
    saved = None
    if interrupted:
        stopped = HilError(by, capture=getattr(stopped, "capture", None))
    try:
        saved = save_partial_capture(stopped, sigmf_dir / "ota", cfg)
    except OSError as e:
        print(f"ota: warning: the capture so far was not saved: {e}", file=sys.stderr)
    if saved:
        record["sigmf"].append(str(saved))
    record["stopped"] = {
        "by": "interrupt" if interrupted else "failure",
        "message": str(stopped).splitlines()[0] if str(stopped) else by,
        "views_decoded": decoded,
        "views_planned": sent,
        "capture": str(saved) if saved else None,
    }
    write_json_atomic(out, record)
    kept = f"; capture so far saved to {saved}" if saved else ""
    what = by if interrupted else f"failed: {record['stopped']['message']}"
    print(
        f"ota: stream {what} after {decoded} of {sent} view(s); the views decoded so far "
        f"written to {out}{kept}",
        file=sys.stderr,
    )
    return 130 if interrupted else 1


def emulator_lag_warning(late_s: float | None, ring_s: float) -> str | None:
    """The warning for emulated boards that fell behind real time (None: they kept up).

    Their own delay is not charged to the host as overruns, but it is slack a real radio
    would not give: the decoder received the samples that much later than their air time.
    Up to ``LAG_WARN_RING_SHARE`` of the ring buffer it changes nothing that matters."""
    if late_s is None or late_s <= LAG_WARN_RING_SHARE * ring_s:
        return None
    return (
        f"the emulated boards delivered samples up to {late_s:.3f} s later than real boards "
        "would have (rendering the air on this host): the stream ran that much behind its air "
        "time, slack that a real radio does not give the decoder"
    )


def _board_overruns(run) -> str:
    """What the board lost, as the run counted it: its overruns, and an emulated Pluto's
    lost buffers (libiio 0.x reports none of a real one)."""
    if run.emulator_lost_buffers is not None:
        return (
            f"{run.emulator_overruns} overrun(s), {run.emulator_lost_buffers} buffer(s) of "
            f"{run.emulator_overrun_samples} samples lost"
        )
    return f"{run.device_overruns} overrun(s)"


def _stream_record(
    opts: OtaRunConfig, cfg, settings, names, pick, views, recs, latency, run, t0
) -> dict:
    """``ota_record``'s file with one row per view, and the ``stream`` section."""
    view_names = [f"{names[i]}#{v}" for v, i in enumerate(pick)]
    done = [v for v in views if v.index in recs]  # all of them unless the stream stopped early
    reports = [replace(r, block=b) for b, v in enumerate(done) for r in v.reports]
    blocks = [(v.x_hat, v.noise_var) for v in done]
    empty = np.zeros(0, np.complex64)
    result = BurstResult(blocks, reports, empty, empty)
    per_view = [recs[v.index] for v in done]
    done_names = [view_names[v.index] for v in done]
    record = ota_record(
        opts, cfg, settings, done_names, [(opts.schemes[0], per_view, result, [])], t0
    )
    start = min((v.sent_at for v in views if v.sent_at is not None), default=0.0)
    rows = []
    for v in views:
        rows.append(
            {
                "view": v.index,
                "image": view_names[v.index],
                "sent_at_s": None if v.sent_at is None else v.sent_at - start,
                "air_s": len(v.burst) / cfg.sample_rate_hz,
                "latency_s": latency.get(v.index),
                "frames_sent": len(v.reports),
                "frames_decoded": sum(r.detected for r in v.reports),
                "complete": v.complete,
            }
        )
    known = [r["latency_s"] for r in rows if r["latency_s"] is not None]
    frames_sent = sum(len(v.reports) for v in views if v.sent_at is not None)
    record["stream"] = {
        **run.as_dict(),
        "frames_sent": frames_sent,
        "frames_lost": frames_sent - run.counts.frames_decoded,
        "views_planned": len(views),
        "views_sent": sum(v.sent_at is not None for v in views),
        "views_decoded": len(done),
        "views_complete": sum(v.complete for v in views),
        "view_interval_s": opts.view_interval_s,
        "ring_s": opts.ring_s,
        # the frame layer's real-time factor on this stream: air time searched per CPU second
        "receiver_realtime_factor": (
            run.counts.samples_searched / cfg.sample_rate_hz / run.counts.receiver_cpu_s
            if run.counts.receiver_cpu_s > 0
            else None
        ),
        "latency_s": {
            "mean": float(np.mean(known)) if known else None,
            "max": float(np.max(known)) if known else None,
            "note": "from the start of a view's transmission to its image out of the decoder",
        },
        "views": rows,
    }
    return record
