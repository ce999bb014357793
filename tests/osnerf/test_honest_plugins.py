"""Nothing breaks for a plugin it does not use, and nothing is silently accepted.

``test_plugins_*``: broken ``semcodec.codecs`` and ``osnerf.schemes`` plugins (one failing
at import, one calling ``sys.exit(3)``, one taking the built-in name ``jscc``, one named
``de:mo``) installed as a package would be: each named in one warning line, every command
that does not use them works, naming one exits 2 with its load error in one line.
``test_accept_*``: flags that do not apply to the chosen mode or renderer are refused.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import common.plugins
from osnerf.cli import main

ROOT = Path(__file__).resolve().parents[2]

ENTRY_POINTS = """\
[semcodec.codecs]
broken = honest_bad_codec:make
quits = honest_exit_codec:make
jscc = honest_ok:make
de:mo = honest_ok:make

[osnerf.schemes]
badscheme = honest_bad_scheme:Scheme
"""
MODULES = {
    "honest_bad_codec": "raise ImportError('no module named torchvision_x')\n",
    "honest_exit_codec": "import sys\nsys.exit(3)\n",
    "honest_ok": "def make(checkpoint=None):\n    raise RuntimeError('never called')\n",
    "honest_bad_scheme": "raise ImportError('no module named scheme_dep_x')\n",
}
BROKEN = "codec plugin broken = honest_bad_codec:make failed to load (ImportError: no module"
QUITS = "codec plugin quits = honest_exit_codec:make failed to load (SystemExit: 3)"
TAKEN = "codec plugin jscc = honest_ok:make is skipped: jscc is taken by a built-in codec"
COLON = "codec plugin de:mo = honest_ok:make is refused"
SCHEME = "scheme plugin badscheme = honest_bad_scheme:Scheme failed to load (ImportError:"


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """A folder of broken plugins with their dist-info, as ``pip install`` leaves them."""
    site = tmp_path_factory.mktemp("site")
    info = site / "honest_plugins-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: honest-plugins\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    for name, text in MODULES.items():
        (site / f"{name}.py").write_text(text)
    return site


@pytest.fixture
def installed(site, monkeypatch):
    """The broken plugins in this process: the tables read their groups again; afterwards
    they forget them."""
    from osnerf.schemes import SCHEMES
    from semcodec import CODECS

    monkeypatch.setattr(common.plugins, "_warned", set(), raising=False)
    monkeypatch.syspath_prepend(str(site))
    before = [(t, dict(t)) for t in (CODECS, SCHEMES)]
    for table, _ in before:
        table.load_entry_points(force=True)
    yield
    for table, entries in before:
        for name in [n for n in table if n not in entries]:
            table.unregister(name)
        table.broken.clear()
    for name in MODULES:
        sys.modules.pop(name, None)


@pytest.fixture(scope="module")
def image(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("img")
    rng = np.random.default_rng(0)
    pixels = rng.integers(0, 256, (32, 48, 3), dtype=np.uint8)
    Image.fromarray(pixels).save(folder / "a.png")
    return folder


def _osnerf(site: Path, *argv: str, timeout_s: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(site)}
    return subprocess.run(
        [sys.executable, "-m", "osnerf.cli", *argv],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


@pytest.mark.parametrize(
    "argv, named",
    [
        (["--help"], [BROKEN, QUITS, TAKEN, COLON, SCHEME]),
        (["eval-codec", "--help"], [BROKEN, QUITS, TAKEN, COLON]),
        (["ota", "--help"], [BROKEN, QUITS, TAKEN, COLON]),
        (["run", "--help"], [SCHEME]),
    ],
)
def test_plugins_help_exits_0_naming_each_broken_plugin_once(site, argv, named):
    r = _osnerf(site, *argv)
    assert r.returncode == 0, r.stderr
    assert "usage: osnerf" in r.stdout and "Traceback" not in r.stderr
    err = _lines(r.stderr)
    assert all(ln.startswith("osnerf: warning: ") for ln in err), err
    assert len(err) == len(set(err)) == len(named), err
    for text in named:
        assert sum(text in ln for ln in err) == 1, (text, err)


def test_plugins_the_default_codec_evaluates_beside_broken_plugins(site, image, tmp_path):
    out = tmp_path / "r.json"
    argv = ["eval-codec", "--images", str(image), "--snr-db", "10", "--cbr", "1/16"]
    r = _osnerf(site, *argv, "--schemes", "jscc", "--no-lpips", "--out", str(out))
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert doc["results"] and doc["results"][0]["psnr"] > 10.0
    warnings = [ln for ln in _lines(r.stderr) if "warning" in ln]
    assert len(warnings) == 4 and any(BROKEN in ln for ln in warnings), warnings


@pytest.mark.parametrize("codec, text", [("broken", BROKEN), ("quits", QUITS)])
def test_plugins_naming_a_broken_codec_exits_2_with_its_load_error(
    installed, image, tmp_path, capsys, codec, text
):
    for command, extra in (
        ("eval-codec", ["--cbr", "1/16"]),
        ("ota", ["--tx", "emulated", "--rx", "emulated", "--size", "32"]),
    ):
        out = tmp_path / f"{command}.json"
        argv = [command, "--images", str(image), "--snr-db", "10", "--schemes", "jscc", *extra]
        assert main([*argv, "--codec", codec, "--out", str(out)]) == 2
        last = _lines(capsys.readouterr().err)[-1]
        assert last.startswith(f"osnerf {command}: error: ") and text in last
        assert not out.exists() and list(tmp_path.iterdir()) == []


def test_plugins_ota_runs_the_default_codec_beside_broken_plugins(installed, image, tmp_path):
    out = tmp_path / "ota.json"
    argv = ["ota", "--tx", "emulated", "--rx", "emulated", "--schemes", "jscc", "--snr-db", "15"]
    argv += ["--images", str(image), "--size", "32", "--symbols-per-frame", "1024"]
    assert main([*argv, "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["results"]
    assert rows and rows[0]["psnr"] > 10.0


def test_plugins_naming_a_broken_scheme_exits_2_with_its_load_error(installed, tmp_path, capsys):
    from osnerf.run.config import RunConfig

    out = tmp_path / "run"
    assert main(["run", "--schemes", "gt,badscheme", "--out", str(out)]) == 2
    last = _lines(capsys.readouterr().err)[-1]
    assert last.startswith("osnerf run: error: argument --schemes") and SCHEME in last
    assert not out.exists()
    with pytest.raises(ValueError, match="scheme plugin badscheme = honest_bad_scheme:Scheme"):
        RunConfig(schemes=("gt", "badscheme"))
    assert RunConfig(schemes=("gt",)).schemes == ("gt",)


def test_plugins_a_sweep_runs_beside_broken_plugins(installed, image, tmp_path):
    spec = tmp_path / "ec.yaml"
    spec.write_text(
        "command: eval-codec\n"
        f"fixed: {{images: {image}, schemes: jscc, cbr: 1/16, no_lpips: true}}\n"
        "axes: {snr_db: [5, 10]}\nseeds: [0]\n"
    )
    out = tmp_path / "ec.jsonl"
    assert main(["sweep", str(spec), "--out", str(out), "--executor", "serial"]) == 0
    rows = [json.loads(ln) for ln in out.read_text().splitlines()]
    assert len(rows) == 2


def test_accept_fault_after_samples_needs_a_fault(tmp_path):
    """Refused before the board serves (accepted, it would serve until SIGINT)."""
    argv = ["hil", "emulate", "pluto", "--port", "0", "--fault-after-samples", "10"]
    try:
        r = _osnerf(tmp_path, *argv, timeout_s=60)
    except subprocess.TimeoutExpired:
        pytest.fail("hil emulate accepted --fault-after-samples without --fault and served")
    err = _lines(r.stderr)
    assert r.returncode == 2 and len(err) == 1, r.stderr
    assert "--fault-after-samples" in err[0] and "--fault " in err[0]


@pytest.mark.parametrize(
    "flag",
    [["--snr-db", "5"], ["--fault", "drop"], ["--fault-after-samples", "10"], ["--port", "1"]],
)
def test_accept_hil_info_takes_no_option_of_emulate(capsys, flag):
    assert main(["hil", "info", "--emulate", *flag]) == 2
    err = _lines(capsys.readouterr().err)
    assert len(err) == 1 and "unrecognized arguments" in err[0] and flag[0] in err[0]


def test_accept_render_refuses_renderer_steps_for_the_full_renderer(tmp_path, capsys):
    model = tmp_path / "model.pt"
    model.write_bytes(b"never read: the flags are refused first")
    out = tmp_path / "r"
    argv = ["render", "--run", str(model), "--out", str(out), "--renderer", "full"]
    assert main([*argv, "--renderer-steps", "5"]) == 2
    err = _lines(capsys.readouterr().err)
    assert len(err) == 1 and "--renderer-steps applies only to a learned renderer" in err[0]
    assert "--renderer full" in err[0] and not out.exists()


def test_accept_render_records_no_seed_for_the_full_renderer(tmp_path):
    """The full renderer draws nothing: a seed (sweeps pass one to every point) is not
    recorded as if it shaped the views."""
    from renderer import load_dataset, save_model
    from tests.renderer.sphere_scene import exact_sphere_field, write_sphere_dataset

    data = write_sphere_dataset(tmp_path / "sphere")
    model = save_model(exact_sphere_field(load_dataset(data, "train")), tmp_path / "model.pt")
    out = tmp_path / "r"
    argv = ["render", "--run", str(model), "--out", str(out), "--num-views", "1"]
    assert main([*argv, "--resolution", "16", "--video", "none", "--seed", "5"]) == 0
    record = json.loads((out / "render.json").read_text())
    assert record["config"]["seed"] is None and record["seed"] is None
    assert record["config"]["renderer"] == "full" and record["config"]["renderer_steps"] is None
