"""`osnerf ota --stream` in real time: a minute of views between emulated radios, as the
receiver must keep up with them, and a CPU burner on the decoder's core.

Three runs of the command, each in its own process, the decoder's process pinned to the
last CPU and the emulated boards' process to the first (``--emulator-cpus``, or
``taskset`` for the Pluto's server), as a host with a radio on USB has them:

- ``hackrf_20msps``: emulated HackRFs at 20 MS/s, jscc at 10 dB, views for 60 s: no
  sample dropped, every frame found, latency per view (exit 0);
- ``pluto_4msps``: the same over an emulated Pluto (``osnerf hil emulate pluto``) at
  4 MS/s, the rate at which real Plutos stay reliable over USB;
- ``hackrf_20msps_burner``: 10 s at 20 MS/s with a busy loop pinned to the decoder's CPU:
  the drops are reported and the command exits 1.

Each run's ``stream`` section (samples received and dropped, frames, latency) is copied
here beside its exit code and the machine's load average before it started. Needs two CPUs;
takes about three minutes.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from osnerf.paths import shared_data_dir

SECONDS = 60.0
BURNER_SECONDS = 10.0
VIEW_INTERVAL_S = 0.1
CODE = "import sys; from osnerf.cli import main; sys.exit(main(sys.argv[1:]))"
SUMMARY = (
    "samples_received",
    "dropped_samples",
    "overruns",
    "device_overruns",
    "emulator_overrun_samples",
    "emulator_lost_buffers",
    "ring_dropped_samples",
    "frames_sent",
    "frames_found",
    "frames_decoded",
    "frames_lost",
    "views_sent",
    "views_complete",
    "header_errors",
    "latency_s",
    "receiver_realtime_factor",
    "emulator_late_max_s",
)


def _cpus() -> tuple[int, int]:
    """(the emulated boards' CPU, the decoder's CPU)."""
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        raise RuntimeError(f"the stream benchmark needs two CPUs, this process has {cpus}")
    return cpus[0], cpus[-1]


def _ota(work: Path, name: str, rate: float, seconds: float, radio: list[str]) -> dict:
    """One `osnerf ota --stream` run on the decoder's CPU; its exit code and stream record."""
    emu_cpu, dec_cpu = _cpus()
    out = work / f"{name}.json"
    views = str(int(round(seconds / VIEW_INTERVAL_S)))
    argv = ["ota", "--stream", *radio, "--schemes", "jscc", "--snr-db", "10"]
    kodak = str(shared_data_dir() / "kodak")
    argv += ["--images", kodak, "--max-images", "4", "--size", "64", "--out", str(out)]
    argv += ["--symbols-per-frame", "1024", "--sample-rate-hz", f"{rate:g}"]
    argv += ["--views", views, "--view-interval-s", str(VIEW_INTERVAL_S), "--overwrite"]
    if radio[1] == "emulated":
        argv += ["--emulator-cpus", str(emu_cpu)]
    load = os.getloadavg()
    cmd = ["taskset", "-c", str(dec_cpu), sys.executable, "-c", CODE, *argv]
    done = subprocess.run(cmd, capture_output=True, text=True, env=_env())
    record = {"command": " ".join(["osnerf", *argv]), "exit_code": done.returncode}
    record["load_average_before"] = [round(x, 2) for x in load]
    record["stderr_tail"] = done.stderr.strip().splitlines()[-4:]
    if out.exists():
        stream = json.loads(out.read_text())["stream"]
        record.update({k: stream.get(k) for k in SUMMARY})
        record["latency_s"] = {k: stream["latency_s"][k] for k in ("mean", "max")}
    return record


def _env() -> dict:
    """This checkout's code, one thread per numeric library (their idle threads spin)."""
    root = str(Path(__file__).resolve().parent.parent)
    path = os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])
    one = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    return {**os.environ, **one, "PYTHONPATH": path}


def _pluto(work: Path, seconds: float) -> dict:
    """The stream over an emulated Pluto served from its own process on the first CPU."""
    emu_cpu, _ = _cpus()
    with socket.socket() as sock:
        sock.bind(("127.0.0.6", 0))
        port = sock.getsockname()[1]
    serve = ["hil", "emulate", "pluto", "--address", "127.0.0.6", "--port", str(port)]
    cmd = ["taskset", "-c", str(emu_cpu), sys.executable, "-c", CODE, *serve]
    server = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, env=_env())
    try:
        server.stderr.readline()  # type: ignore[union-attr]  # "... pluto at ...": listening
        radio = ["--tx", "pluto", "--rx", "pluto", "--uri", f"ip:127.0.0.6:{port}"]
        return _ota(work, "pluto_4msps", 4e6, seconds, radio)
    finally:
        server.terminate()
        server.wait(30)


def _burner(work: Path, seconds: float) -> dict:
    """The HackRF stream with a busy loop pinned to the decoder's CPU."""
    _, dec_cpu = _cpus()
    busy = ["taskset", "-c", str(dec_cpu), sys.executable, "-c", "while True: pass"]
    burner = subprocess.Popen(busy)
    try:
        time.sleep(0.5)
        radio = ["--tx", "emulated", "--rx", "emulated"]
        record = _ota(work, "hackrf_20msps_burner", 20e6, seconds, radio)
    finally:
        burner.kill()
        burner.wait()
    record["drops_reported"] = record["exit_code"] == 1 and bool(record.get("dropped_samples"))
    return record


def run(out_dir: Path, seconds: float = SECONDS, burner_seconds: float = BURNER_SECONDS) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        emulated = ["--tx", "emulated", "--rx", "emulated"]
        results = {"hackrf_20msps": _ota(work, "hackrf_20msps", 20e6, seconds, emulated)}
        results["pluto_4msps"] = _pluto(work, seconds)
        results["hackrf_20msps_burner"] = _burner(work, burner_seconds)
    results["note"] = (
        "the decoder's process on the last CPU, the emulated boards on the first; a shared "
        "machine's other load (load_average_before) can cost samples: rerun on an idle one"
    )
    return results
