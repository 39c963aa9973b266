"""Reading a Table 4.15 row: which of its sagittal and tangential readings are numbers.

Shared by the report and the catalogue so that both say "not resolved" for the same rows.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any


def reading(row: Mapping[str, Any], orient: str) -> float | None:
    """A Table 4.15 row's sagittal or tangential modulation; None when not resolved.

    Rows from before the ``*_resolved`` flags stored a not-resolved reading as 0 (a resolved
    Eq. 2.9 contrast is never exactly 0), so 0 without a flag is read as not resolved."""
    m = row.get(f"{orient}_modulation")
    flag = row.get(f"{orient}_resolved")
    if isinstance(m, bool) or not isinstance(m, int | float):
        return None
    if flag is False or (flag is None and float(m) == 0.0):
        return None
    return float(m)


def average_of(row: Mapping[str, Any]) -> tuple[float | None, str]:
    """The row's Eq. 4.2 average (None when a half is not resolved) and what is missing.
    A row that does not give its halves at all is taken at its stored average."""
    avg = row.get("averaged_modulation")
    if "sagittal_modulation" not in row and "tangential_modulation" not in row:
        return (float(avg) if isinstance(avg, int | float) else None), ""
    s, t = reading(row, "sagittal"), reading(row, "tangential")
    if s is None or t is None:
        return None, " and ".join(o for o, v in (("S", s), ("T", t)) if v is None) + \
            " not resolved"
    return (float(avg) if isinstance(avg, int | float) else (s + t) / 2.0), ""


def fmt_reading(v: float | None) -> str:
    """A reading as text: three decimals, or "not resolved"."""
    return "not resolved" if v is None else f"{v:.3f}"


def verdict_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Table 4.15 rows as shown: "not resolved" for a missing half, no average and no verdict
    built on a 0 (older results averaged one in)."""
    out = []
    for r in rows:
        avg, missing = average_of(r)
        shown = dict(r)
        for orient in ("sagittal", "tangential"):
            v = reading(r, orient)
            shown[f"{orient}_modulation"] = fmt_reading(v) if v is None else v
        if missing:
            s, t = reading(r, "sagittal"), reading(r, "tangential")
            bound = ((s or 0.0) + (t or 0.0)) / 2.0
            shown["averaged_modulation"] = f"N/A ({missing})"
            shown["verdict"] = f"not available: {missing} (average at least {bound:.3f})"
        else:
            shown["averaged_modulation"] = avg
        out.append(shown)
    return out
