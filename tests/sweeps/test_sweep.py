"""The sweep runner: spec validation, resume after a failure or a kill, torn-line repair, executors.

Runs against a stand-in command (tests/sweeps/sweep_fake_command.py) registered in
osnerf.cli.COMMANDS for the test, whose metric is a known function of its options and seed.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
import sweep_fake_command as fake

import osnerf.cli
import osnerf.sweeps.metrics
from osnerf.sweeps import (
    METRIC_RULES,
    MetricRule,
    append_record,
    errors_path,
    expand,
    load_spec,
    open_results,
    read_results,
    run_sweep,
    spec_from_dict,
)

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent


def _with_command(monkeypatch, name, entry):
    """osnerf.cli.COMMANDS with ``name`` added, for this test only."""
    from common import Registry

    table = Registry("command", {**osnerf.cli.COMMANDS, name: entry})
    monkeypatch.setattr(osnerf.cli, "COMMANDS", table)


@pytest.fixture(autouse=True)
def fake_command(monkeypatch):
    _with_command(monkeypatch, fake.NAME, fake.ENTRY)


def _spec(tmp_path, **over):
    d = {
        "command": "fake",
        "fixed": {"log": str(tmp_path / "calls.log")},
        "axes": {"snr_db": [0, 5, 10], "mode": ["a", "b"]},
        "seeds": [0, 1],
    }
    d.update(over)
    return spec_from_dict(d)


def _write_yaml(path: Path, d: dict) -> Path:
    import yaml

    path.write_text(yaml.safe_dump(d))
    return path


def _calls(tmp_path) -> Counter:
    log = tmp_path / "calls.log"
    lines = log.read_text().splitlines() if log.exists() else []
    return Counter(tuple(line.split()[:3]) for line in lines)


def _check_complete(out: Path, spec) -> list[dict]:
    """Every point of the spec exactly once, each with the metric the command must report."""
    records = read_results(out)
    keys = Counter((json.dumps(r["point"], sort_keys=True), r["seed"]) for r in records)
    assert len(records) == spec.num_points
    assert set(keys.values()) == {1}
    for r in records:
        want = fake.expected_value(
            float(r["point"]["snr_db"]), r["point"].get("mode", "a"), r["seed"]
        )
        assert r["metrics"]["results"][0]["value"] == pytest.approx(want, abs=0, rel=1e-15)
        assert r["spec_hash"] == spec.sha256
        assert r["git_commit"]
        assert r["config"]["mode"] == r["point"].get("mode", "a")
    return records


def _metrics_by_point(path: Path) -> dict:
    return {
        (json.dumps(r["point"], sort_keys=True), r["seed"]): r["metrics"]
        for r in read_results(path)
    }


# --- spec -----------------------------------------------------------------------------------


def test_expand_is_the_cartesian_product_with_each_points_command_line(tmp_path):
    spec = _spec(tmp_path, fixed={"verbose": True, "sleep-s": 0})
    points = expand(spec)
    assert spec.num_points == len(points) == 3 * 2 * 2
    assert [(p.values["snr_db"], p.values["mode"], p.seed) for p in points[:4]] == [
        (0, "a", 0),
        (0, "a", 1),
        (0, "b", 0),
        (0, "b", 1),
    ]
    assert points[0].argv == (
        "--verbose",
        "--sleep-s",
        "0",
        "--snr-db",
        "0",
        "--mode",
        "a",
        "--seed",
        "0",
    )
    assert len({p.key for p in points}) == len(points)
    # a false flag is left off the command line
    assert "--verbose" not in expand(_spec(tmp_path, fixed={"verbose": False}))[0].argv


def test_yaml_and_toml_specs_read_the_same(tmp_path):
    y = _write_yaml(
        tmp_path / "s.yaml", {"command": "fake", "axes": {"snr_db": [1, 2]}, "seeds": [3]}
    )
    t = tmp_path / "s.toml"
    t.write_text('command = "fake"\nseeds = [3]\n[axes]\nsnr_db = [1, 2]\n')
    assert load_spec(y) == load_spec(t)
    assert load_spec(y).sha256 == load_spec(t).sha256
    assert spec_from_dict({"command": "fake", "axes": {"snr_db": [1]}, "seeds": 3}).seeds == (
        0,
        1,
        2,
    )


@pytest.mark.parametrize(
    "over, match",
    [
        (
            {"axes": {"snr_db": [0], "bogus": [1]}},
            r"unknown option 'bogus' in 'axes'.*allowed: \[.*'mode'",
        ),
        ({"axes": {"snr_db": [0], "mode": ["a", "c"]}}, r"'mode': 'c'.*invalid choice: 'c'"),
        (
            {"axes": {"snr_db": ["loud"]}},
            r"point \{'snr_db': 'loud'\}.*--snr-db: invalid float value",
        ),
        ({"axes": {"snr_db": []}}, r"empty sweep: axis 'snr_db' has no values"),
        ({"seeds": []}, r"empty sweep: 'seeds' has no values"),
        ({"axes": {"snr_db": [0]}, "seeds": 0}, r"empty sweep"),
        ({"axes": {"snr_db": [0], "seed": [1]}}, r"'seed' in 'axes' is set by the sweep itself"),
        ({"axes": {"snr_db": [0]}, "fixed": {"out": "x"}}, r"'out' in 'fixed' is set by the sweep"),
        ({"axes": {"mode": ["a"]}, "fixed": {}}, r"required: --snr-db"),
        ({"axes": {"snr_db": [0]}, "fixed": {"snr_db": 1}}, r"both 'fixed' and 'axes'"),
        (
            {"axes": {"snr_db": [0]}, "fixed": {"verbose": "yes"}},
            r"'verbose' is a flag: .* true or false",
        ),
        ({"axes": {"snr_db": [0]}, "seeds": [1.5]}, r"'seeds' must hold integers"),
        (
            {"axes": {"snr_db": [0, 5, 0.0]}},
            r"points \{'snr_db': 0\} and \{'snr_db': 0.0\} .* parse to the same command line",
        ),
    ],
)
def test_bad_specs_fail_before_anything_runs(tmp_path, over, match):
    with pytest.raises(ValueError, match=match):
        run_sweep(_spec(tmp_path, **over), tmp_path / "r.jsonl", executor="serial", progress=False)
    assert not (tmp_path / "r.jsonl").exists()
    assert not (tmp_path / "calls.log").exists()


def test_unknown_command_and_spec_fields_list_the_allowed_ones(tmp_path):
    with pytest.raises(KeyError, match=r"unknown command 'nope'.*known: \[.*'ber'"):
        expand(spec_from_dict({"command": "nope"}))
    with pytest.raises(
        ValueError, match=r"unknown spec field\(s\) \['axis'\]; allowed: \['command'"
    ):
        spec_from_dict({"command": "fake", "axis": {}})
    bad = tmp_path / "bad.yaml"
    bad.write_text("command: fake\naxes: {snr_db: [0, 1\n")
    with pytest.raises(ValueError, match=r"bad.yaml: not valid YAML"):
        load_spec(bad)
    with pytest.raises(ValueError, match=r"must end in .yaml, .yml or .toml"):
        load_spec(_write_yaml(tmp_path / "s.json", {"command": "fake"}))


def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    spec = _write_yaml(
        tmp_path / "s.yaml", {"command": "fake", "axes": {"snr_db": [0], "volume": [1]}}
    )
    out = tmp_path / "r.jsonl"
    assert osnerf.cli.main(["sweep", str(spec), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown option 'volume'" in err[0] and "allowed:" in err[0]
    assert osnerf.cli.main(["sweep", str(tmp_path / "missing.yaml"), "--out", str(out)]) == 2
    assert "no such file" in capsys.readouterr().err
    assert osnerf.cli.main(["sweep", str(spec), "--out", str(out), "--executor", "slurm"]) == 2
    assert not out.exists()


def test_a_value_only_the_command_rejects_stops_the_sweep_with_its_message(tmp_path, capsys):
    """argparse cannot see every bad value: the command's own exit 2 stops the sweep at once."""
    spec = _spec(tmp_path, axes={"level": ["low", "loud", "high"]}, fixed={"snr_db": 1}, seeds=[0])
    out = tmp_path / "r.jsonl"
    with pytest.raises(
        ValueError,
        match=r"point \{'level': 'loud'\} seed 0: `osnerf fake` refused its input \(exit 2: "
        r"osnerf fake: error: --level must be one of low, high; got 'loud'\)",
    ):
        run_sweep(spec, out, executor="serial", progress=False)
    assert [r["point"] for r in read_results(out)] == [{"level": "low"}]  # kept; 'high' never ran
    yml = _write_yaml(tmp_path / "s.yaml", spec.to_dict())
    assert (
        osnerf.cli.main(
            ["sweep", str(yml), "--out", str(out), "--no-progress", "--executor", "serial"]
        )
        == 2
    )
    assert "refused its input" in capsys.readouterr().err.strip().splitlines()[-1]


