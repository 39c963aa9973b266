"""Sessions of one unit whose readings disagree beyond their uncertainties (issue 38): flagged
in ``verify`` (the row's notes, never a pass), ``units`` and the certificate, naming both
sessions, the table, row and column and both readings with their intervals - not decided
silently by start time."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from acceptance_sessions import limit, make_session, spec

from benchlab.acceptance.agreement import normalised_error
from benchlab.acceptance.certificate import certificate_content
from benchlab.acceptance.decide import Reading
from benchlab.acceptance.store import read_verdict
from benchlab.cli.main import main

K95 = 1.959963984540054
OLD = "2000-01-01T00:00:00+00:00"


def _unit(root: Path, old_modulation: float) -> tuple[Path, Path]:
    """SN1 measured twice: ``new`` reads 0.60 +- 0.01 (1 sigma), ``old`` (started in 2000)
    ``old_modulation`` +- 0.01."""
    new = make_session(root, "new", serial="SN1", lot="L1", modulation=0.60)
    old = make_session(root, "old", serial="SN1", lot="L1", modulation=old_modulation,
                       started=OLD)
    return new, old


def test_disagreeing_sessions_are_named_and_never_pass(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    new, old = _unit(tmp_path / "root", 0.30)
    path = spec(tmp_path, limit(0.55))
    assert main(["verify", str(new), str(old), "--spec", str(path)]) == 3  # was: 0, silently
    out = capsys.readouterr().out
    lo_new, hi_new = 0.60 - K95 * 0.01, 0.60 + K95 * 0.01
    lo_old, hi_old = 0.30 - K95 * 0.01, 0.30 + K95 * 0.01
    text = (f"sessions disagree beyond their uncertainties on forward_view_modulation "
            f"element=G2E2 sagittal_modulation: new 0.6 [{lo_new:.4g}, {hi_new:.4g}] (decides) "
            f"vs old 0.3 [{lo_old:.4g}, {hi_old:.4g}], E_n 10.8")
    assert text in out, out
    assert "sessions of the unit disagree: never a pass" in out
    assert "unit verdict: INDETERMINATE" in out
    record = read_verdict(new)
    assert record == read_verdict(old)  # the same record in both sessions
    (d,) = record["disagreements"]
    assert (d["limit_id"], d["table"], d["row"], d["column"]) == (
        "fwd-G2E2-S", "forward_view_modulation", "element=G2E2", "sagittal_modulation")
    assert d["decided"] == {"session": "new", "value": 0.60, "low": pytest.approx(lo_new),
                            "high": pytest.approx(hi_new)}
    assert d["other"]["session"] == "old" and d["other"]["value"] == 0.30
    assert d["normalised_error"] == pytest.approx(0.30 / (K95 * 0.01 * 2**0.5))
    (row,) = record["rows"]
    assert row["verdict"] == "indeterminate" and row["reading"] == 0.60

    # units: the verdict is marked and the mark explained
    assert main(["units", "--root", str(tmp_path / "root")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split() == ["SN1", "L1", "2", "indeterminate*"]
    assert lines[-1].startswith("* sessions of the unit disagree beyond their uncertainties")
    assert main(["units", "--root", str(tmp_path / "root"), "--json"]) == 0
    (unit,) = json.loads(capsys.readouterr().out)
    assert unit["verdicts"]["objective"]["disagreements"] == 1

    # the certificate: its own section, and the row's note
    assert main(["certificate", str(new)]) == 0
    page = (new / "certificate-v1.html").read_text()
    assert page.count(text) == 2 and "Sessions that disagree" in page
    assert certificate_content(record, "new").disagreements == (text,)


def test_a_fail_stays_a_fail_with_the_note(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    new, old = _unit(tmp_path / "root", 0.30)
    assert main(["verify", str(new), str(old), "--spec", str(spec(tmp_path, limit(0.70)))]) == 1
    (row,) = read_verdict(new)["rows"]
    assert row["verdict"] == "fail"
    assert any(n.startswith("sessions disagree beyond") for n in row["notes"])
    assert "unit verdict: FAIL" in capsys.readouterr().out


def test_sessions_that_agree_within_their_uncertainties_are_not_flagged(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    new, old = _unit(tmp_path / "root", 0.62)  # E_n = 0.02 / 0.0277 = 0.72
    assert main(["verify", str(new), str(old), "--spec", str(spec(tmp_path, limit(0.55)))]) == 0
    record = read_verdict(new)
    assert record["disagreements"] == [] and record["rows"][0]["notes"] == []
    assert "disagree" not in capsys.readouterr().out
    assert main(["units", "--root", str(tmp_path / "root")]) == 0
    assert capsys.readouterr().out.splitlines()[1].split() == ["SN1", "L1", "2", "pass"]


def test_normalised_error_uses_the_facing_sides_of_the_intervals() -> None:
    a = Reading(0.6, 0.5, 0.61)  # wide below: the side facing b
    b = Reading(0.4, 0.39, 0.45)  # wide above
    assert normalised_error(a, b) == pytest.approx(0.2 / (0.1**2 + 0.05**2) ** 0.5)
    assert normalised_error(b, a) == normalised_error(a, b)
    assert normalised_error(a, Reading(0.4)) is None  # no interval: not compared
