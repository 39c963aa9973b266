"""A session folder whose name is not UTF-8 (copied from another system) under the sessions
folder (issue 38): listed, reindexed, shown, verified, counted in its lot and certified -
its name shown as ``bad\\xffname`` - never an empty listing or a traceback."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from acceptance_sessions import limit, make_session, spec
from sim_runs import MTF_SMALL, run_sim

from benchlab.catalog.index import CATALOG_FILE, session_folder
from benchlab.cli.main import main
from benchlab.storage import printable_name

RAW = b"bad\xffname"  # not UTF-8: Python names it "bad\udcffname"
SHOWN = "bad\\xffname"


def _rename(folder: Path) -> Path:
    target = folder.parent / os.fsdecode(RAW)
    folder.rename(target)
    return target


@pytest.fixture
def root(tmp_path: Path) -> Path:
    root = tmp_path / "root"
    make_session(root, "good", serial="SN1", lot="L1")
    _rename(make_session(root, "other", serial="SN2", lot="L1"))
    (root / CATALOG_FILE).unlink(missing_ok=True)  # built afresh from the folders
    return root


def test_printable_name_escapes_only_what_is_not_utf8() -> None:
    assert printable_name(os.fsdecode(RAW)) == SHOWN
    assert printable_name("objectif \u2265 B") == "objectif \u2265 B"


def test_list_reindex_and_show(root: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["sessions", "list", "--root", str(root)],
                 ["sessions", "reindex", "--root", str(root)],
                 ["sessions", "list", "--root", str(root), "--json"]):
        assert main(argv) == 0, argv
    out = capsys.readouterr().out
    assert "2 sessions indexed" in out
    listed = json.loads(out.splitlines()[-1])
    assert sorted(s["id"] for s in listed) == [SHOWN, "good"]
    for name in (os.fsdecode(RAW), SHOWN):  # the name as the shell passes it, or as shown
        assert main(["sessions", "show", name, "--root", str(root)]) == 0, name
        first = capsys.readouterr().out.splitlines()[0]
        assert first.split() == ["id", SHOWN]
    assert session_folder(str(root / SHOWN)) == root / os.fsdecode(RAW)
    # the terminal UI's sessions screen opens the folder itself, not the escaped name
    from benchlab.tui.services import catalog_sessions

    paths = {s.path.name: s.path for s in catalog_sessions(root)}
    assert paths[os.fsdecode(RAW)] == root / os.fsdecode(RAW)


def test_verify_lot_and_certificate(root: Path, tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    bad = root / os.fsdecode(RAW)
    path = spec(tmp_path, limit(0.55))
    assert main(["verify", str(bad), "--spec", str(path)]) == 0
    assert main(["lot", "L1", "--spec", str(path), "--root", str(root), "--json"]) == 0
    capsys.readouterr()
    assert main(["lot", "L1", "--spec", str(path), "--root", str(root), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["units"] == 2 and result["verdicts"]["pass"] == 2
    assert main(["certificate", str(bad)]) == 0
    assert f"certificate: {root}/{SHOWN}/certificate-v1.html" in capsys.readouterr().out
    page = (bad / "certificate-v1.html").read_text(encoding="utf-8")
    assert f"{SHOWN} verdicts/v1.json" in page


@pytest.mark.slow
def test_pdf_certificate(root: Path, tmp_path: Path) -> None:
    bad = root / os.fsdecode(RAW)
    assert main(["verify", str(bad), "--spec", str(spec(tmp_path, limit(0.55)))]) == 0
    assert main(["certificate", str(bad), "--pdf"]) == 0
    assert (bad / "certificate-v1.pdf").read_bytes().startswith(b"%PDF-")


@pytest.mark.slow
def test_report_of_a_session_so_named(tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    session = _rename(run_sim("mtf", tmp_path / "root", MTF_SMALL).session_path)
    assert main(["report", str(session)]) == 0, capsys.readouterr().err
    # printed and written with the name escaped (a UTF-8 terminal refused the raw name)
    assert f"report: {session.parent}/{SHOWN}/report.html" in capsys.readouterr().out
    page = (session / "report.html").read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>") and f"session {SHOWN}</h1>" in page
    assert main(["analyze", str(session)]) == 0, capsys.readouterr().err