def test_error_records_say_how_each_point_failed_without_progress_bar_text(tmp_path, capsys):
    """A point that fails at run time (exit 1) is recorded as failed and the sweep goes on; a
    point whose input is refused (exit 2) stops it. Each record holds the command's one-line
    error, never the progress bar the command left drawn on stderr."""
    spec = _write_yaml(
        tmp_path / "s.yaml",
        {
            "command": "fake",
            "fixed": {"fail_snr_db": 1, "bar": True},
            "axes": {"snr_db": [1, 2], "level": ["loud"]},  # 1: run-time failure; 2: refused
        },
    )
    out = tmp_path / "r.jsonl"
    argv = ["sweep", str(spec), "--out", str(out), "--executor", "serial", "--no-progress"]
    assert osnerf.cli.main(argv) == 2
    records = [json.loads(line) for line in errors_path(out).read_text().splitlines()]
    assert [(r["point"]["snr_db"], r["error"]) for r in records] == [
        (1, "exit 1: osnerf fake: failed: RuntimeError: planned failure at snr_db=1.0"),
        (2, "exit 2: osnerf fake: error: --level must be one of low, high; got 'loud'"),
    ]
    err = capsys.readouterr().err.strip().splitlines()
    first = next(line for line in err if "'snr_db': 1}" in line)
    assert "failed: exit 1:" in first and "refused" not in first and "reject" not in first
    assert "'snr_db': 2} seed 0: `osnerf fake` refused its input (exit 2: " in err[-1]
    assert "|" not in first + err[-1]


