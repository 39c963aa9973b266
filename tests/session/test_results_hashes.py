"""Results that certify themselves (issue 38): each version records the sha256 of every table
file it wrote, and every reader (report, verify, certificate, the catalogue) refuses a table
that changed, naming the file."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from benchlab.cli.main import main
from benchlab.session import Session, SessionError, read_results


def _session(root: Path) -> Session:
    s = Session.create(root, procedure="mtf", params={}, operator="t", devices={},
                       software_version="t")
    s.write_results({"table_4_11": [{"element": "G2E2", "sagittal_modulation": 0.766}]},
                    summary={}, estimator="histogram")
    s.finish()
    s.release()
    return s


def test_a_version_records_the_hash_of_each_file_it_wrote(tmp_path: Path) -> None:
    s = _session(tmp_path)
    v1 = s.path / "results" / "v1"
    doc = json.loads((v1 / "summary.json").read_text(encoding="utf-8"))
    files = sorted(p.name for p in v1.iterdir() if p.name != "summary.json")
    assert sorted(doc["files_sha256"]) == files
    for name in files:
        assert doc["files_sha256"][name] == hashlib.sha256((v1 / name).read_bytes()).hexdigest()
    tables, _ = read_results(v1)
    assert tables["table_4_11"][0]["sagittal_modulation"] == 0.766


def test_an_edited_table_is_refused_by_every_reader(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    s = _session(tmp_path)
    table = next(p for p in (s.path / "results" / "v1").glob("*.json")
                 if p.name != "summary.json")
    table.write_text(table.read_text(encoding="utf-8").replace("0.766", "0.3"),
                     encoding="utf-8")
    with pytest.raises(SessionError, match=rf"{table.name}: changed since it was written"):
        read_results(table.parent)
    out = tmp_path / "r.html"
    assert main(["report", str(s.path), "--out", str(out)]) == 1
    assert f"{table.name}: changed since it was written" in capsys.readouterr().err
    assert not out.exists()


def test_a_version_from_before_the_hashes_still_reads(tmp_path: Path) -> None:
    s = _session(tmp_path)
    summary = s.path / "results" / "v1" / "summary.json"
    doc = json.loads(summary.read_text(encoding="utf-8"))
    del doc["files_sha256"]
    summary.write_text(json.dumps(doc), encoding="utf-8")
    tables, _ = read_results(summary.parent)
    assert tables["table_4_11"][0]["element"] == "G2E2"
