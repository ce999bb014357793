"""The GNU Radio bridge through GNU Radio 3.10's own runtime: every shipped flowgraph
compiles with ``grcc``; the loopback flowgraph, run headless on Debian's python3, carries
gr-zeromq's stream format and ``osnerf ota --tx zmq:... --rx zmq:...``."""

import json
import shutil
import socket
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from hil import Radio, ZmqRadio
from hil.zmq import FLOWGRAPHS, Flowgraph, compile_flowgraph, ota_noise_voltage
from hil.zmq.flowgraph import GNURADIO_PYTHON

pytest.importorskip("zmq", reason="pyzmq is not installed")
HAVE_GNURADIO = (
    shutil.which("grcc") is not None
    and Path(GNURADIO_PYTHON).is_file()
    and subprocess.run(
        [GNURADIO_PYTHON, "-c", "from gnuradio import zeromq, channels"], capture_output=True
    ).returncode
    == 0
)
pytestmark = pytest.mark.skipif(
    not HAVE_GNURADIO, reason="Debian's gnuradio is not installed (make gnuradio)"
)
SHIPPED = sorted(p.name for p in FLOWGRAPHS.glob("*.grc"))


def free_ports(n: int = 2) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


@pytest.fixture
def endpoints():
    tx, rx = free_ports()
    return f"tcp://127.0.0.1:{tx}", f"tcp://127.0.0.1:{rx}"


def test_the_shipped_flowgraphs_are_the_five_front_ends():
    assert SHIPPED == ["loopback.grc", "osmosdr.grc", "pluto.grc", "soapy.grc", "usrp.grc"]


NEEDS = {  # the GNU Radio module each front end's blocks come from
    "osmosdr.grc": "osmosdr",
    "pluto.grc": "gnuradio.iio",
    "soapy.grc": "gnuradio.soapy",
    "usrp.grc": "gnuradio.uhd",
}


