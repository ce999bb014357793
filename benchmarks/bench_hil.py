"""Receive paths of the HackRF and Pluto front ends on emulated boards: MS/s sustained and
host CPU per MS.

The Pluto runs through pyadi-iio and libiio's network backend against the emulated board's
iiod server in another process (``osnerf hil emulate pluto``): its CPU time is the host's
alone; the server delivers at most the sample rate, like a board.

CPU time (all threads of the process) is the measure; wall time on a shared machine is not.
Side by side in one run: the whole path through pyusb (driver thread + pyusb + emulated
firmware + the medium rendering noise), the same without pyusb (loopback transport), and
the emulator's rendering alone, so the driver's own cost is total minus rendering. The
real HackRF delivers at most 20 MS/s; the question is whether pyusb keeps up at 4 MS/s.
Timings on a shared 2-core machine are noisy.
"""

from __future__ import annotations

import time
from pathlib import Path

from hil import AirChannel, Emulator, HackRF, Pluto, open_loopback

TARGET_MSPS = 4.0
NUM_SAMPLES = 4_000_000  # one second at 4 MS/s


def _measure(fn) -> dict:
    w0, c0 = time.perf_counter(), time.process_time()
    n = fn()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    msps = n / wall / 1e6
    return {
        "samples": n,
        "wall_s": round(wall, 4),
        "cpu_s": round(cpu, 4),
        "msps_wall": round(msps, 2),
        "msps_per_cpu_core": round(n / max(cpu, 1e-9) / 1e6, 2),
        "cpu_s_per_ms": round(cpu / (n / 1e6), 4),
    }


def _pluto() -> dict:
    """The Pluto front end's receive path (pyadi-iio, libiio's network backend) against an
    emulated board in its own process (``osnerf hil emulate pluto``), as against a board on
    the network: CPU time here is the host's alone. The board delivers at most its rate."""
    import signal
    import socket
    import subprocess
    import sys

    with socket.socket() as sock:
        sock.bind(("127.0.0.5", 0))
        port = sock.getsockname()[1]
    code = "import sys; from osnerf.cli import main; sys.exit(main(sys.argv[1:]))"
    args = ["hil", "emulate", "pluto", "--address", "127.0.0.5", "--port", str(port)]
    emu = subprocess.Popen([sys.executable, "-c", code, *args], stderr=subprocess.PIPE, text=True)
    out: dict = {}
    try:
        emu.stderr.readline()  # "... pluto at ip:...": listening
        with Pluto.open(f"ip:127.0.0.5:{port}", rx_chunk_samples=1 << 16) as sdr:
            for rate in (4e6, 10e6, 20e6):
                sdr.sample_rate_hz = rate
                sdr.rx(1000)  # warm up
                out[f"pluto_rx_{rate / 1e6:g}msps"] = _measure(
                    lambda s=sdr: s.rx(NUM_SAMPLES).shape[1]
                )
    finally:
        emu.send_signal(signal.SIGTERM)
        out["pluto_emulator_exit_code_on_sigterm"] = emu.wait(timeout=30)
    return out


def run(out_dir: Path) -> dict:
    results: dict = {"target_msps": TARGET_MSPS, "num_samples": NUM_SAMPLES}
    for chunk in (16384, 262144):
        emu = Emulator(AirChannel(snr_db=20), ppm=(0.0,), seed=0)
        with HackRF.open(backend=emu.backend, rx_chunk_bytes=chunk) as sdr:
            sdr.sample_rate_hz = 4e6
            sdr.rx(1000)  # warm up
            results[f"pyusb_chunk_{chunk}"] = _measure(lambda s=sdr: s.rx(NUM_SAMPLES).shape[1])
            results[f"pyusb_chunk_{chunk}"]["host_dropped_bytes"] = (
                sdr.last_stats.host_dropped_bytes
            )
        emu = Emulator(AirChannel(snr_db=20), ppm=(0.0,), seed=0)
        with open_loopback(emu.radios[0], rx_chunk_bytes=chunk) as sdr:
            sdr.sample_rate_hz = 4e6
            results[f"loopback_chunk_{chunk}"] = _measure(lambda s=sdr: s.rx(NUM_SAMPLES).shape[1])
    emu = Emulator(AirChannel(snr_db=20), ppm=(0.0,), seed=0)
    radio = emu.radios[0]
    radio.sample_rate_hz = 4e6

    def render_only() -> int:
        n, k = 0, 0
        while n < NUM_SAMPLES:
            radio.medium.render(radio, k, 131072, lambda: True)
            n += 131072
            k += 131072
        return n

    results["emulator_render_only"] = _measure(render_only)
    best = results["pyusb_chunk_262144"]
    render = results["emulator_render_only"]
    driver_cpu = max(best["cpu_s_per_ms"] - render["cpu_s_per_ms"], 1e-6)
    results["driver_cpu_s_per_ms_excluding_emulation"] = round(driver_cpu, 4)
    results["driver_only_msps_per_cpu_core"] = round(1.0 / driver_cpu, 1)
    results["driver_cpu_fraction_at_4msps"] = round(driver_cpu * TARGET_MSPS, 3)
    results["keeps_up_at_4msps"] = bool(1.0 / driver_cpu >= TARGET_MSPS)
    results.update(_pluto())
    results["note"] = (
        "msps_wall includes the emulator rendering noise in the same process and depends on how "
        "much CPU the shared machine gives us; msps_per_cpu_core does not. On hardware only the "
        "driver part (driver_cpu_s_per_ms) is spent on the host. Shared 2-core machine: noisy."
    )
    return results
