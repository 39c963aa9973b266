"""The thesis's chapter 4 tables as package data (``benchlab/analysis/data/*.csv``).

Each file starts with ``#`` comment lines naming the table, then a CSV header.
"""

from __future__ import annotations

import csv
from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent / "data"


def thesis_fixture_path(name: str) -> Path:
    """Path of a thesis table shipped with the package.

    Parameters
    ----------
    name : str
        File name with or without ``.csv``, e.g. ``"table_4_15_monte_carlo"``.

    Raises
    ------
    FileNotFoundError
        Naming the files that do exist.
    """
    path = DATA_DIR / (name if name.endswith(".csv") else f"{name}.csv")
    if not path.is_file():
        available = sorted(p.name for p in DATA_DIR.glob("*.csv"))
        raise FileNotFoundError(f"no thesis table {name!r} in {DATA_DIR}; have {available}")
    return path


def read_table(path: str | Path) -> list[dict[str, str]]:
    """Rows of a commented CSV file as dicts of strings (``#`` lines skipped).

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file, or no header row.
    """
    path = Path(path)
    with path.open(newline="", encoding="utf-8") as fh:
        lines = [ln for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"{path}: no header row")
    return [dict(row) for row in csv.DictReader(lines)]


def optional_float(text: str | None) -> float | None:
    """``float(text)``, or ``None`` for an empty cell / ``N/A``."""
    if text is None:
        return None
    text = text.strip()
    if text == "" or text.upper() in {"N/A", "NA", "-"}:
        return None
    return float(text)
