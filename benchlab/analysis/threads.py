"""How many threads one analysis may start: what it asks for in a process of its own (one
``benchlab analyze SESSION``), none in a batch worker.

A batch runs one worker process per core, so a worker's threads buy no wall time: they only
cost CPU (the interpreter lock handed between them) and memory (each new thread's malloc
arena, which kept a worker's resident size growing session after session). Every estimate is
a pure function of its frame, so the numbers are the same either way.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any, TypeVar

_T = TypeVar("_T")
_local = threading.local()


@contextmanager
def one_thread_only() -> Iterator[None]:
    """Within the block, what this thread analyses runs on this thread alone (other threads
    of the process, e.g. a dask worker's other tasks, are not affected)."""
    before = one_thread()
    _local.single = True
    try:
        yield
    finally:
        _local.single = before


def one_thread() -> bool:
    """Whether this thread is inside :func:`one_thread_only`."""
    return bool(getattr(_local, "single", False))


class InlineExecutor(Executor):
    """An executor that runs each task at once on the calling thread (a finished future)."""

    def submit(self, fn: Callable[..., _T], /, *args: Any, **kwargs: Any) -> Future[_T]:
        fut: Future[_T] = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except Exception as exc:  # handed on through the future (an interrupt is not: it stops)
            fut.set_exception(exc)
        return fut


def thread_pool(max_workers: int, thread_name_prefix: str = "") -> Executor:
    """A :class:`ThreadPoolExecutor`, or an :class:`InlineExecutor` inside
    :func:`one_thread_only`."""
    if one_thread():
        return InlineExecutor()
    return ThreadPoolExecutor(max_workers=max_workers, thread_name_prefix=thread_name_prefix)
