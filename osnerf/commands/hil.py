"""`osnerf hil info [--emulate]`: list HackRF boards as ``hackrf_info`` does (pure pyusb),
the Plutos libiio finds and the devices SoapySDR finds; `osnerf hil emulate pluto|soapy
--address 127.0.0.1 [--port N]`: serve an emulated Pluto over iiod's network protocol, or an
emulated SoapySDR device over SoapyRemote's, until SIGINT or SIGTERM."""

from __future__ import annotations

import argparse
import sys

from osnerf.cli import UsageError as usage_error
from osnerf.commands import args as checks

FAULT_AFTER_SAMPLES = 50_000  # --fault-after-samples' default


def _integer(lo: int, hi: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be an integer in [{lo}, {hi}], got {text!r}")
        return value

    parse.__name__ = "integer"
    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", parser_class=type(p))
    sub.required = True
    info = sub.add_parser(
        "info",
        help="board id, firmware, serial and USB API of each HackRF, then each Pluto libiio finds",
        description="list HackRF boards as hackrf_info does (pure pyusb), then the Plutos "
        "libiio finds (USB, ip:$IIOD_REMOTE)",
    )
    info.add_argument(
        "--emulate", action="store_true", help="use two emulated HackRFs instead of USB hardware"
    )
    info.add_argument("--serial", default=None, help="only the HackRF whose serial ends with this")
    info.add_argument(
        "--soapy-args",
        default="",
        help="what SoapySDR.Device.enumerate is asked for, e.g. 'driver=uhd' or "
        "'driver=remote,remote=tcp://HOST:PORT' (default: every installed module's devices)",
    )
    _add_gnuradio_arguments(
        sub.add_parser(
            "gnuradio",
            help="run a GNU Radio flowgraph (gnuradio/*.grc) headless until SIGINT or SIGTERM",
            description="compile a flowgraph with grcc and run it on Debian's python3 in its "
            "own process (GNU Radio 3.10 is built for numpy 1.x), until SIGINT or SIGTERM; "
            "osnerf ota --tx zmq:ADDRESS --rx zmq:ADDRESS then sends through it",
        )
    )
    _add_emulate_arguments(
        sub.add_parser(
            "emulate",
            help="serve an emulated board over iiod's network protocol until SIGINT or SIGTERM",
            description="serve an emulated board (its TX looped to its RX through the air "
            "model) over iiod's network protocol, in the foreground, until SIGINT or SIGTERM",
        )
    )


def _add_gnuradio_arguments(p: argparse.ArgumentParser) -> None:
    from hil.zmq import FLOWGRAPHS

    shipped = ", ".join(sorted(f.stem for f in FLOWGRAPHS.glob("*.grc")))
    p.add_argument("flowgraph", help=f"a .grc file, or a shipped one: {shipped}")
    p.add_argument(
        "--snr-db",
        type=checks.number(-30.0, 60.0, "dB"),
        default=None,
        help="set the flowgraph's noise_voltage so that osnerf ota's frames arrive at this SNR "
        "per symbol (the loopback's noise)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="PARAM=VALUE",
        help="a parameter of the flowgraph (its parameter blocks), e.g. --set echo_delay=2 "
        "--set freq_offset=0.00025; repeatable",
    )


def _gnuradio(args: argparse.Namespace) -> int:
    import signal
    import threading

    from hil.zmq import Flowgraph, ota_noise_voltage

    params = {}
    for item in args.set:
        key, eq, value = item.partition("=")
        if not eq or not key.isidentifier():
            raise usage_error(f"--set must look like PARAM=VALUE, got {item!r}")
        params[key] = value
    if args.snr_db is not None:
        if "noise_voltage" in params:
            raise usage_error("--snr-db sets noise_voltage: give one of them")
        params["noise_voltage"] = f"{ota_noise_voltage(args.snr_db):.9g}"
    try:
        graph = Flowgraph(args.flowgraph, params)
    except FileNotFoundError as e:
        raise usage_error(f"flowgraph: {e}") from None
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    graph.start()
    shown = " ".join(f"{k}={v}" for k, v in params.items()) or "its defaults"
    print(
        f"osnerf hil gnuradio: {graph.grc.name} running (pid {graph.proc.pid}) with {shown}; "
        "SIGINT or SIGTERM stops it",
        file=sys.stderr,
        flush=True,
    )
    while not stop.is_set() and graph.running:
        stop.wait(0.1)
    ended = not graph.running
    rc = graph.close()
    if ended:  # it stopped by itself: a failure
        print(f"osnerf hil gnuradio: {graph.grc.name} exited ({rc})", file=sys.stderr)
        return 1
    return 0


def _add_emulate_arguments(p: argparse.ArgumentParser) -> None:
    from hil import DEVICES
    from hil.emulation import AIR_SNR_DB_RANGE, NETWORK_FAULTS, SOAPY_FAULTS

    served = [k for k, v in DEVICES.items() if v.emulator is not None]
    ports = ", ".join(f"{k} {DEVICES[k].default_port}" for k in served)
    p.add_argument("device", choices=served, help=f"which board: {', '.join(served)}")
    p.add_argument("--address", default="127.0.0.1", help="loopback IPv4 to listen on")
    p.add_argument(
        "--port", type=_integer(0, 65535), default=None, help=f"TCP port (default {ports})"
    )
    p.add_argument(
        "--snr-db",
        type=checks.number(*AIR_SNR_DB_RANGE, "dB"),
        default=15.0,
        help="SNR of the board's TX-to-RX loop for over-the-air frames, dB, until a client "
        "sets the air (osnerf ota does, from its own flags, before each burst) (default 15)",
    )
    p.add_argument("--seed", type=checks.seed, default=0, help="noise seed (default 0)")
    p.add_argument(
        "--fault",
        default=None,
        choices=sorted({*NETWORK_FAULTS, *SOAPY_FAULTS}),
        help="after --fault-after-samples received samples, drop (the board dies), slow "
        "(pluto: each receive reply 6 s late, past libiio's 5 s timeout) or overflow (soapy: "
        "samples lost once, reported as SOAPY_SDR_OVERFLOW)",
    )
    p.add_argument(
        "--fault-after-samples",
        type=_integer(0, 2**40),
        default=None,
        help=f"with --fault: received samples before the fault (default {FAULT_AFTER_SAMPLES})",
    )


def _info_lines(index: int, dev) -> list[str]:
    from hil.hackrf import BOARD_IDS, usb_api_version_string

    board = BOARD_IDS.get(dev.board_id, "unknown")
    return [
        "Found HackRF",
        f"Index: {index}",
        f"Serial number: {dev.serial_number}",
        f"Board ID Number: {dev.board_id} ({board})",
        f"Firmware Version: {dev.firmware_version} "
        f"(API:{usb_api_version_string(dev.usb_api_version)})",
        f"Part ID Number: 0x{dev.part_id[0]:08x} 0x{dev.part_id[1]:08x}",
    ]


def _emulate(args: argparse.Namespace) -> int:
    import signal
    import threading

    from hil import DEVICES
    from hil.emulation import NETWORK_FAULTS, SOAPY_FAULTS
    from osnerf.ota_link import DEFAULT_DELAY_S, DEFAULT_MULTIPATH

    if args.fault is None and args.fault_after_samples is not None:
        raise usage_error(
            "--fault-after-samples applies only with --fault (it says when the fault "
            "strikes); name a --fault or leave --fault-after-samples out"
        )
    faults = SOAPY_FAULTS if args.device == "soapy" else NETWORK_FAULTS
    if args.fault is not None and args.fault not in faults:
        raise usage_error(f"--fault {args.fault}: a {args.device} emulator has {', '.join(faults)}")
    after = FAULT_AFTER_SAMPLES if args.fault_after_samples is None else args.fault_after_samples
    kind = DEVICES[args.device]
    port = kind.default_port if args.port is None else args.port
    board = kind.emulator(
        args.snr_db,
        seed=args.seed,
        multipath=DEFAULT_MULTIPATH,
        delay_s=DEFAULT_DELAY_S,
        fault=args.fault,
        after_samples=after,
    )
    try:
        server = kind.serve(board, args.address, port)
    except ValueError as e:
        raise usage_error(f"--address/--port: {e}") from None
    except OSError as e:
        raise OSError(e.errno, f"cannot listen on {args.address}:{port}: {e.strerror}") from e
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    server.serve_in_background()
    print(
        f"osnerf hil emulate: {args.device} at {getattr(server, 'uri', None) or server.args} "
        f"(air {args.snr_db:g} dB); "
        "SIGINT or SIGTERM stops it",
        file=sys.stderr,
        flush=True,
    )
    told, underruns = False, 0
    overflows = 0
    while not stop.is_set() and not board.dropped.is_set():
        stop.wait(0.05)
        if board.tx_underruns > underruns:
            underruns = board.tx_underruns
            print(
                f"osnerf hil emulate: TX underrun ({underruns} so far): the host fed the DAC late",
                file=sys.stderr,
                flush=True,
            )
        if getattr(board, "overflows", 0) > overflows:
            overflows = board.overflows
            print(
                f"osnerf hil emulate: fault: receive overflow ({overflows} so far)",
                file=sys.stderr,
                flush=True,
            )
        if board.stalled.is_set() and not told:
            told = True
            print(
                f"osnerf hil emulate: fault: receive stalls after {board.samples_received} samples",
                file=sys.stderr,
                flush=True,
            )
    server.close()
    if board.dropped.is_set():
        print("osnerf hil emulate: fault: the board dropped every connection", file=sys.stderr)
        return 1
    return 0


def _pluto_info() -> int:
    """Print each Pluto libiio finds; returns how many."""
    from hil import HilError, Pluto, find_plutos

    found = find_plutos()
    for uri, desc in found:
        try:
            with Pluto.open(uri, configure=False) as dev:
                print(
                    f"Found Pluto\nURI: {uri}\nModel: {dev.product}\nSerial number: "
                    f"{dev.serial_number}\nFirmware Version: {dev.firmware_version}"
                )
        except HilError as e:
            print(f"URI: {uri} ({desc})\nerror: {e}", file=sys.stderr)
    return len(found)


def _soapy_info(query: str) -> int:
    """Print each device ``SoapySDR.Device.enumerate(query)`` finds (with its ranges when
    it opens); returns how many (0 without the binding)."""
    from hil import DeviceNotFoundError, HilError, SoapyRadio
    from hil.soapy import find_soapy_devices

    try:
        found = find_soapy_devices(query)
    except DeviceNotFoundError:  # no binding: no SoapySDR device to list
        return 0
    for args in found:
        print(f"Found SoapySDR device\nArgs: {args}")
        try:
            with SoapyRadio.open(args) as radio:
                r = radio.ranges()
                print(
                    f"Driver: {radio.driver_key}\nHardware: {radio.hardware_key}\n"
                    f"Frequency range: {r['center_freq_range_hz'][0]:g}-"
                    f"{r['center_freq_range_hz'][1]:g} Hz\nSample rate range: "
                    f"{r['sample_rate_range_hz'][0]:g}-{r['sample_rate_range_hz'][1]:g} S/s"
                )
        except HilError as e:
            print(f"error: {e}", file=sys.stderr)
    return len(found)


def run(args: argparse.Namespace) -> int:
    from hil import Emulator, HackRF, HilError, find_hackrfs

    if args.action == "emulate":
        return _emulate(args)
    if args.action == "gnuradio":
        return _gnuradio(args)
    backend = Emulator().backend if args.emulate else None
    serials = [d.serial_number for d in find_hackrfs(backend)]
    if args.serial:
        serials = [s for s in serials if s.endswith(args.serial.lower())]
    if not serials:
        found = _pluto_info()
        found += _soapy_info(args.soapy_args)
        if found:  # no HackRF, but a Pluto or a SoapySDR device
            return 0
        which = f" with a serial ending in {args.serial!r}" if args.serial else ""
        raise RuntimeError(f"no HackRF board found{which}, no Pluto and no SoapySDR device")
    print("osnerf hil info (pure pyusb, no libhackrf)")
    for i, serial in enumerate(serials):
        try:
            with HackRF.open(serial, backend=backend, configure=False) as dev:
                print("\n".join(_info_lines(i, dev)))
        except HilError as e:
            print(f"Index: {i}\nSerial number: {serial}\nerror: {e}", file=sys.stderr)
            return 1
        if i + 1 < len(serials):
            print()
    _pluto_info()
    _soapy_info(args.soapy_args)
    return 0
