"""Results files are named after what they hold; the thesis table label stays the key, and
sessions written with the old thesis-table file names still read back."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

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


def test_a_version_is_never_visible_before_it_is_complete(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C at the rename leaves no results/vN (the number was claimed by an empty folder
    before, which then became "latest"); folders without summary.json are no version."""
    session = _session(tmp_path)
    v1 = session.write_results({"t": ROWS}, summary={}, estimator="histogram")

    def interrupted(src: object, dst: object) -> None:
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr("benchlab.session.results.os.rename", interrupted)
        with pytest.raises(KeyboardInterrupt):
            session.write_results({"t": ROWS}, summary={}, estimator="histogram")
    assert sorted(p.name for p in session.results_dir.iterdir()) == ["v1"]
    assert session.latest_results() == v1 and session.result_versions() == [1]
    # What older software left behind: an empty v2 and a v3 without its summary.
    (session.results_dir / "v2").mkdir()
    (session.results_dir / "v3").mkdir()
    (session.results_dir / "v3" / "t.json").write_text("[]")
    assert session.result_versions() == [1] and session.latest_results() == v1
    v2 = session.write_results({"t": ROWS}, summary={"n": 2}, estimator="histogram")
    assert v2.name == "v2" and (v2 / "summary.json").is_file()  # the empty folder replaced
    v4 = session.write_results({"t": ROWS}, summary={"n": 4}, estimator="histogram")
    assert v4.name == "v4" and json.loads((v4 / "summary.json").read_text())["version"] == 4
    assert (session.results_dir / "v3" / "t.json").read_text() == "[]"  # never touched
    assert session.result_versions() == [1, 2, 4]


def test_extra_folders_arrive_with_the_version(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """``unwrap`` writes its view TIFFs beside a version: they move in before the version
    appears, so an interruption leaves no version without them (it used to rename them in
    after the version was visible)."""
    session = _session(tmp_path)
    staged = session.results_dir / ".unwrap-x.tmp"
    staged.mkdir(parents=True)
    (staged / "a.tiff").write_bytes(b"view")
    v1 = session.write_results({"t": ROWS}, summary={}, estimator="unwrap",
                               extra_dirs={"unwrapped": staged})
    assert (v1 / "unwrapped" / "a.tiff").read_bytes() == b"view" and not staged.exists()
    staged.mkdir()
    (staged / "b.tiff").write_bytes(b"view")

    def interrupted(src: object, dst: object) -> None:
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr("benchlab.session.results.os.rename", interrupted)
        with pytest.raises(KeyboardInterrupt):
            session.write_results({"t": ROWS}, summary={}, estimator="unwrap",
                                  extra_dirs={"unwrapped": staged})
    assert session.result_versions() == [1]
    assert sorted(p.name for p in session.results_dir.iterdir()) == ["v1"]
    # What a kill leaves behind is cleaned by the next writer.
    (session.results_dir / ".unwrap-y.tmp").mkdir()
    assert session.remove_temporary_files() == ["results/.unwrap-y.tmp"]
