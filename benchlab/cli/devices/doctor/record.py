"""What a bring-up learns from outside the devices, kept in its cassette so that ``benchlab
doctor --replay CASSETTE`` runs the same checks to the same results.

The device exchanges are in the cassette already (:mod:`benchlab.drivers.trace.io_trace`).
The rest - the run's options and bench file, each answer a person gave, the host clock read
to time frames, what the machine has installed (libusb, the udev rule, group membership) and
what is on the USB bus - goes into ``note`` lines of device ``doctor``, one JSON object each
(``{"k": kind, "v": value}``), in the order the doctor asked. A replay answers from them.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from benchlab.drivers.trace import io_trace
from benchlab.drivers.trace.cassette import CassetteError, ReplayDivergedError

NOTE_DEVICE = "doctor"
_T = TypeVar("_T")


class Outside:
    """Facts from outside the devices: live (computed, then noted in the cassette) or
    replayed (read back from a cassette's notes, in order)."""

    def __init__(self, replayed: list[dict[str, Any]] | None = None) -> None:
        self._replayed = replayed

    @property
    def replaying(self) -> bool:
        return self._replayed is not None

    def get(self, kind: str, compute: Callable[[], _T]) -> _T:
        """``compute()`` (noted in the cassette), or the value the recorded run noted."""
        if self._replayed is None:
            value = compute()
            io_trace.note(NOTE_DEVICE, json.dumps({"k": kind, "v": value}))
            return value
        # The next note of this kind: a replay that skips a check (its device diverged)
        # passes over that check's notes, as the devices' own streams do.
        for i, item in enumerate(self._replayed):
            if item.get("k") == kind:
                del self._replayed[: i + 1]
                return item["v"]  # type: ignore[no-any-return]
        raise ReplayDivergedError(f"replay diverged: the doctor needs {kind!r}, the cassette "
                                  "noted nothing more of it")


def read_notes(path: str | Path) -> list[dict[str, Any]]:
    """The doctor's notes of a cassette, in order; the first is the run's (``k`` = "run")."""
    notes: list[dict[str, Any]] = []
    try:
        with io_trace.open_text(path, "r") as fh:
            lines = fh.read().splitlines()
    except OSError as exc:
        raise CassetteError(f"{path}: cannot read the cassette: {exc}") from exc
    for i, text in enumerate(lines[1:], 2):
        try:
            item = json.loads(text)
            if item.get("dev") == NOTE_DEVICE and "note" in item:
                notes.append(json.loads(item["note"]))
        except (json.JSONDecodeError, AttributeError, TypeError):
            raise CassetteError(f"{path}: line {i} is not a cassette event") from None
    if not notes or notes[0].get("k") != "run":
        raise CassetteError(f"{path}: not a bring-up recording (no doctor run note): record "
                            "one with `benchlab doctor`")
    return notes
