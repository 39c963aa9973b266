"""The catalogue where it lives (issue 38): ``sessions list`` reads the folder ``run`` writes
to (``[paths] sessions`` of the bench file ``config init`` wrote); a sessions folder on
read-only media is listed (the catalogue is built in memory, nothing is written); a rebuild
that fails (a full disk) leaves no empty catalogue that is trusted afterwards.
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest
from many_sessions_helpers import copy_session
from sim_runs import RAD_SMALL, only_session

from benchlab.catalog import index
from benchlab.catalog.index import Catalog
from benchlab.cli.main import main

pytestmark = pytest.mark.timeout(120)


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One real simulated radiometry session."""
    root = tmp_path_factory.mktemp("source")
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL),
                 "--out", str(root), "--sample", "LED-1"]) == 0
    return only_session(root)


def _listed(capsys: pytest.CaptureFixture[str], *argv: str) -> list[str]:
    assert main(["sessions", "list", "--json", *argv]) == 0
    return [row["id"] for row in json.loads(capsys.readouterr().out)]


def test_sessions_list_reads_the_folder_config_init_set(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "home").mkdir()
    assert main(["config", "init"]) == 0  # [paths] sessions = "~/benchlab-sessions"
    monkeypatch.chdir(tmp_path)  # no ./sessions here
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL)]) == 0
    written = only_session(tmp_path / "home" / "benchlab-sessions")
    capsys.readouterr()
    assert _listed(capsys) == [written.name]
    assert main(["units", "--json"]) == 0
    assert main(["sessions", "list", "--root", str(tmp_path / "nowhere")]) == 1
    assert "nowhere: no such sessions folder (from --root)" in capsys.readouterr().err


def _tree_digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): (hashlib.sha256(p.read_bytes()).hexdigest()
                                       if p.is_file() else "dir")
            for p in sorted(root.rglob("*"))}


@pytest.fixture
def read_only_root(source: Path, tmp_path: Path,
                   monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A sessions folder with a session and a catalogue, then made read-only."""
    root = tmp_path / "archive"
    copy_session(source, root / source.name)
    with Catalog.open(root):
        pass
    paths = [root, *root.rglob("*")]
    for p in paths:
        p.chmod(p.stat().st_mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    if os.geteuid() == 0:  # permissions do not bind root: stand in for a read-only mount
        monkeypatch.setattr(index, "_read_only", lambda root, path: True)
    yield root
    for p in paths:
        p.chmod(p.stat().st_mode | stat.S_IWUSR)


def test_a_read_only_sessions_folder_is_listed_and_left_as_it_was(
        read_only_root: Path, source: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = _tree_digest(read_only_root)
    assert _listed(capsys, "--root", str(read_only_root)) == [source.name]
    assert main(["units", "--root", str(read_only_root), "--json"]) == 0
    assert [u["serial"] for u in json.loads(capsys.readouterr().out)] == ["LED-1"]
    assert _tree_digest(read_only_root) == before


def test_a_rebuild_that_fails_leaves_no_catalogue_to_trust(
        source: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "root"
    for i in range(40):  # more rows than the schema's empty pages hold
        copy_session(source, root / f"{source.name}-{i:02d}", sample=f"LED-{i}")
    real_migrate = index.migrate

    def full_disk_after_schema(conn: sqlite3.Connection, *args: object) -> int:
        before = real_migrate(conn, *args)  # type: ignore[arg-type]
        pages = conn.execute("PRAGMA page_count").fetchone()[0]
        conn.execute(f"PRAGMA max_page_count = {pages}")  # SQLite's own "disk is full"
        return before

    monkeypatch.setattr(index, "migrate", full_disk_after_schema)
    assert main(["sessions", "list", "--root", str(root)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot open or rebuild the catalogue" in err
    assert "full" in err
    assert sorted(p.name for p in root.iterdir() if not p.is_dir()) == []  # nothing left
    monkeypatch.setattr(index, "migrate", real_migrate)  # space again
    assert len(_listed(capsys, "--root", str(root))) == 40


def test_a_folder_name_that_is_not_utf8_is_listed(
        source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A session folder copied from another system with a Latin-1 name: listed with its byte
    escaped; before, the catalogue crashed with UnicodeEncodeError (or listed nothing)."""
    root = tmp_path / "root"
    copy_session(source, root / os.fsdecode(b"lens-\xe9t\xe9"))
    assert _listed(capsys, "--root", str(root)) == ["lens-\\xe9t\\xe9"]
    assert main(["sessions", "reindex", "--root", str(root)]) == 0
    assert "1 sessions indexed" in capsys.readouterr().out
