"""Resumes are the same run or refused; refusals and early deaths leave nothing behind;
values a command looks up only when it runs are checked first; Ctrl-C stops a Ray sweep
cleanly. Trainings here are a few steps on 16 px crops."""

from __future__ import annotations

import errno
import gc
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import semcodec
from osnerf.cli import main
from osnerf.commands import eval_codec
from osnerf.sweeps import append_record, expand, run_sweep, spec_from_dict

ROOT = Path(__file__).resolve().parents[2]


def _images(folder: Path, n: int, side: int, seed: int) -> Path:
    folder.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    for i in range(n):
        pixels = (rng.random((side, side, 3)) * 255).astype(np.uint8)
        Image.fromarray(pixels).save(folder / f"{i}.png")
    return folder


def _last_line(err: str) -> str:
    """The last thing drawn on stderr (a progress bar ends its draws with \\r)."""
    return [s for s in err.replace("\r", "\n").splitlines() if s.strip()][-1]


# ------------------------------------------------------------------- eval-codec's partial
@pytest.fixture
def interrupted_eval(tmp_path, monkeypatch):
    """An eval-codec run interrupted after its first point: (argv, out, partial, calls)."""
    img = _images(tmp_path / "img", 2, 32, 0)
    out = tmp_path / "r.json"
    argv = ["eval-codec", "--images", str(img), "--snr-db", "1,10", "--schemes", "analog"]
    argv += ["--no-lpips", "--out", str(out)]
    real, calls = eval_codec._point, []

    def point(ctx, scheme, ki, snr, *a):
        calls.append(snr)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(ctx, scheme, ki, snr, *a)

    monkeypatch.setattr(eval_codec, "_point", point)
    assert main(argv) == 130
    calls.clear()
    monkeypatch.setattr(eval_codec, "_point", lambda *a: calls.append(a[3]) or real(*a))
    partial = eval_codec.partial_path(out)
    assert partial.is_file()
    return argv, out, partial, calls


@pytest.mark.parametrize(
    "change, field",
    [(["--seed", "1"], "seed"), (["--cbr", "1/8"], "cbr"), (["--max-images", "1"], "image_names")],
)
def test_resumes_eval_codec_keeps_another_evaluations_partial_unless_overwrite(
    interrupted_eval, capsys, change, field
):
    argv, out, partial, calls = interrupted_eval
    before = partial.read_bytes()
    capsys.readouterr()
    assert main(argv + change) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and field in err and "--overwrite" in err, err
    assert partial.read_bytes() == before and not out.exists() and calls == []
    assert main(argv + change + ["--overwrite"]) == 0
    assert calls == [1.0, 10.0]  # nothing of the other evaluation was taken over
    doc = json.loads(out.read_text())
    assert [r["snr_db"] for r in doc["results"]] == [1.0, 10.0] and not partial.exists()


def test_resumes_eval_codec_same_arguments_still_resume(interrupted_eval):
    argv, out, partial, calls = interrupted_eval
    assert main(argv) == 0 and calls == [10.0]


