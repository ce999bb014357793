"""Where sweep points run: one worker function (:func:`execute_point`: the command in the
worker's process, with its own temporary ``--out``) and the executors that schedule it
(:data:`EXECUTORS`: this process, a local process pool, or Ray)."""

from __future__ import annotations

import contextlib
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
from pathlib import Path
from typing import Any

import osnerf.cli
from common import Registry

Task = dict[str, Any]  # plain data, picklable: what a worker needs to run one point
Outcome = dict[str, Any]  # {"ok", "result", "error", "seconds"}


_PROGRESS_BAR = re.compile(r"\d+%\|.*\| *\d+(\.\d+)?\S*/\S+ \[")
"""A tqdm bar as drawn on stderr: ``desc:  25%|##5       | 1/4 [00:00<00:00, 9.8it/s]``."""


def _error_line(stderr: str, command: str) -> str | None:
    """The command's one-line error (``osnerf X: error: ...`` / ``osnerf X: failed: ...``)
    from its stderr, without any progress-bar text: a bar left drawn when the command failed
    shares the error's line (tqdm ends a draw with ``\r``, not a newline), and its redraws may
    follow. Without such a line, the last line that is not a progress bar."""
    lines = [ln.strip() for ln in stderr.replace("\r", "\n").splitlines() if ln.strip()]
    tag = f"osnerf {command}:"
    ours = [ln[ln.index(tag) :] for ln in lines if tag in ln]
    others = [ln for ln in lines if not _PROGRESS_BAR.search(ln)]
    return (ours or others or [None])[-1]


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
    t0 = time.perf_counter()
    if task.get("threads"):
        n = str(task["threads"])
        for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
            os.environ[var] = n
        import torch

        torch.set_num_threads(int(task["threads"]))
    if task["command"] not in osnerf.cli.COMMANDS:  # a command the driver registered itself
        osnerf.cli.COMMANDS.register(task["command"], (task["module"], task["command"]))
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
    started = not ray.is_initialized()
    try:
        if started:
            kwargs: dict[str, Any] = {
                "address": ray_address,
                "include_dashboard": False,
                "runtime_env": ray_runtime_env,
                "log_to_driver": False,
            }
            if ray_address is None and not os.environ.get("RAY_ADDRESS"):
                kwargs["num_cpus"] = workers  # a local instance sized like the local pool
            with _sigint_held():  # Ctrl-C while Ray starts: after, then shut down in full
                ray.init(**kwargs)
        yield from _ray_results(ray, tasks)
    finally:
        if started:
            with _sigint_held():  # a second Ctrl-C does not cut the shutdown short
                ray.shutdown()


def _ray_results(ray, tasks: list[tuple[str, Task]]) -> Iterator[tuple[str, Outcome]]:
    """Submit every task to Ray and yield each outcome as it finishes; cancel the rest when
    the caller stops (an error, Ctrl-C, or the generator closed)."""
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
        with _sigint_held():
            for ref in pending:
                ray.cancel(ref, force=True)


@contextlib.contextmanager
def _sigint_held():
    """Hold Ctrl-C while Ray starts or stops, then raise it as the usual KeyboardInterrupt.

    A SIGINT meanwhile is only noted (any thread of this process may take it), and it is
    blocked in the Ray processes started meanwhile (they inherit the mask), so a Ctrl-C to
    the terminal's process group neither cuts ``ray.init`` / ``ray.shutdown`` short nor kills
    Ray's own processes half-way (orphans, their fatal-error traces).
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted: list[int] = []
    handler = signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
        signal.signal(signal.SIGINT, handler)
    if noted:
        raise KeyboardInterrupt


EXECUTORS = Registry[Callable[..., Iterator[tuple[str, Outcome]]]](
    "executor", {"local": _local, "ray": _ray, "serial": _serial}
)


def get_executor(name: str) -> Callable[..., Iterator[tuple[str, Outcome]]]:
    return EXECUTORS[name]
