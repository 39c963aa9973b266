"""benchlab.session.read_results: the one reader of a results/vN folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchlab.session import SessionError, read_results
from benchlab.storage import atomic_write_json


def test_reads_tables_and_summary(tmp_path: Path) -> None:
    atomic_write_json(tmp_path / "table_4_12.json", [{"lp": 0.5, "modulation": 0.75}])
    atomic_write_json(tmp_path / "summary.json", {"estimator": "sinefit"})
    tables, summary = read_results(tmp_path)
    assert tables == {"table_4_12": [{"lp": 0.5, "modulation": 0.75}]}
    assert summary == {"estimator": "sinefit"}


def test_corrupt_file_is_named(tmp_path: Path) -> None:
    (tmp_path / "table_4_11.json").write_text("{not json", encoding="utf-8")
    with pytest.raises(SessionError, match="table_4_11.json"):
        read_results(tmp_path)
