"""Re-analyse many sessions at once: a process pool on every core, or a dask cluster.

Each session goes through exactly :func:`benchlab.protocols.runs.reanalyze`, the same call as
``benchlab analyze SESSION``, in a worker process: same files, same numbers, frames verified
by hash before and after. One session failing never stops the others; the outcome of each is
an :class:`BatchItem` (analysed, skipped with the reason, or failed with the reason).

Executors: :class:`concurrent.futures.ProcessPoolExecutor` (``forkserver`` workers that
import the analysis stack once, so each session costs only its analysis), or, with
``scheduler="tcp://host:8786"``, the ``concurrent.futures`` executor of a
``distributed.Client`` (the optional ``dask`` extra) so the same code runs on a cluster whose
workers see the same session folders.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import resource
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from benchlab.catalog.index import session_recorder
from benchlab.drivers.errors import BenchlabError
from benchlab.session import SESSION_FILE, Session

if TYPE_CHECKING:
    from benchlab.analysis.bars.estimators import EstimatorChoice

Outcome = Literal["analysed", "skipped", "failed"]
#: How long to try reaching a dask scheduler before giving up.
SCHEDULER_TIMEOUT_S = 10.0
#: Modules a forkserver worker imports once, before it takes any session.
_PRELOAD = ["benchlab.protocols.runs", "benchlab.protocols.mtf.steps",
            "benchlab.protocols.radiometry"]


class BatchError(BenchlabError):
    """A batch that cannot start (no sessions, bad --jobs, no dask, unreachable scheduler)."""


@dataclass(frozen=True)
class BatchItem:
    """What happened to one session of a batch."""

    session: str
    outcome: Outcome
    reason: str = ""
    results: str = ""
    seconds: float = 0.0
    #: The worker's peak resident memory (KiB) after this session: flat across a batch
    #: when nothing accumulates per session.
    worker_peak_kib: int = 0
    worker_pid: int = 0
    #: CPU seconds the worker spent on this session (independent of other load).
    cpu_seconds: float = 0.0


@dataclass
class BatchReport:
    """Every session's outcome, in the order given, and the wall time."""

    items: list[BatchItem] = field(default_factory=list)
    seconds: float = 0.0
    jobs: int = 0
    executor: str = ""

    def count(self, outcome: Outcome) -> int:
        return sum(1 for i in self.items if i.outcome == outcome)

    @property
    def failed(self) -> bool:
        return self.count("failed") > 0


def find_sessions(root: str | Path) -> list[Path]:
    """Session folders directly under ``root`` (folders holding ``session.json``), sorted."""
    base = Path(root)
    if not base.is_dir():
        raise BatchError(f"{base}: no such folder of sessions")
    return sorted(p for p in base.iterdir() if (p / SESSION_FILE).is_file())


def _acquisition_pending(session: Session) -> list[str]:
    from benchlab.protocols.runs import make_procedure, session_params

    done = session.completed_steps()
    steps = make_procedure(session_params(session)).steps()
    return [s.id for s in steps if s.kind != "analysis" and s.id not in done]


def analyse_one(path: str, estimator: EstimatorChoice | None = None, catalogue: bool = True
                ) -> BatchItem:
    """Re-analyse one session in this process (the worker's task; never raises).

    ``catalogue=False``: the parent records the session in the catalogue (local pool). A batch
    worker has a core to itself at most (the others have workers of their own), so the
    session is analysed on this thread alone (:func:`benchlab.analysis.threads.one_thread_only`).
    """
    from benchlab.analysis.threads import one_thread_only

    with one_thread_only():
        return _analyse_one(path, estimator, catalogue)


def _analyse_one(path: str, estimator: EstimatorChoice | None, catalogue: bool) -> BatchItem:
    from benchlab.protocols.runs import reanalyze

    t0 = time.perf_counter()
    cpu0 = time.process_time()

    def item(outcome: Outcome, reason: str = "", results: str = "") -> BatchItem:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return BatchItem(path, outcome, reason, results, time.perf_counter() - t0, peak,
                         os.getpid(), time.process_time() - cpu0)

    folder = Path(path)
    if not (folder / SESSION_FILE).is_file():
        return item("skipped", f"not a session folder (no {SESSION_FILE})")
    try:
        session = Session.open(folder)
        if session.status == "running":
            return item("skipped", "status running: a run may still be writing it")
        pending = _acquisition_pending(session)
        if pending:
            return item("skipped", f"acquisition incomplete ({len(pending)} steps to do, "
                        f"first {pending[0]}): benchlab resume it first")
        out = reanalyze(folder, estimator=estimator, catalogue=catalogue)
    except Exception as exc:  # noqa: BLE001 - one bad session must not stop the batch
        return item("failed", f"{type(exc).__name__}: {exc}")
    return item("analysed", results=str(out))


