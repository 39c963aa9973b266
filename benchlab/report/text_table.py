"""Plain-text tables that fit a terminal: long repeated reasons as footnotes, and a table wider
than the terminal printed as blocks of columns, each block led by the first column again.

``--json`` / ``--csv`` outputs keep every column on one row; only the terminal text is folded.
"""

from __future__ import annotations

import os
import re
import shutil
from collections.abc import Sequence

#: Gap between two columns.
GAP = "  "
#: At most this many leading columns are repeated in each block to name the rows.
MAX_LEAD = 3
#: A cell of this form is a reason; the reason goes to a footnote, the cell keeps ``n/a [k]``.
_REASON = re.compile(r"^n/a \((?P<why>.+)\)$")


def terminal_width(default: int = 80) -> int:
    """The width to fit: ``COLUMNS`` when set, the terminal's when there is one, else 80."""
    if os.environ.get("COLUMNS", "").strip().isdigit():
        return max(20, int(os.environ["COLUMNS"]))
    return max(20, shutil.get_terminal_size((default, 24)).columns)


def footnoted(body: list[list[str]]) -> tuple[list[list[str]], list[str]]:
    """Cells ``n/a (reason)`` as ``n/a [k]``, one footnote ``[k] reason`` per distinct reason."""
    notes: dict[str, int] = {}
    out = []
    for row in body:
        new = []
        for c in row:
            m = _REASON.match(c)
            if m:
                k = notes.setdefault(m["why"], len(notes) + 1)
                c = f"n/a [{k}]"
            new.append(c)
        out.append(new)
    return out, [f"[{k}] n/a: {why}" for why, k in notes.items()]


def _block(header: Sequence[str], body: Sequence[Sequence[str]], right: bool) -> list[str]:
    widths = [max(len(x) for x in col) for col in zip(header, *body, strict=False)]

    def line(cells: Sequence[str]) -> str:
        return GAP.join(c.rjust(w) if right else c.ljust(w)
                        for c, w in zip(cells, widths, strict=True)).rstrip()

    return [line(header), *(line(r) for r in body)]


def one_line_table(header: Sequence[str], body: Sequence[Sequence[str]], *,
                   right: bool = True) -> str:
    """Every row on one line, however wide (``--wide``; files and tests that read rows)."""
    return "\n".join(_block(header, body, right))


def _lead(cells: Sequence[Sequence[str]], n_columns: int) -> int:
    """How many leading columns name a row: the fewest (up to :data:`MAX_LEAD`) whose values
    tell the rows apart (``gain`` and ``bits`` for a characterisation)."""
    for k in range(1, min(MAX_LEAD, n_columns - 1) + 1):
        if len({tuple(r[:k]) for r in cells}) == len(cells):
            return k
    return 1


def fit_table(header: Sequence[str], body: Sequence[Sequence[str]], *, width: int | None = None,
              right: bool = True) -> str:
    """A table as text no wider than ``width`` (default: :func:`terminal_width`).

    Repeated ``n/a (reason)`` cells become footnotes; if the rows are still too wide, the
    columns are printed in blocks, one under the other, each starting with the leading
    columns that name the row (:func:`_lead`) so that every value can be read against it.
    A single cell wider than ``width`` is the only thing that can exceed it.
    """
    limit = terminal_width() if width is None else width
    cells, notes = footnoted([list(r) for r in body])
    head = list(header)
    full = _block(head, cells, right)
    if max(map(len, full)) <= limit or len(head) <= 2:
        return "\n".join(full + notes)
    widths = [max(len(x) for x in col) for col in zip(head, *cells, strict=False)]
    lead = _lead(cells, len(head))
    lead_w = sum(widths[:lead]) + len(GAP) * (lead - 1)
    blocks: list[list[int]] = []
    current: list[int] = list(range(lead))
    used = lead_w
    for i in range(lead, len(head)):
        if len(current) > lead and used + len(GAP) + widths[i] > limit:
            blocks.append(current)
            current, used = list(range(lead)), lead_w
        current.append(i)
        used += len(GAP) + widths[i]
    blocks.append(current)
    lines: list[str] = []
    for n, cols in enumerate(blocks):
        if n:
            lines.append("")
        lines += _block([head[i] for i in cols], [[r[i] for i in cols] for r in cells], right)
    return "\n".join(lines + notes)
