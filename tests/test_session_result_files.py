"""Results files are named after what they hold; the thesis table label stays the key, and
sessions written with the old thesis-table file names still read back."""

from __future__ import annotations

import json
from pathlib import Path

from benchlab.session import RESULT_FILE_STEMS, Session, read_results
from benchlab.storage import atomic_write_json

ROWS = [{"object_lp_per_mm": 4.0, "sagittal_modulation": 0.5}]


def _session(tmp_path: Path) -> Session:
    return Session.create(tmp_path, procedure="mtf", params={}, operator="t", devices={},
                          software_version="0", name="s")


def test_written_under_descriptive_names_read_back_under_labels(tmp_path: Path) -> None:
    session = _session(tmp_path)
    folder = session.write_results({"table_4_12": ROWS, "extra_table": ROWS},
                                   summary={"n": 1}, estimator="histogram")
    names = sorted(p.name for p in folder.iterdir())
    assert names == ["extra_table.csv", "extra_table.json", "radial_view_modulation.csv",
                     "radial_view_modulation.json", "summary.json"]
    summary_doc = json.loads((folder / "summary.json").read_text())
    assert summary_doc["table_files"] == {"extra_table": "extra_table",
                                          "table_4_12": "radial_view_modulation"}
    tables, summary = read_results(folder)
    assert tables == {"table_4_12": ROWS, "extra_table": ROWS}
    assert summary["summary"] == {"n": 1}


def test_old_thesis_file_names_still_read(tmp_path: Path) -> None:
    for label in RESULT_FILE_STEMS:
        atomic_write_json(tmp_path / f"{label}.json", ROWS)
    tables, _ = read_results(tmp_path)
    assert sorted(tables) == sorted(RESULT_FILE_STEMS)


def test_every_file_name_says_what_it_holds() -> None:
    stems = list(RESULT_FILE_STEMS.values())
    assert len(set(stems)) == len(stems)
    assert not any(stem.startswith("table_") for stem in stems)
