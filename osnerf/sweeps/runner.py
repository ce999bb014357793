"""Run a sweep: expand the spec, skip finished points, execute the rest, append each result.

Each point runs ``osnerf.cli.main([command, *argv, "--out", TMP])`` in a worker (in-process,
a spawned process of a ``concurrent.futures`` pool, or a Ray task), and the worker returns
the command's result JSON. The driver extracts the metrics (:mod:`osnerf.sweeps.metrics`)
and appends one line per finished point to the results file (:mod:`osnerf.sweeps.store`),
with the codec record of the command's result (``codec``, null for a command without one).
Failed points are not written there: they go to ``<out>.errors.jsonl`` and are retried by
the next run of the same spec. A point whose command rejects its arguments (exit 2: a value
its parser accepted but the command does not) stops the sweep with a ValueError: the spec
is wrong, and every other point with that value would fail the same way.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from osnerf import cli
from osnerf.provenance import git_commit
from osnerf.sweeps.executors import Outcome, Task, get_executor
from osnerf.sweeps.metrics import channel_params, metric_rule
from osnerf.sweeps.spec import Point, SweepSpec, command_options, command_parser, expand, point_key
from osnerf.sweeps.store import append_record, check_results, open_results


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
    check_results(
        out, spec.sha256, spec=spec.to_dict()
    )  # a refusal creates nothing: no folder, no lock
    out.parent.mkdir(parents=True, exist_ok=True)
    with _exclusive(out):
        run = _Sweep(spec, rule, executor, run_executor, workers, cpus, progress, keep)
        return _run_points(run, points, out, ray_address, ray_runtime_env)


@contextlib.contextmanager
def _exclusive(out: Path):
    """Hold ``<out>.lock`` (flock) while a sweep writes ``out``: two sweeps on one file refuse.

    The lock file is removed when the sweep ends (while still held), so none is left beside
    ``out``; a sweep that locked a file removed meanwhile locks the new one instead.
    """
    import fcntl

    lock = out.with_name(out.name + ".lock")
    while True:
        f = open(lock, "a")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.close()
            raise ValueError(
                f"--out {str(out)!r}: another sweep is writing it (lock {lock.name} is held); "
                "wait for it or use another --out"
            ) from None
        if _same_file(f, lock):
            break
        f.close()  # the sweep that held it has ended and removed it: lock the new one
    try:
        yield
    finally:
        with contextlib.suppress(FileNotFoundError):
            lock.unlink()  # still held: a sweep waiting on this file retries on a new one
        f.close()  # releases the lock


def _same_file(f, path: Path) -> bool:
    """True when the open file ``f`` is still the file at ``path``."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return False
    own = os.fstat(f.fileno())
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)


@dataclass(frozen=True)
class _Sweep:
    """What every point of one sweep shares."""

    spec: SweepSpec
    rule: Any
    executor: str
    run_executor: Callable[..., Iterator[tuple[str, Outcome]]]
    workers: int
    cpus: int
    progress: bool
    keep: str | Path | None


def _tasks(run: _Sweep, todo: list[Point]) -> list[tuple[str, Task]]:
    threads = max(1, run.cpus // run.workers) if run.executor == "local" else None  # Ray: its own
    return [
        (
            p.key,
            {
                "command": run.spec.command,
                "module": cli.COMMANDS[run.spec.command][0],
                "argv": list(p.argv),
                "out_kind": run.rule.out_kind,
                "json_name": run.rule.json_name,
                "threads": threads,
                "keep": str(Path(run.keep).resolve()) if run.keep else None,
                "slug": point_slug(p),
            },
        )
        for p in todo
    ]


def _run_points(run: _Sweep, points, out, ray_address, ray_runtime_env) -> SweepSummary:
    from tqdm import tqdm

    spec = run.spec
    done = {
        point_key(r["point"], r.get("seed")) for r in open_results(out, spec.sha256, spec.to_dict())
    }
    todo: list[Point] = [p for p in points if p.key not in done]
    summary = SweepSummary(total=len(points), skipped=len(points) - len(todo))
    errors = errors_path(out)
    if errors.exists():
        errors.unlink()  # failures of an earlier run are retried now
    if not todo:
        return summary
    by_key = {p.key: p for p in todo}
    stream = run.run_executor(
        _tasks(run, todo), run.workers, ray_address=ray_address, ray_runtime_env=ray_runtime_env
    )
    bar = tqdm(
        total=len(points),
        initial=summary.skipped,
        unit="point",
        desc=f"sweep {spec.command}",
        disable=not run.progress,
        file=sys.stderr,
        dynamic_ncols=True,
    )
    try:
        for key, outcome in stream:
            _record(run, by_key[key], outcome, out, errors, summary, bar)
            bar.update(1)
    finally:
        stream.close()  # stop the executor now (cancel what has not started)
        bar.close()
    return summary


def _record(run: _Sweep, p: Point, outcome: Outcome, out, errors, summary, bar) -> None:
    """Append one finished point to ``out`` (or its failure to ``errors``)."""
    spec, rule = run.spec, run.rule
    if outcome["ok"]:
        result = outcome["result"]
        try:
            metrics = rule.extract(result)
        except (KeyError, IndexError, TypeError) as e:
            outcome = {
                **outcome,
                "ok": False,
                "error": (
                    f"result of `osnerf {spec.command}` lacks the field {e} its metric rule reads"
                ),
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
                "spec": spec.to_dict(),
                "versions": result.get("versions"),
                "codec": result.get("codec"),
                "channel": channel_params(result),
                "output": outcome.get("kept"),
                "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
            },
        )
        summary.finished += 1
        return
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
        f"osnerf sweep: point {p.values} seed {p.seed} failed: {outcome['error']}", file=sys.stderr
    )
    if outcome.get("rc") == 2:  # bad input: every other point would fail the same
        raise ValueError(
            f"point {p.values} seed {p.seed}: `osnerf {spec.command}` refused its "
            f"input (exit 2: {outcome['error'].partition(': ')[2]}); fix the spec "
            "or the input (finished points are kept)"
        )
