"""The ``benchlab`` command line."""

import argparse
import math

from benchlab.drivers.errors import UsageError

__all__ = ["PROCEDURES", "UsageError", "non_negative_int", "positive_float", "positive_int"]

#: The procedures ``run`` and the TUI offer: benchlab.protocols.params.PROCEDURES, written out
#: so that building the parser imports no numpy (a test keeps the two equal).
PROCEDURES = ("mtf", "radiometry", "characterise", "depth", "fov")


def _whole_number(text: str, minimum: int) -> int:
    """``text`` as an integer >= ``minimum``, else argparse's usage error (exit 2)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < minimum:
        raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1 (a count: frames, repeats, cases, jobs)."""
    return _whole_number(text, 1)


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0 (0 switches the feature off, e.g. ``--bootstrap``)."""
    return _whole_number(text, 0)


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (a time scale, a duration)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value
