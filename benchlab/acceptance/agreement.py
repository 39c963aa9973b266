"""Do the sessions of one unit agree? Two readings of the same quantity that differ beyond
their uncertainties say that at least one session is wrong, or its interval too narrow.

The test is the normalised error of proficiency testing (ISO 13528, the *E_n* number):

    E_n = |x_1 - x_2| / sqrt(U_1^2 + U_2^2)

with ``U`` each reading's expanded uncertainty at the spec's coverage - the half-width of its
interval on the side facing the other reading, so an asymmetric interval counts the side that
matters. ``E_n > 1``: the two readings disagree. A reading without an interval cannot be said
to disagree beyond its uncertainty, and is not compared. Everything here is pure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from benchlab.acceptance.decide import Reading

#: ``E_n`` above this: the readings disagree beyond their uncertainties.
EN_LIMIT = 1.0


@dataclass(frozen=True)
class SessionReading:
    """One session's reading of one quantity, with its interval."""

    session: str
    value: float
    low: float
    high: float

    def text(self) -> str:
        return f"{self.session} {self.value:.4g} [{self.low:.4g}, {self.high:.4g}]"


@dataclass(frozen=True)
class Disagreement:
    """The reading that decided a verdict row and another session's reading of the same
    quantity (same table, row and column) that disagrees with it."""

    limit_id: str
    table: str
    row: str
    column: str
    decided: SessionReading
    other: SessionReading
    normalised_error: float

    def text(self) -> str:
        """One line for a verdict row's notes, a certificate and the terminal."""
        where = f"{self.table} {self.row} {self.column}".replace("  ", " ")
        return (f"sessions disagree beyond their uncertainties on {where}: "
                f"{self.decided.text()} (decides) vs {self.other.text()}, "
                f"E_n {self.normalised_error:.3g}")

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> Disagreement:
        """The disagreement of a stored verdict record (:meth:`as_dict`)."""
        return cls(str(doc["limit_id"]), str(doc["table"]), str(doc["row"]),
                   str(doc["column"]), SessionReading(**doc["decided"]),
                   SessionReading(**doc["other"]), float(doc["normalised_error"]))


def normalised_error(a: Reading, b: Reading) -> float | None:
    """``E_n`` of two readings (None when either has no value or no interval)."""
    if a.value is None or b.value is None:
        return None
    if a.low is None or a.high is None or b.low is None or b.high is None:
        return None
    high, low = (a, b) if a.value >= b.value else (b, a)
    assert high.value is not None and high.low is not None
    assert low.value is not None and low.high is not None
    gap = high.value - low.value
    u = math.hypot(high.value - high.low, low.high - low.value)
    if u <= 0:
        return math.inf if gap > 0 else 0.0
    return gap / u


def disagreement(decided: Reading, other: Reading, *, limit_id: str, table: str, row: str,
                 column: str, decided_session: str, other_session: str
                 ) -> Disagreement | None:
    """The disagreement of two sessions' readings of one quantity, or None when they agree
    within their uncertainties (or cannot be compared)."""
    en = normalised_error(decided, other)
    if en is None or en <= EN_LIMIT:
        return None

    def reading(session: str, r: Reading) -> SessionReading:
        assert r.value is not None and r.low is not None and r.high is not None
        return SessionReading(session, r.value, r.low, r.high)

    return Disagreement(limit_id, table, row, column, reading(decided_session, decided),
                        reading(other_session, other), en)