# --- results file ---------------------------------------------------------------------------


def test_results_of_another_spec_are_refused(tmp_path, capsys):
    out = tmp_path / "r.jsonl"
    run_sweep(_spec(tmp_path, axes={"snr_db": [0]}), out, executor="serial", progress=False)
    before = out.read_bytes()
    with pytest.raises(ValueError, match=r"holds results of another sweep spec"):
        run_sweep(_spec(tmp_path, axes={"snr_db": [0, 1]}), out, executor="serial", progress=False)
    spec = _write_yaml(tmp_path / "s.yaml", {"command": "fake", "axes": {"snr_db": [7]}})
    assert osnerf.cli.main(["sweep", str(spec), "--out", str(out), "--no-progress"]) == 2
    assert "another sweep spec" in capsys.readouterr().err
    assert out.read_bytes() == before


def test_two_sweeps_on_one_results_file_refuse(tmp_path):
    import fcntl

    out = tmp_path / "r.jsonl"
    with open(tmp_path / "r.jsonl.lock", "w") as held:  # another sweep holds the lock
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(ValueError, match=r"another sweep is writing it"):
            run_sweep(_spec(tmp_path), out, executor="serial", progress=False)
    assert not out.exists()
    summary = run_sweep(
        _spec(tmp_path, axes={"snr_db": [0]}), out, executor="serial", progress=False
    )
    assert summary.finished == 2  # the lock is free again


