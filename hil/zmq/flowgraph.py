"""GNU Radio flowgraphs (``.grc``) compiled by ``grcc`` and run headless in their own
process: :class:`Flowgraph`.

GNU Radio 3.10 on Debian is built for numpy 1.x, so it cannot load beside our numpy 2: each
flowgraph runs on Debian's ``/usr/bin/python3``, and talks to us over ZeroMQ
(:class:`hil.ZmqRadio`). The flowgraphs osnerf ships live in ``gnuradio/`` at the
repository's root (:data:`FLOWGRAPHS`); each parameter block of a flowgraph is a command
line option of its compiled script (``--noise-voltage 0.05``).
"""

from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from hil.errors import DeviceNotFoundError, HilError
from hil.ota.config import OtaConfig

FLOWGRAPHS = Path(__file__).resolve().parents[2] / "gnuradio"
GNURADIO_PYTHON = "/usr/bin/python3"
INSTALL_HINT = (
    "GNU Radio 3.10 is not installed: 'make gnuradio' as root, or 'sudo apt-get install "
    "--no-install-recommends gnuradio gr-osmosdr' (Debian 12)"
)


def flowgraph_path(name: str | os.PathLike) -> Path:
    """A ``.grc`` file: a path, or the name of one in :data:`FLOWGRAPHS` (``loopback``)."""
    p = Path(name)
    if p.suffix == ".grc" and p.is_file():
        return p
    shipped = FLOWGRAPHS / f"{p.stem}.grc"
    if shipped.is_file():
        return shipped
    known = ", ".join(sorted(f.stem for f in FLOWGRAPHS.glob("*.grc")))
    raise FileNotFoundError(f"no flowgraph {str(name)!r}: a .grc file, or one of {known}")


def compile_flowgraph(grc: str | os.PathLike, out_dir: str | os.PathLike) -> Path:
    """``grcc GRC -o OUT_DIR``: the flowgraph's Python script (no GUI needed).

    Raises:
        DeviceNotFoundError: no ``grcc``; HilError: grcc refused the flowgraph.
    """
    grcc = shutil.which("grcc")
    if grcc is None:
        raise DeviceNotFoundError(INSTALL_HINT)
    out_dir = Path(out_dir)
    before = set(out_dir.glob("*.py"))
    done = subprocess.run(
        [grcc, str(grc), "-o", str(out_dir)], capture_output=True, text=True, timeout=120
    )
    made = sorted(set(out_dir.glob("*.py")) - before) or sorted(out_dir.glob("*.py"))
    if done.returncode != 0 or not made:
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        raise HilError(f"grcc {grc}: failed: {' / '.join(tail)}")
    return made[0]


def noise_voltage(snr_db: float, signal_power_dbfs: float, occupied_fraction: float = 1.0):
    """``channels.channel_model``'s noise voltage (standard deviation per complex sample)
    that puts a signal of mean power ``signal_power_dbfs``, spread over
    ``occupied_fraction`` of the band, at ``snr_db`` per occupied subcarrier (Es/N0 of its
    symbols: what a receiver measures on its pilots)."""
    return math.sqrt(10 ** ((signal_power_dbfs - snr_db) / 10) / occupied_fraction)


def ota_noise_voltage(snr_db: float, cfg=None) -> float:
    """The noise voltage that puts ``osnerf ota``'s frames (``hil.OtaConfig``'s mean power,
    ``phy``'s OFDM: used carriers of the FFT) at ``snr_db`` per symbol."""
    import phy  # loads torch, which import hil does not

    cfg = cfg or OtaConfig()
    fc = phy.FrameConfig()
    used = fc.fft_size - sum(fc.num_guard_carriers) - int(fc.dc_null)
    return noise_voltage(snr_db, cfg.tx_power_dbfs, used / fc.fft_size)


class Flowgraph:
    """One flowgraph in its own process on Debian's python3 (a context manager).

    Args:
        grc: a ``.grc`` path or the name of a shipped one.
        params: the flowgraph's parameters, ``{"noise_voltage": 0.05}`` (ids as in the
            ``.grc``; each becomes ``--noise-voltage 0.05``).
        python: the interpreter GNU Radio is installed for.
    """

    def __init__(self, grc, params: dict | None = None, python: str = GNURADIO_PYTHON):
        self.grc = flowgraph_path(grc)
        self.params = dict(params or {})
        self.python = python
        self.proc: subprocess.Popen | None = None
        self._dir: tempfile.TemporaryDirectory | None = None

    def argv(self, script: Path) -> list[str]:
        out = [self.python, "-u", str(script)]
        for k, v in self.params.items():
            out += [f"--{k.replace('_', '-')}", str(v)]
        return out

    def start(self, settle_s: float = 0.5) -> Flowgraph:
        """Compile and start it; raises ``HilError`` when it exits within ``settle_s``."""
        if not Path(self.python).is_file():
            raise DeviceNotFoundError(INSTALL_HINT)
        self._dir = tempfile.TemporaryDirectory(prefix="osnerf-grc-")
        script = compile_flowgraph(self.grc, self._dir.name)
        log = Path(self._dir.name) / "stderr.log"  # a file: a pipe nobody reads fills and stalls
        with log.open("w") as err_file:
            self.proc = subprocess.Popen(
                self.argv(script),
                stdin=subprocess.PIPE,  # a prompting flowgraph waits on it; never written
                stdout=subprocess.DEVNULL,
                stderr=err_file,
                text=True,
                env={k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")},
            )
        deadline = time.monotonic() + settle_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                err = log.read_text(errors="replace").strip()
                self.close()
                raise HilError(f"flowgraph {self.grc.name} exited: {err.splitlines()[-1:]}")
            time.sleep(0.05)
        return self

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def wait(self) -> int:
        """Until it ends by itself; its exit status."""
        assert self.proc is not None
        return self.proc.wait()

    def close(self, timeout_s: float = 10.0) -> int | None:
        """Stop it (SIGTERM, then SIGKILL after ``timeout_s``); its exit status."""
        rc = None
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGTERM)
                try:
                    self.proc.wait(timeout=timeout_s)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
            rc = self.proc.returncode
            if self.proc.stdin is not None:
                self.proc.stdin.close()
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None
        return rc

    def __enter__(self) -> Flowgraph:
        return self if self.running else self.start()

    def __exit__(self, *exc) -> None:
        self.close()
