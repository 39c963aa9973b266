"""A batch worker analyses on one thread (:mod:`benchlab.analysis.threads`): the same numbers
as a threaded ``benchlab analyze SESSION``, and no thread started per session (the threads'
malloc arenas kept a worker's memory growing with every session it took)."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest
from many_sessions_helpers import copy_session, real_session, results_files

from benchlab.analysis import threads
from benchlab.protocols.batch import analyse_one
from benchlab.protocols.runs import reanalyze


def test_inline_executor_runs_each_task_at_once_and_hands_on_its_failure() -> None:
    ran: list[str] = []
    with threads.one_thread_only(), threads.thread_pool(4) as pool:
        assert isinstance(pool, threads.InlineExecutor)
        ok = pool.submit(lambda x: ran.append(threading.current_thread().name) or x * 2, 21)
        assert ok.done() and ok.result() == 42
        bad = pool.submit(int, "not a number")
        assert bad.done()
        with pytest.raises(ValueError, match="not a number"):
            bad.result()
        # only this thread: another thread of the process still gets its pool
        other: list[bool] = []
        t = threading.Thread(target=lambda: other.append(threads.one_thread()))
        t.start()
        t.join()
        assert other == [False]
    assert ran == [threading.current_thread().name]
    assert not threads.one_thread()  # the block's end restores it
    with threads.thread_pool(2) as pool:
        assert not isinstance(pool, threads.InlineExecutor)


@pytest.mark.slow
def test_a_batch_worker_starts_no_thread_and_reads_what_a_threaded_analysis_reads(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = real_session(tmp_path / "source")
    threaded = results_files(reanalyze(copy_session(source, tmp_path / "a"),
                                       estimator="sinefit"))
    started: list[str] = []
    real_start = threading.Thread.start

    def start(self: threading.Thread) -> None:
        started.append(self.name)
        real_start(self)

    monkeypatch.setattr(threading.Thread, "start", start)
    item = analyse_one(str(copy_session(source, tmp_path / "b")), "sinefit", False)
    assert item.outcome == "analysed", item.reason
    assert started == []  # no frame prefetch, no forward-view thread, no chart-reading pool
    assert results_files(Path(item.results)) == threaded
