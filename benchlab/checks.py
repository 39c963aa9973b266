"""Checking parsed TOML tables (bench configuration, procedure parameters) in one pass.

Every problem is collected and reported at once, each naming the dotted field
(``stage.travel_mm: must be [low, high] with low < high``), so a technician fixes a file in one
go. This sits below both users: ``benchlab.bench`` (bench files) and ``benchlab.protocols``
(parameter files, which add their own checks in ``protocols/params.py``).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

from benchlab.drivers.errors import BenchlabError


class ParamsError(BenchlabError):
    """A parameter or configuration file has problems; the message lists every one."""

    def __init__(self, source: str, problems: list[str]) -> None:
        self.source = source
        self.problems = list(problems)
        lines = "\n".join(f"  {p}" for p in self.problems)
        n = len(self.problems)
        super().__init__(f"{source}: {n} problem{'s' if n != 1 else ''}:\n{lines}")


@dataclass(frozen=True)
class BenchLimits:
    """What the bench allows, so parameters are checked against it with everything else.

    ``led_ceilings_ma`` is ``None`` when the bench has no LED controller configured;
    ``stage_travel_mm`` is ``None`` without a stage (positions are then set by hand).
    """

    led_ceilings_ma: Mapping[int, float] | None = None
    stage_travel_mm: tuple[float, float] | None = None
    #: The bit depths the bench's camera decodes (bench file ``[camera] bit_depths``, written
    #: by ``benchlab doctor``); None: not settled, any of :data:`CAMERA_BIT_DEPTHS`.
    camera_bit_depths: tuple[int, ...] | None = None

    def bits_problem(self, bits: int) -> str | None:
        """Why the bench's camera cannot measure at ``bits`` (None: it can)."""
        depths = self.camera_bit_depths
        if depths is None or bits in depths:
            return None
        return (f"{bits} bits is not a depth this bench's camera decodes (bench file "
                f"[camera] bit_depths = {list(depths)}, settled by `benchlab doctor`)")


#: Bit depths a procedure may ask the camera for: those some camera profile decodes (the
#: MCE-B013-U's 8, 10, 12). A bench's own are its bench file's ``[camera] bit_depths``,
#: checked when the run configures the camera.
CAMERA_BIT_DEPTHS = (8, 10, 12)


class TableChecker:
    """Reads typed values out of a nested mapping, collecting every problem."""

    def __init__(self, data: Mapping[str, Any]) -> None:
        self.data = data
        self.problems: list[str] = []
        self.seen: set[str] = set()

    def get(self, dotted: str, default: Any) -> tuple[bool, Any]:
        """``(found, value)`` at a dotted key; marks the key as read."""
        self.seen.add(dotted)
        node: Any = self.data
        for part in dotted.split("."):
            if not isinstance(node, Mapping) or part not in node:
                return False, default
            node = node[part]
        return True, node

    def fail(self, dotted: str, message: str) -> None:
        self.problems.append(f"{dotted}: {message}")

    def number(
        self, dotted: str, default: float, lo: float | None = None, hi: float | None = None,
        *, lo_open: bool = False, hi_open: bool = False,
    ) -> float:
        found, value = self.get(dotted, default)
        if not found:
            return default
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(dotted, f"must be a number, got {value!r}")
            return default
        value = float(value)
        if not math.isfinite(value):
            self.fail(dotted, f"must be finite, got {value}")
            return default
        below = lo is not None and (value <= lo if lo_open else value < lo)
        if below or (hi is not None and (value >= hi if hi_open else value > hi)):
            rng = (f"{'>' if lo_open else '>='} {lo}" if hi is None else
                   f"in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}")
            self.fail(dotted, f"must be {rng}, got {value:g}")
            return default
        return value

    def integer(self, dotted: str, default: int, lo: int, hi: int) -> int:
        found, value = self.get(dotted, default)
        if not found:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(dotted, f"must be an integer, got {value!r}")
            return default
        if not lo <= value <= hi:
            self.fail(dotted, f"must be in [{lo}, {hi}], got {value}")
            return default
        return value

    def choice(self, dotted: str, default: Any, allowed: tuple[Any, ...]) -> Any:
        found, value = self.get(dotted, default)
        if found and value not in allowed:
            self.fail(dotted, f"must be one of {', '.join(map(str, allowed))}; got {value!r}")
            return default
        return value

    def string(self, dotted: str, default: str) -> str:
        found, value = self.get(dotted, default)
        if found and not isinstance(value, str):
            self.fail(dotted, f"must be a string, got {value!r}")
            return default
        return value

    def numbers(
        self, dotted: str, default: tuple[float, ...], lo: float, hi: float,
        *, lo_open: bool = False, distinct: bool = True,
    ) -> tuple[float, ...]:
        found, value = self.get(dotted, default)
        if not found:
            return default
        if not isinstance(value, list) or not value:
            self.fail(dotted, f"must be a non-empty list of numbers, got {value!r}")
            return default
        out: list[float] = []
        ok = True
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                self.fail(f"{dotted}[{i}]", f"must be a number, got {v!r}")
                ok = False
            elif (v <= lo if lo_open else v < lo) or v > hi:
                self.fail(f"{dotted}[{i}]", f"must be in {'(' if lo_open else '['}{lo}, {hi}], "
                          f"got {v:g}")
                ok = False
            else:
                out.append(float(v))
        if ok and distinct and len(set(out)) != len(out):
            self.fail(dotted, "has duplicate values")
            ok = False
        return tuple(out) if ok else default

    _get = get  # the name procedure checks use

    def number_table(self, dotted: str, names: Collection[str], what: str
                     ) -> dict[str, float]:
        """An optional table of numbers whose keys must be among ``names`` (e.g. a simulated
        lens's parameters): ``{}`` when absent; each bad key or value is reported."""
        found, table = self.get(dotted, {})
        out: dict[str, float] = {}
        if not found:
            return out
        if not isinstance(table, Mapping):
            self.fail(dotted, f"must be a table of {what}")
            return out
        for key, value in table.items():
            self.seen.add(f"{dotted}.{key}")
            if key not in names:
                self.fail(f"{dotted}.{key}",
                          f"unknown parameter; known: {', '.join(sorted(names))}")
            elif isinstance(value, bool) or not isinstance(value, int | float):
                self.fail(f"{dotted}.{key}", f"must be a number, got {value!r}")
            else:
                out[str(key)] = float(value)
        return out

    def unknown_keys(self) -> None:
        """Flag keys nobody read (typos would otherwise be silently ignored)."""

        def walk(node: Mapping[str, Any], prefix: str) -> None:
            for key, value in node.items():
                dotted = f"{prefix}{key}"
                nested = any(s.startswith(dotted + ".") for s in self.seen)
                if isinstance(value, Mapping) and nested:
                    walk(value, dotted + ".")
                elif dotted not in self.seen:
                    self.fail(dotted, "unknown parameter")

        walk(self.data, "")