def default_jobs() -> int:
    """Every core this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


@contextmanager
def _executor(jobs: int, scheduler: str | None) -> Iterator[tuple[cf.Executor, str]]:
    if scheduler is None:
        method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() \
            else "spawn"
        ctx = multiprocessing.get_context(method)
        if method == "forkserver":
            ctx.set_forkserver_preload(_PRELOAD)
        with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            yield pool, f"{jobs} local processes ({method})"
        return
    try:
        from distributed import Client
    except ImportError as exc:
        raise BatchError("--scheduler needs the dask extra: pip install 'benchlab[dask]'") \
            from exc
    try:
        client = Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise BatchError(f"--scheduler {scheduler}: cannot connect ({exc})") from exc
    try:
        n = len(client.scheduler_info().get("workers", {}))
        # pure=False: every call is a new analysis, never a cached result of an earlier one.
        yield client.get_executor(pure=False), f"dask scheduler {scheduler} ({n} workers)"
    finally:
        client.close()


ProgressFn = Callable[[int, int, BatchItem], None]


def run_batch(
    sessions: Sequence[str | Path],
    *,
    estimator: str | None = None,
    jobs: int | None = None,
    scheduler: str | None = None,
    progress: ProgressFn | None = None,
) -> BatchReport:
    """Re-analyse every session; ``progress(done, total, item)`` after each one finishes.

    Raises
    ------
    BatchError
        Before anything runs: no sessions, ``jobs < 1``, or the executor cannot be had.
    """
    from benchlab.protocols.runs import check_estimator

    checked = check_estimator(estimator)
    # A session named twice is analysed once (two workers would race for one folder): named
    # by the folder it resolves to, so ROOT/s, ROOT/./s, a symlink to it and --all ROOT's s
    # are one session. The first spelling given is the one reported.
    unique: dict[Path, str] = {}
    for s in sessions:
        unique.setdefault(Path(s).resolve(), str(Path(s)))
    paths = list(unique.values())
    if not paths:
        raise BatchError("no sessions to analyse")
    if jobs is not None and jobs < 1:
        raise BatchError(f"--jobs must be >= 1, got {jobs}")
    n_jobs = min(jobs or default_jobs(), len(paths))
    t0 = time.perf_counter()
    report = BatchReport(jobs=n_jobs)
    by_path: dict[str, BatchItem] = {}
    # A local pool's sessions are catalogued here, each root's catalogue opened once; a
    # cluster's workers catalogue their own (this process may not see the folders).
    in_parent = scheduler is None
    with _executor(n_jobs, scheduler) as (executor, label), session_recorder() as record:
        report.executor = label
        futures = {executor.submit(analyse_one, p, checked, not in_parent): p for p in paths}
        for fut in cf.as_completed(futures):
            p = futures[fut]
            try:
                result = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker died (OOM, kill): that session
                result = BatchItem(p, "failed", f"worker lost: {type(exc).__name__}: {exc}")
            if in_parent and result.outcome == "analysed":
                record(p)
            by_path[p] = result
            if progress is not None:
                progress(len(by_path), len(paths), result)
    report.items = [by_path[p] for p in paths]
    report.seconds = time.perf_counter() - t0
    return report


def summary_rows(report: BatchReport) -> Iterable[tuple[str, str, str]]:
    """``(session, outcome, detail)`` for the summary table: failures and skips first."""
    order = {"failed": 0, "skipped": 1, "analysed": 2}
    for i in sorted(report.items, key=lambda i: order[i.outcome]):
        detail = i.reason if i.outcome != "analysed" else f"{Path(i.results).name} " \
            f"({i.seconds:.2f} s)"
        yield Path(i.session).name, i.outcome, detail


def worker_memory_profile(report: BatchReport, parts: int = 4) -> list[tuple[int, int]]:
    """Peak worker memory (KiB) per part of the batch (sessions in the order given):
    ``(sessions so far, max peak)``; flat numbers mean nothing accumulates per session."""
    items = [i for i in report.items if i.worker_peak_kib]
    if not items:
        return []
    out = []
    size = max(1, len(items) // parts)
    for k in range(0, len(items), size):
        chunk = items[k:k + size]
        out.append((k + len(chunk), max(i.worker_peak_kib for i in chunk)))
    return out
