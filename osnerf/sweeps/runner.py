"""Run a sweep: expand the spec, skip finished points, execute the rest, append each result.

Each point runs ``osnerf.cli.main([command, *argv, "--out", TMP])`` in a worker (in-process,
a spawned process of a ``concurrent.futures`` pool, or a Ray task), and the worker returns
the command's result JSON. The driver extracts the metrics (:mod:`osnerf.sweeps.metrics`)
and appends one line per finished point to the results file (:mod:`osnerf.sweeps.store`).
Failed points are not written there: they go to ``<out>.errors.jsonl`` and are retried by
the next run of the same spec. A point whose command rejects its arguments (exit 2: a value
its parser accepted but the command does not) stops the sweep with a ValueError: the spec
is wrong, and every other point with that value would fail the same way.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import multiprocessing
import os
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from osnerf.sweeps.metrics import metric_rule
from osnerf.sweeps.spec import Point, SweepSpec, command_options, command_parser, expand, point_key
from osnerf.sweeps.store import append_record, open_results

Task = dict[str, Any]  # plain data, picklable: what a worker needs to run one point
Outcome = dict[str, Any]  # {"ok", "result", "error", "seconds"}


def _error_line(stderr: str, command: str) -> str | None:
    """The command's one-line error (``osnerf X: error: ...``) from its stderr, without the
    progress-bar redraws (``\r``-separated) that may follow it; else the last other line."""
    lines = [ln.strip() for ln in stderr.replace("\r", "\n").splitlines() if ln.strip()]
    ours = [ln for ln in lines if ln.startswith(f"osnerf {command}:")]
    return (ours or lines or [None])[-1]


def execute_point(task: Task) -> Outcome:
    """Run one point in this process and return its outcome (never raises).

    Args:
        task: ``{"command", "module", "argv", "out_kind", "json_name", "threads", "keep",
            "slug"}``; ``module`` is the command's module from the driver's
            ``osnerf.cli.COMMANDS``, so a worker runs exactly the command the driver
            validated; ``keep`` (or None) is a folder where the point's output is copied as
            ``<slug>`` (``<slug>.json`` for a file).
    Returns:
        ``{"ok": bool, "result": dict | None, "error": str | None, "seconds": float,
        "kept": str | None}``, and ``"rc"`` (the command's exit code) when it failed.
    Raises:
        KeyboardInterrupt: the command was interrupted (the sweep stops).
    """
    import osnerf.cli

    t0 = time.perf_counter()
    if task.get("threads"):
        n = str(task["threads"])
        for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
            os.environ[var] = n
        import torch

        torch.set_num_threads(int(task["threads"]))
    osnerf.cli.COMMANDS.setdefault(task["command"], (task["module"], task["command"]))
    err = io.StringIO()
    with tempfile.TemporaryDirectory(prefix="osnerf-sweep-") as tmp:
        out = Path(tmp) / ("result.json" if task["out_kind"] == "file" else "run")
        try:
            with contextlib.redirect_stderr(err):
                rc = osnerf.cli.main([task["command"], *task["argv"], "--out", str(out)])
        except KeyboardInterrupt:
            raise
        except BaseException as e:  # noqa: BLE001 - SystemExit from a command, for example
            rc, msg = 1, f"{type(e).__name__}: {e}"
        else:
            msg = _error_line(err.getvalue(), task["command"]) or f"exit code {rc}"
        if rc == 130:  # osnerf.cli's code for an interrupted command: stop the sweep too
            raise KeyboardInterrupt
        seconds = time.perf_counter() - t0
        if rc != 0:
            return {
                "ok": False,
                "result": None,
                "error": f"exit {rc}: {msg}",
                "seconds": seconds,
                "rc": rc,
            }
        path = out if task["out_kind"] == "file" else out / task["json_name"]
        try:
            result = json.loads(path.read_text())
        except (OSError, ValueError) as e:
            return {
                "ok": False,
                "result": None,
                "seconds": seconds,
                "error": f"the command succeeded but its result {path.name} is unreadable: {e}",
            }
        kept = None
        if task.get("keep"):  # copy the point's own output (views, report) before tmp goes
            kept = Path(task["keep"]) / (
                task["slug"] + (".json" if task["out_kind"] == "file" else "")
            )
            kept.parent.mkdir(parents=True, exist_ok=True)
            if task["out_kind"] == "file":
                shutil.copy2(out, kept)
            else:
                shutil.copytree(out, kept, dirs_exist_ok=True)
    return {
        "ok": True,
        "result": result,
        "error": None,
        "seconds": seconds,
        "kept": kept and str(kept),
    }


# --- executors: (tasks, workers, options) -> (key, outcome) in completion order ---------------


def _serial(tasks: list[tuple[str, Task]], workers: int, **_: Any) -> Iterator[tuple[str, Outcome]]:
    for key, task in tasks:
        yield key, execute_point(task)


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _die_with_parent(parent_pid: int, poll_s: float = 0.5) -> None:
    """Pool initializer: this worker dies when the sweep that started it dies.

    A sweep killed with SIGKILL cannot shut its pool down; its workers would run on (and
    block forever writing a result nobody reads). Linux sends SIGKILL on the parent's death
    (``prctl(PR_SET_PDEATHSIG)``); a watchdog thread covers other systems and the window
    before the call, exiting as soon as the parent process is no longer ``parent_pid``.
    """
    import signal
    import threading

    if sys.platform.startswith("linux"):
        import ctypes

        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the watchdog alone
            pass

    def orphaned() -> bool:
        return os.getppid() != parent_pid

    if orphaned():  # the parent died before prctl took effect
        os._exit(1)

    def watch() -> None:
        while not orphaned():
            time.sleep(poll_s)
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="sweep-parent-watchdog", daemon=True).start()


def _local(tasks: list[tuple[str, Task]], workers: int, **_: Any) -> Iterator[tuple[str, Outcome]]:
    ctx = multiprocessing.get_context("spawn")  # fork after torch/OpenMP threads is unsafe
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=ctx,
        initializer=_die_with_parent,
        initargs=(os.getpid(),),
    )
    try:
        futures = {pool.submit(execute_point, task): key for key, task in tasks}
        for fut in as_completed(futures):
            try:
                outcome = fut.result()
            except Exception as e:  # noqa: BLE001 - a worker died (BrokenProcessPool, ...)
                outcome = {
                    "ok": False,
                    "result": None,
                    "error": f"worker failed: {type(e).__name__}: {e}",
                    "seconds": 0.0,
                }
            yield futures[fut], outcome
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _ray(
    tasks: list[tuple[str, Task]],
    workers: int,
    ray_address: str | None = None,
    ray_runtime_env: dict | None = None,
    **_: Any,
) -> Iterator[tuple[str, Outcome]]:
    try:
        import ray
    except ImportError:
        raise ValueError(
            "--executor ray needs the 'ray' package: pip install 'osnerf[ray]'"
        ) from None
    started = False
    if not ray.is_initialized():
        kwargs: dict[str, Any] = {
            "address": ray_address,
            "include_dashboard": False,
            "runtime_env": ray_runtime_env,
            "log_to_driver": False,
        }
        if ray_address is None and not os.environ.get("RAY_ADDRESS"):
            kwargs["num_cpus"] = workers  # a local instance sized like the local pool
        ray.init(**kwargs)
        started = True
    remote = ray.remote(num_cpus=1)(execute_point)
    refs = {remote.remote(task): key for key, task in tasks}
    pending = list(refs)
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                try:
                    outcome = ray.get(ref)
                except Exception as e:  # noqa: BLE001 - a task or its worker died
                    outcome = {
                        "ok": False,
                        "result": None,
                        "seconds": 0.0,
                        "error": f"ray task failed: {type(e).__name__}: {str(e).splitlines()[0]}",
                    }
                yield refs[ref], outcome
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()


EXECUTORS: dict[str, Callable[..., Iterator[tuple[str, Outcome]]]] = {
    "local": _local,
    "ray": _ray,
    "serial": _serial,
}


def get_executor(name: str) -> Callable[..., Iterator[tuple[str, Outcome]]]:
    if name not in EXECUTORS:
        raise KeyError(f"unknown executor {name!r}; known: {sorted(EXECUTORS)}")
    return EXECUTORS[name]


@dataclass
class SweepSummary:
    """What one run of a sweep did.

    Attributes:
        total: points in the spec.
        skipped: points already in the results file (not run again).
        finished: points run and appended now.
        failed: ``(point values, seed, error)`` of points that failed now (retried next run).
    """

    total: int
    skipped: int
    finished: int = 0
    failed: list[tuple[dict[str, Any], int | None, str]] = field(default_factory=list)


def point_slug(p: Point) -> str:
    """A file name for a point: ``snr_db=0_mode=a_seed=0-<8 hex of its key>``."""
    text = "_".join(f"{k}={v}" for k, v in p.values.items()) + f"_seed={p.seed}"
    text = re.sub(r"[^A-Za-z0-9.=+-]+", "-", text).strip("-")[:80]
    return f"{text}-{hashlib.sha256(p.key.encode()).hexdigest()[:8]}"


def errors_path(out: str | Path) -> Path:
    out = Path(out)
    return out.with_name(out.name + ".errors.jsonl")


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    executor: str = "local",
    workers: int | None = None,
    progress: bool = True,
    ray_address: str | None = None,
    ray_runtime_env: dict | None = None,
    keep: str | Path | None = None,
) -> SweepSummary:
    """Run every point of ``spec`` not yet in ``out``; append each as it finishes.

    Args:
        spec: the sweep.
        out: results file (JSON Lines); created if absent, repaired if its last line is torn.
        executor: "local" (process pool), "ray", or "serial" (in this process, for debugging).
        workers: parallel points (default: half the CPU cores, at least 1).
        ray_address: Ray cluster address for ``executor="ray"`` (None: ``$RAY_ADDRESS`` or a
            local instance).
        ray_runtime_env: Ray runtime environment for the tasks (e.g. ``env_vars``).
        keep: folder where each finished point's own output (its JSON file, or its run
            folder with views and report) is kept as ``<slug>``; recorded in the line as
            ``"output"``. None: outputs are deleted. On a cluster it must be a path every
            worker can write.
    Raises:
        ValueError / KeyError: a bad spec, executor or results file, before anything runs.
        ValueError: during the run, a point's command refused its input (exit 2); the
            points finished before are kept.
    """
    run_executor = get_executor(executor)
    points = expand(spec)
    if "out" not in command_options(command_parser(spec.command)):
        raise ValueError(
            f"command {spec.command!r} has no --out option: a sweep point needs its JSON result"
        )
    cpus = os.cpu_count() or 1
    workers = max(1, cpus // 2) if workers is None else workers
    if workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    rule = metric_rule(spec.command)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with _exclusive(out):
        return _run_points(
            spec,
            points,
            out,
            rule,
            executor,
            run_executor,
            workers,
            cpus,
            progress,
            ray_address,
            ray_runtime_env,
            keep,
        )


@contextlib.contextmanager
def _exclusive(out: Path):
    """Hold ``<out>.lock`` (flock) while a sweep writes ``out``: two sweeps on one file refuse."""
    import fcntl

    lock = out.with_name(out.name + ".lock")
    with open(lock, "w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ValueError(
                f"--out {str(out)!r}: another sweep is writing it (lock {lock.name} is held); "
                "wait for it or use another --out"
            ) from None
        yield  # closing the file releases the lock


def _run_points(
    spec,
    points,
    out,
    rule,
    executor,
    run_executor,
    workers,
    cpus,
    progress,
    ray_address,
    ray_runtime_env,
    keep,
) -> SweepSummary:
    from osnerf.cli import COMMANDS
    from osnerf.provenance import git_commit

    done = {point_key(r["point"], r.get("seed")) for r in open_results(out, spec.sha256)}
    todo: list[Point] = [p for p in points if p.key not in done]
    summary = SweepSummary(total=len(points), skipped=len(points) - len(todo))
    errors = errors_path(out)
    if errors.exists():
        errors.unlink()  # failures of an earlier run are retried now
    if not todo:
        return summary
    threads = max(1, cpus // workers) if executor == "local" else None  # Ray sets its own
    by_key = {p.key: p for p in todo}
    tasks = [
        (
            p.key,
            {
                "command": spec.command,
                "module": COMMANDS[spec.command][0],
                "argv": list(p.argv),
                "out_kind": rule.out_kind,
                "json_name": rule.json_name,
                "threads": threads,
                "keep": str(Path(keep).resolve()) if keep else None,
                "slug": point_slug(p),
            },
        )
        for p in todo
    ]
    from tqdm import tqdm

    stream = run_executor(tasks, workers, ray_address=ray_address, ray_runtime_env=ray_runtime_env)
    bar = tqdm(
        total=len(points),
        initial=summary.skipped,
        unit="point",
        desc=f"sweep {spec.command}",
        disable=not progress,
        file=sys.stderr,
        dynamic_ncols=True,
    )
    try:
        for key, outcome in stream:
            p = by_key[key]
            if outcome["ok"]:
                result = outcome["result"]
                try:
                    metrics = rule.extract(result)
                except (KeyError, IndexError, TypeError) as e:
                    outcome = {
                        **outcome,
                        "ok": False,
                        "error": f"result of `osnerf {spec.command}` lacks the field {e} its metric rule reads",
                    }
            if outcome["ok"]:
                append_record(
                    out,
                    {
                        "point": p.values,
                        "config": result.get("config"),
                        "seed": p.seed,
                        "git_commit": result.get("git_commit") or git_commit(),
                        "metrics": metrics,
                        "seconds": outcome["seconds"],
                        "command": spec.command,
                        "argv": list(p.argv),
                        "spec_hash": spec.sha256,
                        "versions": result.get("versions"),
                        "output": outcome.get("kept"),
                        "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
                    },
                )
                summary.finished += 1
            else:
                summary.failed.append((p.values, p.seed, outcome["error"]))
                append_record(
                    errors,
                    {
                        "point": p.values,
                        "seed": p.seed,
                        "error": outcome["error"],
                        "seconds": outcome["seconds"],
                        "spec_hash": spec.sha256,
                    },
                )
                bar.write(
                    f"osnerf sweep: point {p.values} seed {p.seed} failed: {outcome['error']}",
                    file=sys.stderr,
                )
                if outcome.get("rc") == 2:  # bad input: every other point would fail the same
                    raise ValueError(
                        f"point {p.values} seed {p.seed}: `osnerf {spec.command}` refused its "
                        f"input (exit 2: {outcome['error'].partition(': ')[2]}); fix the spec "
                        "or the input (finished points are kept)"
                    )
            bar.update(1)
    finally:
        stream.close()  # stop the executor now (cancel what has not started)
        bar.close()
    return summary
