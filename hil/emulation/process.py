"""Emulated HackRFs served from a process of their own (:class:`EmulatorProcess`).

The boards of a :class:`hil.Emulator` render the air (channel, resampling, noise, the ADC)
for every sample they deliver; in the receiver's process that work would share the
interpreter lock with the decoder. Here the boards live in a child process and the host
sees them through the same pyusb backend (:class:`hil.emulation.EmulatorBackend`): enumeration and
descriptors are answered locally, and every control request and bulk transfer goes to the
child over a local socket, one connection per host thread, so a receive that waits for its
samples never holds up a transmit. The boards' pacing and their overrun and underrun
counts (:mod:`hil.emulation.pacing`) are the child's, exactly as in one process::

    with EmulatorProcess(AirChannel(snr_db=10), ppm=(0.0, 20.0), paced=True) as emu:
        rx = HackRF.open(emu.serials[1], backend=emu.backend)
"""

from __future__ import annotations

import gc
import json
import os
import secrets
import select
import subprocess
import sys
import threading
from collections.abc import Callable
from multiprocessing.connection import Client, Connection, Listener
from pathlib import Path

import usb.core

from common import tune_malloc
from hil.emulation.air import AirChannel
from hil.emulation.hackrf import EmulatedHackRF, RadioSpec
from hil.emulation.usb_backend import Emulator, EmulatorBackend

START_TIMEOUT_S = 60.0  # the child imports numpy and compiles the resampler once
_ERRORS = {"USBTimeoutError": usb.core.USBTimeoutError, "USBError": usb.core.USBError}
CALLS: dict[str, Callable[..., object]] = {
    "control": EmulatedHackRF.control,
    "bulk_read": EmulatedHackRF.bulk_read,
    "bulk_write": EmulatedHackRF.bulk_write,
    "overrun_samples": lambda radio: radio.overrun_samples,
    "underrun_samples": lambda radio: radio.underrun_samples,
    "rx_late_max_s": lambda radio: radio.rx_late_max_s,
}
"""What the host may ask of a board in the child: ``name -> (board, *args) -> reply``."""


def serve_connection(conn: Connection, emu: Emulator) -> None:
    """Answer one host thread's calls ``(method, board, args)`` (:data:`CALLS`) until it
    hangs up."""
    with conn:
        while True:
            try:
                method, index, args = conn.recv()
            except (EOFError, OSError):
                return
            radio = emu.radios[index]
            reply: tuple
            try:
                reply = ("ok", CALLS[method](radio, *args))
            except usb.core.USBError as e:
                reply = ("usb", type(e).__name__, e.strerror, e.backend_error_code, e.errno)
            except Exception as e:  # noqa: BLE001 - re-raised in the host's thread
                reply = ("error", f"{type(e).__name__}: {e}")
            try:
                conn.send(reply)
            except (EOFError, OSError):  # the host went away mid-call (SIGTERM, Ctrl-C)
                return


def _serve(options: dict) -> None:
    """The child: make the boards, answer connections until the parent closes stdin."""
    if options["cpus"]:
        os.sched_setaffinity(0, options["cpus"])
    channel = AirChannel.from_json(options["channel"])
    emu = Emulator(channel, ppm=options["ppm"], seed=options["seed"], paced=options["paced"])
    # every transfer allocates the same few arrays: reuse the heap's pages instead of
    # faulting in fresh ones, and keep the collector's full passes off the modules'
    # objects (tens of ms with the interpreter held, longer than a board's buffer lasts)
    tune_malloc()
    gc.collect()
    gc.freeze()
    with Listener(family="AF_UNIX", authkey=bytes.fromhex(options["key"])) as listener:

        def accept():
            while True:
                try:
                    conn = listener.accept()
                except OSError:
                    return
                threading.Thread(target=serve_connection, args=(conn, emu), daemon=True).start()

        threading.Thread(target=accept, daemon=True).start()
        print(json.dumps({"address": listener.address, "serials": emu.serials}), flush=True)
        sys.stdin.read()  # EOF: the parent closed the boards or went away


