"""Re-analysis that does not pile up (issue 29): a re-analysis whose frames, settings, software
version and results match an existing version adds no version and says which; anything else
still adds one, and the history stays append-only."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sim_runs import RAD_SMALL, events, only_session, run_sim

from benchlab.cli.main import main
from benchlab.protocols.runs import reanalyze
from benchlab.session import Session
from benchlab.session import results as session_mod


@pytest.fixture(scope="module")
def radiometry_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("reanalysis")
    run_sim("radiometry", root, RAD_SMALL)
    return only_session(root)


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    out = dst / src.name
    shutil.copytree(src, out)
    return out


@pytest.mark.slow
def test_fifty_identical_reanalyses_leave_one_version(radiometry_session: Path,
                                                      tmp_path: Path) -> None:
    path = _copy(radiometry_session, tmp_path)
    assert Session.open(path).result_versions() == [1]
    v1 = (path / "results" / "v1")
    files_before = {p.name: p.read_bytes() for p in v1.iterdir()}
    for _ in range(50):
        assert reanalyze(path, catalogue=False) == v1
    assert Session.open(path).result_versions() == [1]
    assert {p.name: p.read_bytes() for p in v1.iterdir()} == files_before  # untouched
    matched = [e for e in events(path) if e.get("kind") == "results_matched"]
    assert len(matched) == 50 and {e["version"] for e in matched} == {1}


@pytest.mark.slow
def test_a_different_estimator_or_software_version_adds_a_version(
    radiometry_session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = _copy(radiometry_session, tmp_path)
    monkeypatch.setattr(session_mod, "_software_version", lambda: "99.0.0")
    v2 = reanalyze(path, catalogue=False)
    assert v2.name == "v2"
    assert json.loads((v2 / "summary.json").read_text())["software_version"] == "99.0.0"
    assert reanalyze(path, catalogue=False) == v2  # the same again: matches v2, not v1
    monkeypatch.setattr(session_mod, "_software_version", lambda: "99.0.1")
    assert reanalyze(path, catalogue=False).name == "v3"
    assert reanalyze(path, catalogue=False, new_version=True).name == "v4"  # asked for one
    assert Session.open(path).result_versions() == [1, 2, 3, 4]


@pytest.mark.slow
def test_results_that_differ_add_a_version(radiometry_session: Path, tmp_path: Path) -> None:
    """Same frames, settings and software: a result file edited in v1 (results differ) means
    a new version, never a match with different bytes."""
    path = _copy(radiometry_session, tmp_path)
    v1 = path / "results" / "v1"
    table = next(p for p in sorted(v1.glob("*.csv")))
    table.write_text(table.read_text() + "\n")
    assert reanalyze(path, catalogue=False).name == "v2"
    assert reanalyze(path, catalogue=False).name == "v2"


def test_cli_says_which_version_it_matches(radiometry_session: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    path = _copy(radiometry_session, tmp_path)
    assert main(["analyze", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["matched_version"] == 1 and doc["results"].endswith("v1")
    assert main(["analyze", str(path)]) == 0
    out = capsys.readouterr().out
    assert "identical to v1 (same frames, settings, software version and results): no new " \
           "version written" in out
    assert Session.open(path).result_versions() == [1]