def test_a_torn_last_line_is_cut_and_the_sweep_completes(tmp_path):
    spec = _spec(tmp_path)
    out = tmp_path / "r.jsonl"
    run_sweep(
        _spec(tmp_path, axes={"snr_db": [0, 5, 10], "mode": ["a", "b"]}, seeds=[0, 1]),
        out,
        executor="serial",
        progress=False,
    )
    full = out.read_bytes()
    lines = full.splitlines(keepends=True)
    # a crash mid-write: the first 3 lines whole, the 4th cut in the middle
    out.write_bytes(b"".join(lines[:3]) + lines[3][: len(lines[3]) // 2])
    kept = open_results(out, spec.sha256)
    assert len(kept) == 3
    assert out.read_bytes() == b"".join(lines[:3])  # earlier points untouched
    assert (tmp_path / "r.jsonl.torn").read_bytes() == lines[3][: len(lines[3]) // 2] + b"\n"
    summary = run_sweep(spec, out, executor="serial", progress=False)
    assert (summary.skipped, summary.finished, summary.failed) == (3, 9, [])
    _check_complete(out, spec)
    # the three kept points did not run again: twice in total (first run + none now)
    calls = _calls(tmp_path)
    assert sum(calls.values()) == 12 + 9


def test_a_bad_line_before_the_last_is_an_error_not_a_repair(tmp_path):
    out = tmp_path / "r.jsonl"
    out.write_text(
        '{"point": {}, "seed": 0, "spec_hash": "x"}\nnot json\n{"point": {}, "seed": 1}\n'
    )
    with pytest.raises(ValueError, match=r"line 2 is not a valid JSON record and is not the last"):
        open_results(out, "x")


def test_append_writes_whole_lines(tmp_path):
    out = tmp_path / "r.jsonl"
    for i in range(3):
        append_record(out, {"i": i, "x": float("nan") if i == 1 else 0.5})
    assert [json.loads(line)["i"] for line in out.read_text().splitlines()] == [0, 1, 2]
    assert out.read_bytes().endswith(b"\n")


# --- resume ---------------------------------------------------------------------------------


def test_a_failing_point_is_retried_and_the_rerun_completes_each_point_once(tmp_path, capsys):
    flag = tmp_path / "fixed-it"
    spec = _spec(
        tmp_path,
        fixed={"log": str(tmp_path / "calls.log"), "fail_snr_db": 5, "fail_once_flag": str(flag)},
    )
    out = tmp_path / "r.jsonl"
    s1 = run_sweep(spec, out, executor="local", workers=2, progress=False)
    assert (s1.total, s1.skipped, s1.finished, len(s1.failed)) == (12, 0, 8, 4)
    assert all("planned failure at snr_db=5.0" in err for _, _, err in s1.failed)
    assert all(r["point"]["snr_db"] != 5 for r in read_results(out))
    assert len(errors_path(out).read_text().splitlines()) == 4
    flag.touch()
    # through the CLI: the 8 finished points are skipped, the 4 failed ones retried
    yml = _write_yaml(tmp_path / "s.yaml", spec.to_dict())
    assert (
        osnerf.cli.main(
            ["sweep", str(yml), "--out", str(out), "--executor", "serial", "--no-progress"]
        )
        == 0
    )
    assert "4 finished now" in capsys.readouterr().err
    assert not errors_path(out).exists()
    _check_complete(out, spec)
    calls = _calls(tmp_path)
    assert all(n == (2 if snr == "5.0" else 1) for (snr, _, _), n in calls.items())


def test_cli_reports_failed_points_with_exit_1(tmp_path, capsys):
    spec = _write_yaml(
        tmp_path / "s.yaml",
        {"command": "fake", "fixed": {"fail_snr_db": 1}, "axes": {"snr_db": [0, 1]}},
    )
    out = tmp_path / "r.jsonl"
    assert (
        osnerf.cli.main(
            ["sweep", str(spec), "--out", str(out), "--executor", "serial", "--no-progress"]
        )
        == 1
    )
    err = capsys.readouterr().err
    assert "1 failed" in err and "re-run the same command to retry" in err
    assert len(read_results(out)) == 1


def _sweep_process(yml: Path, out: Path, *extra: str, stderr=subprocess.DEVNULL):
    """`osnerf sweep YML --out OUT --no-progress EXTRA...` with the fake command, in a new
    process."""
    argv = ["sweep", str(yml), "--out", str(out), "--no-progress", *extra]
    driver = (
        "import sys, osnerf.cli, sweep_fake_command as f; osnerf.cli.COMMANDS.register(f.NAME, "
        "f.ENTRY); "
        f"sys.exit(osnerf.cli.main({argv!r}))"
    )
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])
    )
    return subprocess.Popen([sys.executable, "-c", driver], env=env, cwd=ROOT, stderr=stderr)