class _RemoteRadio:
    """A board in the child as :class:`hil.emulation.EmulatorBackend` sees it: identity and USB
    state here, requests and transfers there."""

    def __init__(self, owner: EmulatorProcess, spec: RadioSpec, index: int):
        self.owner, self.spec, self.index = owner, spec, index
        self.unplugged = False
        self.configuration = 1
        self.claimed = False

    @property
    def serial(self) -> str:
        return self.spec.serial

    def control(self, request_type, request, value, index, data_or_length):
        return self.owner.call(
            "control", self.index, request_type, request, value, index, data_or_length
        )

    def bulk_read(self, num_bytes: int) -> bytes:
        return self.owner.call("bulk_read", self.index, num_bytes)

    def bulk_write(self, data: bytes) -> int:
        return self.owner.call("bulk_write", self.index, bytes(data))

    @property
    def overrun_samples(self) -> int:
        """Samples this board lost to overruns (the child's count)."""
        return self.owner.call("overrun_samples", self.index)

    @property
    def underrun_samples(self) -> int:
        """Silence this board sent when the host wrote late (the child's count)."""
        return self.owner.call("underrun_samples", self.index)

    @property
    def rx_late_max_s(self) -> float:
        """The most a receive transfer came out later than a real board's (the child's)."""
        return self.owner.call("rx_late_max_s", self.index)


class EmulatorProcess:
    """:class:`hil.Emulator`'s boards in a child process (a context manager; :meth:`close`
    ends the child).

    Args:
        channel, ppm, seed, paced: as :class:`hil.Emulator`.
        cpus: CPUs the child runs on (``os.sched_setaffinity``); None: those of this
            process.
    """

    def __init__(
        self,
        channel: AirChannel | None = None,
        ppm=(0.0, 20.0),
        seed: int = 0,
        paced: bool = True,
        cpus=None,
    ):
        ppm = tuple(float(x) for x in ppm)
        self._key = secrets.token_bytes(32)
        self._local = threading.local()
        self._conns: list[Connection] = []
        self._lock = threading.Lock()
        options = {
            "channel": (channel or AirChannel()).to_json(),
            "ppm": ppm,
            "seed": int(seed),
            "paced": bool(paced),
            "cpus": sorted(int(c) for c in cpus) if cpus else None,
            "key": self._key.hex(),
        }
        root = str(Path(__file__).resolve().parents[2])  # this checkout, whatever the cwd
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])),
        }
        self.process = subprocess.Popen(
            [sys.executable, "-c", "from hil.emulation.process import main; main()"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=env,
            text=True,
        )
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.write(json.dumps(options) + "\n")
        self.process.stdin.flush()
        ready, _, _ = select.select([self.process.stdout], [], [], START_TIMEOUT_S)
        line = self.process.stdout.readline() if ready else ""
        if not line:
            self.close()
            raise RuntimeError("the emulator process did not start")
        started = json.loads(line)
        self._address, serials = started["address"], started["serials"]
        self.radios = [
            _RemoteRadio(self, RadioSpec(s, ppm=float(x)), i)
            for i, (s, x) in enumerate(zip(serials, ppm))
        ]
        self.backend = EmulatorBackend(self.radios)

    @property
    def serials(self) -> list[str]:
        return [r.serial for r in self.radios]

    def call(self, method: str, index: int, *args):
        """``method(*args)`` of board ``index`` in the child, on this thread's connection."""
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = Client(self._address, family="AF_UNIX", authkey=self._key)
            self._local.conn = conn
            with self._lock:
                self._conns.append(conn)
        conn.send((method, index, args))
        reply = conn.recv()
        if reply[0] == "ok":
            return reply[1]
        if reply[0] == "usb":
            _, name, strerror, code, errno_ = reply
            if errno_ == 19:  # the child's board is gone: enumeration here forgets it too
                self.radios[index].unplugged = True
            raise _ERRORS.get(name, usb.core.USBError)(strerror, code, errno_)
        raise RuntimeError(f"emulated board {index}: {reply[1]}")

    def close(self) -> None:
        """End the child (idempotent)."""
        with self._lock:
            for conn in self._conns:
                conn.close()
            self._conns.clear()
        if self.process.poll() is None:
            try:
                self.process.stdin.close()  # type: ignore[union-attr]
                self.process.wait(5.0)
            except (OSError, subprocess.TimeoutExpired):
                self.process.kill()
                self.process.wait()
        for pipe in (self.process.stdin, self.process.stdout):
            if pipe is not None and not pipe.closed:
                pipe.close()

    def __enter__(self) -> EmulatorProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def main() -> None:
    """The child's entry point: its options as one line of JSON on stdin. The parent ends
    it (by closing stdin); a Ctrl-C or SIGTERM meant for the parent's process group ends it
    quietly, never with a thread's traceback."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent's to handle; it closes us
    signal.signal(signal.SIGTERM, lambda *_: os._exit(0))
    try:
        _serve(json.loads(sys.stdin.readline()))
    except (KeyboardInterrupt, BrokenPipeError, EOFError):
        os._exit(0)
