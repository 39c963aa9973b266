"""``benchlab analyze --all ROOT --scheduler ADDRESS`` on a real dask.distributed cluster: a
scheduler and two worker processes started here as a lab starts them (``dask scheduler``,
``dask worker``), sharing the sessions folder. One worker is killed mid-batch: its sessions
are run again elsewhere, none is lost, none gets two new results versions, and the catalogue
lists every session once."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from many_sessions_helpers import copy_session, real_session, results_files

from benchlab.cli.main import main
from benchlab.protocols.batch import BatchItem, run_batch
from benchlab.protocols.runs import reanalyze

distributed = pytest.importorskip("distributed")  # the dask extra (installed with [test])

SESSIONS = 8


def _start(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    with log.open("wb") as out:
        return subprocess.Popen([sys.executable, "-m", *args], stdout=out,
                                stderr=subprocess.STDOUT, start_new_session=True)


@pytest.fixture()
def cluster(tmp_path: Path) -> Iterator[str]:
    """A scheduler and two single-threaded workers (each with its nanny, as ``dask worker``
    runs by default), on this machine; yields the scheduler's address."""
    sched_file = tmp_path / "scheduler.json"
    procs = [_start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                     "--no-dashboard", "--scheduler-file", str(sched_file)],
                    tmp_path / "scheduler.log")]
    try:
        for name in ("bench-a", "bench-b"):
            procs.append(_start(["distributed.cli.dask_worker", "--scheduler-file",
                                 str(sched_file), "--nthreads", "1", "--nworkers", "1",
                                 "--name", name, "--no-dashboard", "--host", "127.0.0.1"],
                                tmp_path / f"{name}.log"))
        deadline = time.monotonic() + 60
        while not sched_file.exists():
            assert time.monotonic() < deadline, (tmp_path / "scheduler.log").read_text()
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        with distributed.Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:
        for p in procs:  # the whole process group: the nanny and its worker
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait(timeout=30)


def _kill_a_busy_worker(address: str) -> int:
    """SIGKILL the worker process of a worker that has a session in hand; its pid."""
    with distributed.Client(address, timeout="30s") as client:
        deadline = time.monotonic() + 30
        while True:
            busy = [w for w, keys in client.processing().items() if keys]
            if busy or time.monotonic() > deadline:
                break
            time.sleep(0.01)
        assert busy, "no worker had a session in hand"
        pid = int(client.run(os.getpid, workers=[busy[0]])[busy[0]])
    os.kill(pid, signal.SIGKILL)
    return pid


@pytest.mark.slow
def test_a_worker_killed_mid_batch_costs_only_its_sessions(cluster: str, tmp_path: Path) -> None:
    source = real_session(tmp_path / "source")
    root = tmp_path / "shared-sessions"
    sessions = [copy_session(source, root / f"lens-{i}", sample=f"lens-{i}")
                for i in range(SESSIONS)]
    # another estimator than the run's: each session gets a new version (v2), so a second
    # one (v3) would show
    expected = results_files(reanalyze(copy_session(source, tmp_path / "single" / "s"),
                                       estimator="sinefit"))
    killed: list[int] = []

    def progress(done: int, total: int, item: BatchItem) -> None:
        if done == 1:  # the first session is back: the other worker has one in hand
            killed.append(_kill_a_busy_worker(cluster))

    report = run_batch(sessions, estimator="sinefit", scheduler=cluster, progress=progress)
    assert killed and report.executor.startswith("dask scheduler tcp://127.0.0.1")
    assert [i.outcome for i in report.items] == ["analysed"] * SESSIONS, \
        [i.reason for i in report.items]
    with pytest.raises(ProcessLookupError):
        os.kill(killed[0], 0)  # it did die, with a session in hand
    assert len({i.worker_pid for i in report.items}) >= 2  # both workers (and the restart)
    for s, item in zip(sessions, report.items, strict=True):
        # one new version each: an analysis cut short by the kill left none (a version is
        # renamed into place whole), and a rerun of one that had finished matched it
        assert sorted(p.name for p in (s / "results").iterdir()) == ["v1", "v2"]
        assert Path(item.results) == s / "results" / "v2"
        assert results_files(s / "results" / "v2") == expected
    before = _list(root)
    assert sorted(r["id"] for r in before) == sorted(s.name for s in sessions)
    assert {r["results_version"] for r in before} == {2}


def _list(root: Path) -> list[dict[str, object]]:
    """``benchlab sessions list --root ROOT --json``, parsed (stdout captured here)."""
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["sessions", "list", "--root", str(root), "--json"]) == 0
    rows = json.loads(out.getvalue())
    assert isinstance(rows, list)
    return rows

