"""How every simulator routes a host command to its handler: one table per simulator class.

A handler method is registered with the command key(s) it serves (a verb for the SLC, a
message id for APT, a command byte for the camera)::

    class SimulatedThing(PtyDevice):
        commands: CommandTable[str] = CommandTable()

        @commands.handles("MODE")
        def _mode(self, args: list[int]) -> str: ...

and the simulator's reader calls ``self.commands.handler(self, key)``; ``None`` means the
firmware does not know the command, and each simulator answers that as its device does.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any, Generic, TypeVar

K = TypeVar("K", bound=Hashable)
F = TypeVar("F", bound=Callable[..., Any])


class CommandTable(Generic[K]):
    """Command key -> name of the handler method, filled by :meth:`handles` at class creation."""

    def __init__(self) -> None:
        self._methods: dict[K, str] = {}

    def handles(self, *keys: K) -> Callable[[F], F]:
        """Decorator: the method handles these command keys."""

        def register(method: F) -> F:
            for key in keys:
                if key in self._methods:
                    raise ValueError(f"command {key!r} already handled by {self._methods[key]}")
                self._methods[key] = method.__name__
            return method

        return register

    def handler(self, simulator: object, key: K) -> Callable[..., Any] | None:
        """The bound handler of ``simulator`` for ``key``, or ``None`` for an unknown command."""
        name = self._methods.get(key)
        return None if name is None else getattr(simulator, name)

    def keys(self) -> list[K]:
        return list(self._methods)
