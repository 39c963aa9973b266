"""How many threads one analysis may start: what it asks for in a process of its own (one
``benchlab analyze SESSION``), none in a batch worker.

A batch runs one worker process per core, so a worker's threads buy no wall time: they only
cost CPU (the interpreter lock handed between them) and memory (each new thread's malloc
arena, which kept a worker's resident size growing session after session). Every estimate is
a pure function of its frame, so the numbers are the same either way.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from typing import Any, TypeVar

_T = TypeVar("_T")
_single = False


def use_one_thread(on: bool = True) -> None:
    """From now on (in this process) every analysis runs on the calling thread alone."""
    global _single
    _single = on


def one_thread() -> bool:
    """Whether :func:`use_one_thread` is in force."""
    return _single


class InlineExecutor(Executor):
    """An executor that runs each task at once on the calling thread (a finished future)."""

    def submit(self, fn: Callable[..., _T], /, *args: Any, **kwargs: Any) -> Future[_T]:
        fut: Future[_T] = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller through the future
            fut.set_exception(exc)
        return fut


def thread_pool(max_workers: int, thread_name_prefix: str = "") -> Executor:
    """A :class:`ThreadPoolExecutor`, or an :class:`InlineExecutor` under
    :func:`use_one_thread`."""
    if _single:
        return InlineExecutor()
    return ThreadPoolExecutor(max_workers=max_workers, thread_name_prefix=thread_name_prefix)
