"""A damaged results version is an error naming the file (and key), never a traceback and
never a report with a table silently left out."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from many_sessions_helpers import copy_session, real_session
from sim_runs import reseal_results

from benchlab.cli.main import main
from benchlab.session import SessionError, read_results
from benchlab.storage import atomic_write_json


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return real_session(tmp_path_factory.mktemp("source"))


def _report_fails(session: Path, capsys: pytest.CaptureFixture[str]) -> str:
    assert main(["report", str(session)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("benchlab: error: ") and "Traceback" not in err
    assert not (session / "report.html").exists()  # nothing half-written
    return err


@pytest.mark.slow
def test_a_row_without_a_key_the_report_needs(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    s = copy_session(source, tmp_path / "s")
    table = s / "results" / "v1" / "forward_view_modulation.json"
    table.write_text('[{"element": "G1E5"}]')
    reseal_results(table.parent)
    err = _report_fails(s, capsys)
    assert f"{table}: row 1 has no 'image_lp_per_mm'" in err


@pytest.mark.slow
def test_a_value_of_the_wrong_kind_names_the_section(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    s = copy_session(source, tmp_path / "s")
    table = s / "results" / "v1" / "radial_view_modulation.json"
    rows = json.loads(table.read_text())
    rows[0]["object_lp_per_mm"] = "two"
    table.write_text(json.dumps(rows))
    reseal_results(table.parent)
    err = _report_fails(s, capsys)
    assert str(s / "results" / "v1") in err and "cannot be drawn" in err


@pytest.mark.parametrize(("content", "expected"), [
    (None, "radial_view_modulation.json: missing (summary.json lists table table_4_12)"),
    ("null", "averaged_mtf_vs_monte_carlo.json: not a table (a JSON list of row objects "
             "expected, found null)"),
    ('{"rows": []}', "averaged_mtf_vs_monte_carlo.json: not a table"),
    ("[1, 2]", "averaged_mtf_vs_monte_carlo.json: not a table (a JSON list of row objects "
               "expected, found a list holding int)"),
])
def test_a_listed_table_missing_or_not_rows(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | None,
    expected: str,
) -> None:
    s = copy_session(source, tmp_path / "s")
    v1 = s / "results" / "v1"
    if content is None:
        (v1 / "radial_view_modulation.json").unlink()
    else:
        (v1 / "averaged_mtf_vs_monte_carlo.json").write_text(content)
        reseal_results(v1)
    with pytest.raises(SessionError) as exc:
        read_results(v1)
    assert expected in str(exc.value)
    assert expected in _report_fails(s, capsys)


def test_read_results_checks_only_what_is_asked_and_the_summary(tmp_path: Path) -> None:
    atomic_write_json(tmp_path / "summary.json", {"tables": ["table_4_12", "table_4_13"]})
    atomic_write_json(tmp_path / "radial_view_modulation.json", [{"object_lp_per_mm": 2}])
    with pytest.raises(SessionError, match="image_heights_field_points.json: missing"):
        read_results(tmp_path)
    tables, _ = read_results(tmp_path, skip={"table_4_13"})  # not asked for: not checked
    assert tables == {"table_4_12": [{"object_lp_per_mm": 2}]}
    (tmp_path / "summary.json").write_text("[]")
    with pytest.raises(SessionError, match="summary.json: not a results summary"):
        read_results(tmp_path)