def test_a_sweep_killed_mid_way_resumes_with_every_point_exactly_once(tmp_path):
    spec_d = {
        "command": "fake",
        "fixed": {"log": str(tmp_path / "calls.log"), "sleep_s": 0.4},
        "axes": {"snr_db": [0, 1, 2, 3, 4, 5]},
        "seeds": [0],
    }
    yml = _write_yaml(tmp_path / "s.yaml", spec_d)
    out = tmp_path / "r.jsonl"
    proc = _sweep_process(yml, out, "--executor", "serial", stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if out.exists() and len(out.read_bytes().splitlines()) >= 2:
            break
        assert proc.poll() is None, proc.stderr.read().decode()
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    proc.stderr.close()
    n_before = len(read_results(out))
    assert 2 <= n_before < 6, "the kill must land mid-sweep"
    spec = load_spec(yml)
    summary = run_sweep(spec, out, executor="serial", progress=False)
    assert summary.skipped == n_before and summary.finished == 6 - n_before and not summary.failed
    _check_complete(out, spec)
    calls = _calls(tmp_path)
    assert set(calls) == {(f"{s}.0", "a", "0") for s in range(6)}
    assert sum(calls.values()) <= 7  # at most the point being run when killed ran twice


def _children(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (from /proc; zombies count as dead)."""
    parents = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            state, ppid = stat.rpartition(")")[2].split()[:2]
            if state != "Z":
                parents.setdefault(int(ppid), []).append(int(d.name))
    out, todo = set(), [pid]
    while todo:
        for c in parents.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_a_pool_sweep_killed_with_sigkill_takes_its_workers_along(tmp_path):
    """After kill -9 of `osnerf sweep`, its pool workers and the multiprocessing
    resource_tracker exit too: none runs on, or blocks on a pipe holding its result."""
    log = tmp_path / "calls.log"
    spec_d = {
        "command": "fake",
        "fixed": {"log": str(log), "sleep_s": 1.5},
        "axes": {"snr_db": [0, 1, 2, 3, 4, 5]},
        "seeds": [0],
    }
    yml = _write_yaml(tmp_path / "s.yaml", spec_d)
    out = tmp_path / "r.jsonl"
    proc = _sweep_process(yml, out, "--executor", "local", "--workers", "2")
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # both workers are inside a point
        if log.exists() and len(log.read_text().splitlines()) >= 2:
            break
        assert proc.poll() is None, "the sweep ended before it was killed"
        time.sleep(0.05)
    family = _children(proc.pid)
    workers = {int(line.split()[3]) for line in log.read_text().splitlines()}
    assert workers <= family and len(workers) == 2
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    deadline = time.monotonic() + 20
    while any(_alive(p) for p in family) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [p for p in family if _alive(p)]
    for p in left:  # do not leave them to the machine when the test fails
        os.kill(p, signal.SIGKILL)
    assert not left, "processes of the killed sweep still run 20 s later"
    n_before = len(read_results(out)) if out.exists() else 0
    assert n_before < 6, "the kill must land mid-sweep"
    spec = load_spec(yml)
    summary = run_sweep(spec, out, executor="serial", progress=False)
    assert summary.finished == 6 - n_before and not summary.failed
    _check_complete(out, spec)


def test_ctrl_c_stops_the_sweep_and_keeps_the_finished_points(tmp_path):
    spec = _spec(
        tmp_path,
        axes={"snr_db": [0, 1, 2, 3]},
        fixed={"interrupt_snr_db": 2, "log": str(tmp_path / "calls.log")},
    )
    out = tmp_path / "r.jsonl"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec, out, executor="serial", progress=False)
    assert sorted(r["point"]["snr_db"] for r in read_results(out)) == [0, 0, 1, 1]  # 2 seeds
    assert not any(
        line.startswith("3.0") for line in (tmp_path / "calls.log").read_text().splitlines()
    )


def test_kept_outputs_files_and_run_folders(tmp_path, monkeypatch):
    spec = _spec(tmp_path, axes={"snr_db": [0, 5]}, seeds=[0])
    run_sweep(spec, tmp_path / "f.jsonl", executor="serial", progress=False, keep=tmp_path / "keep")
    for r in read_results(tmp_path / "f.jsonl"):
        kept = json.loads(Path(r["output"]).read_text())
        assert (
            kept["results"] == r["metrics"]["results"]
            and Path(r["output"]).parent == tmp_path / "keep"
        )
    # a command whose --out is a folder: the rule reads metrics.json inside, the folder is kept
    _with_command(monkeypatch, "fake-dir", fake.ENTRY)
    from common import Registry

    rule = MetricRule("dir", lambda d: d["results"][0], "metrics.json")
    rules = Registry("metric rule", {**METRIC_RULES, "fake-dir": rule})
    monkeypatch.setattr(osnerf.sweeps.metrics, "METRIC_RULES", rules)
    spec = spec_from_dict({**spec.to_dict(), "command": "fake-dir"})
    run_sweep(spec, tmp_path / "d.jsonl", executor="serial", progress=False, keep=tmp_path / "keep")
    records = read_results(tmp_path / "d.jsonl")
    assert [r["metrics"]["value"] for r in records] == [
        fake.expected_value(s, "a", 0) for s in (0, 5)
    ]
    for r in records:
        assert (Path(r["output"]) / "view.txt").read_text() == "a rendered view\n"
    assert len({r["output"] for r in records}) == 2


# --- executors ------------------------------------------------------------------------------


def test_the_local_pool_gives_the_serial_results(tmp_path):
    spec = _spec(tmp_path, axes={"snr_db": [0, 5], "mode": ["a", "b"]}, seeds=[0, 7])
    serial, local = tmp_path / "serial.jsonl", tmp_path / "local.jsonl"
    run_sweep(spec, serial, executor="serial", progress=False)
    run_sweep(spec, local, executor="local", workers=2, progress=False)

    assert _metrics_by_point(serial) == _metrics_by_point(local)
    _check_complete(local, spec)


def test_a_local_ray_instance_gives_the_local_results(tmp_path):
    ray = pytest.importorskip("ray")
    spec = _spec(tmp_path, axes={"snr_db": [0, 5], "mode": ["a", "b"]}, seeds=[0, 7])
    local, on_ray = tmp_path / "local.jsonl", tmp_path / "ray.jsonl"
    run_sweep(spec, local, executor="local", workers=2, progress=False)
    run_sweep(
        spec,
        on_ray,
        executor="ray",
        workers=2,
        progress=False,
        ray_runtime_env={"env_vars": {"PYTHONPATH": str(HERE)}},
    )
    assert not ray.is_initialized()  # the sweep shut down the instance it started

    assert _metrics_by_point(local) == _metrics_by_point(on_ray)
    _check_complete(on_ray, spec)
    pids = {line.split()[3] for line in (tmp_path / "calls.log").read_text().splitlines()}
    assert os.getpid() not in {int(p) for p in pids}  # the points ran in worker processes