@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    """Every shipped flowgraph whose blocks are installed, compiled by one grcc run:
    ``{name: script}`` (Debian's gnuradio and gr-osmosdr have them all)."""
    check = "import importlib.util as u, sys; print(*[m for m in sys.argv[1:] if u.find_spec(m)])"
    found = subprocess.run(
        [GNURADIO_PYTHON, "-c", check, *NEEDS.values()], capture_output=True, text=True
    ).stdout.split()
    names = [n for n in SHIPPED if NEEDS.get(n, "gnuradio") in (*found, "gnuradio")]
    out = tmp_path_factory.mktemp("grcc")
    done = subprocess.run(
        ["grcc", *[str(FLOWGRAPHS / n) for n in names], "-o", str(out)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    return {n: out / f"osnerf_{n[: -len('.grc')]}.py" for n in names}


def test_compile_flowgraph_names_its_script(tmp_path):
    assert compile_flowgraph(FLOWGRAPHS / "loopback.grc", tmp_path).name == "osnerf_loopback.py"


@pytest.mark.parametrize("name", SHIPPED)
def test_every_flowgraph_compiles_with_grcc(name, compiled):
    if name not in compiled:
        pytest.skip(f"{NEEDS[name]} is not installed for GNU Radio (make gnuradio)")
    script = compiled[name]
    text = script.read_text()
    # headless, talking to osnerf over ZeroMQ in complex64 items with tags off
    assert "zeromq.pull_source(gr.sizeof_gr_complex, 1, tx_address, 100, False, 2)" in text
    assert "zeromq.push_sink(gr.sizeof_gr_complex, 1, rx_address, 100, False, 2)" in text
    assert "qtgui" not in text and "tb.wait()" in text
    assert subprocess.run([GNURADIO_PYTHON, "-m", "py_compile", str(script)]).returncode == 0


def test_the_radio_pushes_raw_complex64_items(endpoints):
    import zmq

    tx, _ = endpoints
    with ZmqRadio(tx, None, sample_rate_hz=4e6) as radio:
        assert isinstance(radio, Radio)
        ctx = zmq.Context()
        pull = ctx.socket(zmq.PULL)
        pull.connect(tx)
        x = (np.arange(1000) * (0.001 + 0.0005j)).astype(np.complex64)
        got = []

        def read():
            while sum(len(g) for g in got) < len(x) and pull.poll(10_000):
                got.append(np.frombuffer(pull.recv(), np.complex64))

        reader = threading.Thread(target=read)
        reader.start()
        radio.tx(x)
        reader.join(15)
        while pull.poll(200):  # silence the clock pushed before it stopped, if any
            got.append(np.frombuffer(pull.recv(), np.complex64))
        pull.close(0)
        ctx.term()
    # a message is just items: the burst's 1000 (8 bytes each), then chunks of silence
    assert got[0].nbytes == 1000 * 8 and np.array_equal(got[0], x)
    assert all(len(g) == 8192 and not g.any() for g in got[1:])


def test_the_loopback_returns_a_burst_bit_exact_without_noise(endpoints):
    tx, rx = endpoints
    params = {"tx_address": tx, "rx_address": rx, "noise_voltage": 0}
    rng = np.random.default_rng(0)
    i, q = np.clip(0.2 * rng.standard_normal((2, 50_000)), -1, 1)
    x = (i + 1j * q).astype(np.complex64)
    with Flowgraph("loopback", params), ZmqRadio(tx, rx) as radio:
        out = {}
        capture = threading.Thread(target=lambda: out.setdefault("y", radio.rx(1_500_000)))
        capture.start()
        deadline = time.monotonic() + 10
        while not radio.receiving and time.monotonic() < deadline:
            time.sleep(0.001)
        radio.tx(x)
        capture.join(30)
    y = out["y"][0]
    start = int(np.flatnonzero(y)[0])
    np.testing.assert_array_equal(y[start : start + len(x)], x)
    assert not y[start + len(x) :].any()


def test_ota_crosses_the_loopback_at_10_db_with_no_frame_lost(endpoints, tmp_path, shared_data):
    semcodec = pytest.importorskip("semcodec")
    if not semcodec.DEFAULT_CHECKPOINT.is_file():
        pytest.skip("semcodec's shipped default checkpoint is not in this checkout")
    from osnerf.cli import main

    images = tmp_path / "images"
    images.mkdir()
    for path in sorted((shared_data / "kodak").glob("*.png"))[:3]:
        shutil.copy(path, images / path.name)
    tx, rx = endpoints
    params = {"tx_address": tx, "rx_address": rx, "noise_voltage": ota_noise_voltage(10.0)}
    out = tmp_path / "ota.json"
    with Flowgraph("loopback", params):
        rc = main(
            ["ota", "--tx", f"zmq:{tx}", "--rx", f"zmq:{rx}", "--schemes", "jscc,digital"]
            + ["--images", str(images), "--max-images", "3", "--out", str(out)]
        )
    assert rc == 0
    d = json.loads(out.read_text())
    s = d["summary"]
    assert s["frames_sent"] == 12 and s["frames_lost"] == 0
    # the mean of 12 frames' pilot estimates, and the noise falls on the frames differently
    # each run (the scatter is in docs/design-notes.md, "Over the air")
    assert abs(s["snr_db_measured"] - 10.0) < 1.0
    assert d["config"]["tx"] == f"zmq:{tx}" and d["config"]["snr_db"] is None  # the air's own


def test_hil_gnuradio_runs_the_flowgraph_until_sigterm(endpoints):
    import os
    import signal
    import sys

    import zmq

    root = Path(__file__).resolve().parents[2]
    path = os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONPATH": path}
    tx, rx = endpoints
    code = "import sys; from osnerf.cli import main; sys.exit(main(sys.argv[1:]))"
    argv = ["hil", "gnuradio", "loopback", "--snr-db", "10"]
    argv += ["--set", f"tx_address={tx}", "--set", f"rx_address={rx}"]
    proc = subprocess.Popen(
        [sys.executable, "-c", code, *argv], stderr=subprocess.PIPE, text=True, env=env
    )
    try:
        line = proc.stderr.readline()
        assert "loopback.grc running" in line
        assert f"noise_voltage={ota_noise_voltage(10):.9g}" in line
        ctx = zmq.Context()
        push, pull = ctx.socket(zmq.PUSH), ctx.socket(zmq.PULL)
        push.bind(tx)
        pull.connect(rx)
        push.send(np.ones(4096, np.complex64).tobytes())
        assert pull.poll(10_000)  # through GNU Radio's channel model: the same count, noisy
        y = np.frombuffer(pull.recv(), np.complex64)
        assert 0 < len(y) <= 4096 and abs(np.mean(y) - 1) < 0.1
        push.close(0), pull.close(0), ctx.term()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
    finally:
        proc.kill()
