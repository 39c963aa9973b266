"""CLI commands of this group (filled in by the owning layer)."""

from __future__ import annotations

import argparse


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add this group's sub-commands."""