@pytest.mark.parametrize("kind", ["fifo", "folder"])
def test_leftovers_eval_codec_partial_that_is_no_file_is_refused_before_any_work(
    tmp_path, monkeypatch, capsys, kind
):
    img = _images(tmp_path / "img", 1, 32, 0)
    out = tmp_path / "r.json"
    partial = eval_codec.partial_path(out)
    os.mkfifo(partial) if kind == "fifo" else partial.mkdir()
    calls = []
    monkeypatch.setattr(eval_codec, "_point", lambda *a: calls.append(a) or {})
    argv = ["eval-codec", "--images", str(img), "--snr-db", "1", "--schemes", "analog"]
    assert main(argv + ["--no-lpips", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "r.json.partial" in err and "not a regular" in err
    assert calls == [] and not out.exists()


# ------------------------------------------------------------------ train-codec's resumes
TRAIN = ["--model", "adjscc_s4_w64", "--crop-px", "16", "--batch-size", "2", "--threads", "1"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A finished 2-step training: (root with data folders, its folder, its argv)."""
    root = tmp_path_factory.mktemp("train")
    for name, seed in (("data", 0), ("data2", 1), ("val", 2)):
        _images(root / name, 2, 40, seed)
    argv = ["train-codec", "--data", str(root / "data"), "--val", str(root / "val"), *TRAIN]
    argv += ["--max-steps", "2"]
    assert main([*argv, "--out", str(root / "run")]) == 0
    return root, root / "run", argv


@pytest.fixture
def run_copy(trained, tmp_path):
    root, run, argv = trained
    out = tmp_path / "run"
    shutil.copytree(run, out)
    return root, out, [*argv, "--out", str(out)]


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.mark.parametrize(
    "change, flag",
    [
        (["--lr", "0.002"], "--lr"),
        (["--seed", "1"], "--seed"),
        (["--batch-size", "4"], "--batch-size"),
        (["--crop-px", "20"], "--crop-px"),
        (["--channel", "rayleigh"], "--channel"),
        ("data2", "--data"),
    ],
)
def test_resumes_train_codec_refuses_a_changed_argument_naming_it(run_copy, capsys, change, flag):
    root, out, argv = run_copy
    if change == "data2":
        argv = [a if a != str(root / "data") else str(root / "data2") for a in argv]
        change = []
    before = _files(out)
    capsys.readouterr()
    assert main(argv + change) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"changes {flag} (" in err, err
    assert _files(out) == before


def test_resumes_train_codec_records_more_steps_as_history(run_copy):
    _, out, argv = run_copy
    argv = [*argv[: argv.index("--max-steps")], *argv[argv.index("--max-steps") + 2 :]]
    assert main([*argv, "--max-steps", "4", "--save-every-s", "1000"]) == 0
    card = semcodec.load_codec(out / "last.safetensors").card
    assert card["training"]["steps"] == 4 and card["training"]["config"]["max_steps"] == 4
    assert card["resumes"] == [
        {"step": 2, "changed": {"max_steps": [2, 4], "save_every_s": [180.0, 1000.0]}}
    ]


def test_resumes_train_codec_refuses_fewer_steps_than_taken(run_copy, capsys):
    _, out, argv = run_copy
    before = _files(out)
    capsys.readouterr()
    assert main([*argv, "--max-steps", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("osnerf train-codec: error: --max-steps 1 is below the 2 steps"), err
    assert _files(out) == before


def test_resumes_train_codec_finished_run_again_changes_nothing(run_copy, capsys):
    _, out, argv = run_copy
    before = _files(out)
    assert main(argv) == 0
    assert "nothing to do" in capsys.readouterr().err
    assert _files(out) == before


def test_resumes_train_codec_overwrite_starts_over(run_copy):
    _, out, argv = run_copy
    old = semcodec.training.load_train_state(out / "last_state.pt")["model"]
    assert main([*argv, "--lr", "0.002", "--overwrite"]) == 0
    card = semcodec.load_codec(out / "last.safetensors").card
    assert card["training"]["config"]["lr"] == 0.002 and card["training"]["steps"] == 2
    assert "resumes" not in card
    state = semcodec.training.load_train_state(out / "last_state.pt")
    assert state["step"] == 2 and state["config"]["lr"] == 0.002
    # two new steps from the first weights at the new lr, not the old run's weights
    assert any(not (state["model"][k] == v).all() for k, v in old.items())


def test_leftovers_train_codec_dying_before_its_first_checkpoint(trained, tmp_path, capsys):
    import common.files

    root, _, argv = trained
    out = tmp_path / "run"
    real = common.files._write_file

    def full_disk(path, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    common.files._write_file = full_disk
    try:
        rc = main([*argv, "--out", str(out)])
    finally:
        common.files._write_file = real
    gc.collect()  # an open progress bar would redraw itself when collected
    err = capsys.readouterr().err
    assert rc == 1 and "No space left on device" in err
    assert _last_line(err).startswith("osnerf train-codec: failed: OSError"), err[-300:]
    assert not out.exists()
    assert main([*argv, "--out", str(out)]) == 0  # nothing blocks the rerun


@pytest.mark.parametrize("backend", ["nccl", "gloo"])
def test_accept_ddp_backend_outside_torchrun_is_refused(
    trained, tmp_path, capsys, monkeypatch, backend
):
    monkeypatch.delenv("WORLD_SIZE", raising=False)
    _, _, argv = trained
    out = tmp_path / "run"
    assert main([*argv, "--ddp-backend", backend, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--ddp-backend {backend}" in err, err
    assert not out.exists()


# --------------------------------------------------------------------------------- sweeps
@pytest.mark.parametrize(
    "command, axes, where",
    [
        ("eval-codec", {"codec": ["jscc", "nosuch"]}, "axis 'codec' value 'nosuch'"),
        ("eval-codec", {"channel": ["awgn", "nope"]}, "axis 'channel' value 'nope'"),
        ("eval-codec", {"schemes": [["jscc", "bogus"]]}, "axis 'schemes' value 'jscc,bogus'"),
        ("eval-codec", {"mcs": ["16qam-9/10"]}, "axis 'mcs' value '16qam-9/10'"),
        ("train-codec", {"channel": ["awgn,nope"]}, "axis 'channel' value 'awgn,nope'"),
        ("train-codec", {"codec": ["jscc:missing.safetensors"]}, "axis 'codec'"),
        ("render", {"renderer": ["fancy"]}, "axis 'renderer' value 'fancy'"),
    ],
)
def test_accept_sweep_axes_are_checked_against_their_tables_first(tmp_path, command, axes, where):
    fixed = {"images": str(tmp_path)} if command == "eval-codec" else {}
    if command == "render":
        fixed = {"run": str(tmp_path)}
    spec = spec_from_dict({"command": command, "fixed": fixed, "axes": axes, "seeds": [0]})
    with pytest.raises(ValueError, match=f"^{where}"):
        expand(spec)


def test_accept_sweep_good_table_values_pass(tmp_path):
    spec = spec_from_dict(
        {
            "command": "eval-codec",
            "fixed": {"images": str(tmp_path), "schemes": ["jscc", "digital"]},
            "axes": {"codec": ["jscc"], "channel": ["awgn", "rayleigh"], "mcs": ["qpsk-1/2"]},
        }
    )
    assert len(expand(spec)) == 2


def _ber_spec(snrs):
    return spec_from_dict(
        {"command": "ber", "fixed": {"num_bits": 2000}, "axes": {"snr_db": snrs}, "seeds": [0]}
    )


def test_leftovers_sweep_refusal_leaves_no_lock(tmp_path):
    out = tmp_path / "r.jsonl"
    append_record(out, {"point": {"snr_db": 9}, "seed": 0, "spec_hash": "another"})
    before = out.read_bytes()
    with pytest.raises(ValueError, match="another sweep spec"):
        run_sweep(_ber_spec([0]), out, executor="serial", progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.jsonl"]
    assert out.read_bytes() == before
    nowhere = tmp_path / "new" / "r.jsonl"
    with pytest.raises(ValueError, match="axis 'channel'"):
        run_sweep(
            spec_from_dict(
                {
                    "command": "eval-codec",
                    "fixed": {"images": str(tmp_path)},
                    "axes": {"channel": ["nope"]},
                }
            ),
            nowhere,
            executor="serial",
            progress=False,
        )
    assert not nowhere.parent.exists()


def test_leftovers_a_finished_sweep_leaves_no_lock(tmp_path):
    out = tmp_path / "r.jsonl"
    summary = run_sweep(_ber_spec([0, 5]), out, executor="serial", progress=False)
    assert summary.finished == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.jsonl"]


# ------------------------------------------------------------------------------------ Ray
def _tagged(tag: str) -> dict[int, str]:
    """pid -> command line of every process whose environment holds ``tag``."""
    found = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if tag.encode() in (d / "environ").read_bytes():
                found[int(d.name)] = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
    return found


RAY_DRIVER = """
import sys, osnerf.cli
sys.exit(osnerf.cli.main({argv!r}))
"""


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc")
def test_ray_ctrl_c_while_ray_starts_stops_cleanly(tmp_path):
    """Ctrl-C to the sweep's process group while Ray starts (its raylet already up): the usual
    'interrupted' line, exit 130, and no Ray process of this sweep left behind."""
    pytest.importorskip("ray")
    spec = tmp_path / "s.yaml"
    spec.write_text("command: ber\nfixed: {num_bits: 2000}\naxes: {snr_db: [0, 5]}\n")
    argv = ["sweep", str(spec), "--out", str(tmp_path / "r.jsonl"), "--no-progress"]
    argv += ["--executor", "ray", "--workers", "1"]
    tag = f"OSNERF_TEST_{uuid.uuid4().hex}"
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    env |= {"PYTHONPATH": str(ROOT), tag: "1"}
    code = RAY_DRIVER.format(argv=argv)
    proc = subprocess.Popen(
        [sys.executable, "-c", code],
        env=env,
        cwd=ROOT,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if any("raylet" in c for c in _tagged(tag).values()):
                break
            time.sleep(0.05)
        os.killpg(proc.pid, signal.SIGINT)
        err = proc.communicate(timeout=120)[1].decode()
        left = _tagged(tag)
        assert proc.returncode == 130, err[-2000:]
        assert _last_line(err) == "osnerf sweep: interrupted", err[-2000:]
        assert "SIGINT received" not in err and "***" not in err
        assert left == {}, left
    finally:
        for pid in _tagged(tag):
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
