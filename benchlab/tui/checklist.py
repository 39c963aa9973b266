"""The Run screen's checklist as rows an 80-column terminal shows whole.

Each step gets a short unique label - its number in the run - and its description, wrapped in
a column as wide as the panel allows (never cut). The thesis reference of a step (``6 (8)``:
Table 4.10 step 6, repeated as step 8) is a column of its own only where it tells the steps
apart and the panel has room for it beside the description; a procedure whose steps all cite
one section names it in the panel's title instead.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

#: A reference column wider than this is left out (it would squeeze the description).
REF_MAX_CHARS = 6
#: The reference column is shown only if it leaves the description this wide ...
WHAT_MIN_CHARS = 16
#: ... and the description never gets narrower than this (the panel scrolls instead).
WHAT_FLOOR_CHARS = 8
#: The status mark before each step's number (2 characters) and every column's padding.
MARK_CHARS = 2
CELL_PADDING = 2


def short_step_label(label: str) -> str:
    """``"Table 4.10 step 6 (step 8)"`` -> ``"6 (8)"``; ``"section 4.4"`` -> ``"§4.4"``."""
    return (label.replace("Table 4.10 step ", "").replace("(step ", "(")
            .replace("section ", "§"))


@dataclass(frozen=True)
class ChecklistLayout:
    """What the checklist table shows: its column headers and widths, and one row per step.

    Attributes
    ----------
    headers : tuple of str
        The columns: ``("#", "ref", "what")`` or ``("#", "what")``.
    widths : tuple of int
        The width of each of those columns (characters, without padding); the first holds
        the status mark (:data:`MARK_CHARS`) and the step's number.
    rows : list of tuple of str
        Per step: its number, its reference (when shown) and its description; the number
        is right-aligned, ready for a mark in front (:func:`numbered`).
    """

    headers: tuple[str, ...]
    widths: tuple[int, ...]
    rows: list[tuple[str, ...]]


def checklist_layout(steps: Sequence[Any], width_chars: int) -> ChecklistLayout:
    """The checklist of ``steps`` (``.table_step``, ``.id``, ``.title``) for a table
    ``width_chars`` wide (its content region, scrollbar excluded)."""
    refs = [short_step_label(s.table_step or s.id) for s in steps]
    show_ref = len(set(refs)) > 1 and max(map(len, refs), default=0) <= REF_MAX_CHARS
    numbers = [str(i) for i in range(1, len(steps) + 1)]
    num_w = max(1, *map(len, numbers)) if numbers else 1
    ref_w = max(3, *map(len, refs)) if show_ref and refs else 0
    numbers = [n.rjust(num_w) for n in numbers]
    num_w += MARK_CHARS
    used = (num_w + CELL_PADDING) + CELL_PADDING
    if show_ref and width_chars - used - ref_w - CELL_PADDING < WHAT_MIN_CHARS:
        show_ref = False  # a narrow panel: the description before the reference
    if show_ref:
        used += ref_w + CELL_PADDING
    what_w = max(WHAT_FLOOR_CHARS, width_chars - used)
    if show_ref:
        return ChecklistLayout(("#", "ref", "what"), (num_w, ref_w, what_w),
                               [(n, r, s.title) for n, r, s in zip(numbers, refs, steps,
                                                                    strict=True)])
    return ChecklistLayout(("#", "what"), (num_w, what_w),
                           [(n, s.title) for n, s in zip(numbers, steps, strict=True)])


def numbered(mark: str, number: str) -> str:
    """A checklist row's first cell: its status mark (2 characters) and its number."""
    return f"{mark:<{MARK_CHARS}}{number}"
