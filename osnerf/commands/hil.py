"""`osnerf hil info [--emulate]`: list HackRF boards as ``hackrf_info`` does (pure pyusb)."""

from __future__ import annotations

import argparse
import sys

ACTIONS = ("info",)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "action", choices=ACTIONS, help="info: board id, firmware, serial, USB API of each HackRF"
    )
    p.add_argument(
        "--emulate", action="store_true", help="use two emulated boards instead of USB hardware"
    )
    p.add_argument("--serial", default=None, help="only the board whose serial ends with this")


def _info_lines(index: int, dev) -> list[str]:
    from hil import protocol

    board = protocol.BOARD_IDS.get(dev.board_id, "unknown")
    return [
        "Found HackRF",
        f"Index: {index}",
        f"Serial number: {dev.serial_number}",
        f"Board ID Number: {dev.board_id} ({board})",
        f"Firmware Version: {dev.firmware_version} (API:{protocol.usb_api_version_string(dev.usb_api_version)})",
        f"Part ID Number: 0x{dev.part_id[0]:08x} 0x{dev.part_id[1]:08x}",
    ]


def run(args: argparse.Namespace) -> int:
    from hil import Emulator, HackRF, HilError, find_hackrfs

    backend = Emulator().backend if args.emulate else None
    serials = [d.serial_number for d in find_hackrfs(backend)]
    if args.serial:
        serials = [s for s in serials if s.endswith(args.serial.lower())]
    if not serials:
        which = f" with a serial ending in {args.serial!r}" if args.serial else ""
        raise RuntimeError(f"no HackRF board found{which}")
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
    return 0
