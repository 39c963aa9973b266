"""No typo in a spec becomes a stored verdict (issue 38).

A spec naming a table, column or ``where`` key the results do not have, a limit on a text
column or a ``where`` value of the wrong type is a usage error (exit 2) naming the limit and
the field; nothing in the sessions folder changes (verdicts, journal, catalogue: the whole
folder is hashed). The journal keeps the spec's file and hash, not its text; an identical
verification stores no new version. The schema the spec is checked against is what the
procedures really write.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
from acceptance_sessions import limit, make_session, spec
from sim_runs import FIXTURES, MTF_SMALL, RAD_SMALL, run_sim

from benchlab.acceptance.results_schema import RESULTS_SCHEMA
from benchlab.acceptance.spec import MAX_SPEC_BYTES
from benchlab.cli.main import main
from benchlab.session import RESULT_FILE_STEMS, Session, read_results

ROOT = Path(__file__).resolve().parents[2]


def _folder_digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def stored(tmp_path: Path) -> Path:
    """A sessions folder with one session, verified once (a verdict, a catalogue)."""
    root = tmp_path / "sessions"
    session = make_session(root, "s1", serial="OBJ-1")
    assert main(["verify", str(session), "--spec", str(spec(tmp_path, limit(0.5)))]) == 0
    return session


TYPOS = {
    "unknown column": (limit(0.5, column="sagittal_modulatoin"),
                       "limit 'fwd-G2E2-S' (#1): field 'column': forward_view_modulation has "
                       "no column 'sagittal_modulatoin' (did you mean 'sagittal_modulation'?)"),
    "unknown table": (limit(0.5, table="forward_view_modulatoin"),
                      "field 'table': no results table 'forward_view_modulatoin' (did you "
                      "mean 'forward_view_modulation'?)"),
    "where of the wrong type": (limit(0.5, where="{ element = 5 }"),
                                "field 'where.element': forward_view_modulation.element holds "
                                "text; got 5"),
    "where on an unknown column": (limit(0.5, where='{ elemnt = "G2E2" }'),
                                   "field 'where.elemnt': forward_view_modulation has no "
                                   "column 'elemnt'"),
    "text column": (limit(0.5, column="sagittal_estimator"),
                    "field 'column': forward_view_modulation.sagittal_estimator holds text, "
                    "not a number"),
    "thesis label, unknown column": (limit(0.5, table="table_4_11", column="modulation"),
                                     "field 'column': table_4_11 has no column 'modulation'"),
    "fov verdict is text": (limit(15.0, table="field_of_view", column="verdict",
                                  where='{ quantity = "radial_fov_deg" }'),
                            "field 'column': field_of_view.verdict holds text, not a number"),
    "fov mapping unknown column": (limit(2.0, table="image_height_mapping",
                                         column="image_height", where='{ view = "radial" }'),
                                   "field 'column': image_height_mapping has no column "
                                   "'image_height' (did you mean 'image_height_mm'?)"),
    "number where on text": (limit(0.5, table="characterisation", column="read_noise_e",
                                   where='{ gain = "1" }'),
                             "field 'where.gain': characterisation.gain holds number; "
                             "got '1'"),
}


@pytest.mark.parametrize("case", sorted(TYPOS))
def test_a_typo_is_a_usage_error_and_nothing_is_written(
    stored: Path, tmp_path: Path, case: str, capsys: pytest.CaptureFixture[str]
) -> None:
    text, message = TYPOS[case]
    path = spec(tmp_path, text)
    root = stored.parent
    before = _folder_digest(root)
    capsys.readouterr()
    assert main(["verify", str(stored), "--spec", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"benchlab: error: {path}: spec not usable (")
    assert message in err, err
    assert _folder_digest(root) == before  # no verdicts/v2, journal and catalogue as they were
    assert main(["lot", "L1", "--spec", str(path), "--root", str(root)]) == 2


def test_every_problem_is_listed_at_once(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    path = spec(tmp_path, *(t for t, _ in (TYPOS[c] for c in ("unknown column", "text column"))))
    path.write_text(path.read_text().replace('id = "fwd-G2E2-S"', 'id = "a"', 1)
                    .replace('id = "fwd-G2E2-S"', 'id = "b"', 1))
    assert main(["verify", "--spec", str(path)]) == 2
    err = capsys.readouterr().err
    assert "(2 problems)" in err and "limit 'a' (#1)" in err and "limit 'b' (#2)" in err


def test_a_huge_spec_is_refused_before_it_is_read(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path = spec(tmp_path, limit(0.5))
    path.write_text(path.read_text() + "#" * MAX_SPEC_BYTES)
    assert main(["verify", "--spec", str(path)]) == 2
    assert "a spec is at most 1048576 bytes" in capsys.readouterr().err
    long_name = spec(tmp_path, limit(0.5))
    long_name.write_text(long_name.read_text().replace('name = "objective"',
                                                       f'name = "{"n" * 5000}"'))
    assert main(["verify", "--spec", str(long_name)]) == 2
    assert "field 'name': 5000 characters; at most 200" in capsys.readouterr().err


def _journal(session: Path) -> list[dict]:
    return [json.loads(line) for line in (session / "events.jsonl").read_text().splitlines()]


def test_the_journal_keeps_the_spec_hash_and_identical_verdicts_store_once(
    stored: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = spec(tmp_path, limit(0.5))
    path.write_text(path.read_text().replace('revision = "B"',
                                             f'revision = "B"\ndescription = "{"d" * 100_000}"'))
    size = (stored / "events.jsonl").stat().st_size
    assert main(["verify", str(stored), "--spec", str(path)]) == 0
    event = _journal(stored)[-1]
    assert event["kind"] == "verdict_written" and event["version"] == 2
    assert event["spec_file"] == str(path)
    assert event["spec_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert (stored / "events.jsonl").stat().st_size - size < 400  # not the 100 kB description
    assert json.loads((stored / "verdicts" / "v2.json").read_text())["spec"]["sha256"] == \
        event["spec_sha256"]
    journal = (stored / "events.jsonl").read_bytes()
    capsys.readouterr()
    for _ in range(3):  # the same verification again: nothing new
        assert main(["verify", str(stored), "--spec", str(path)]) == 0
        assert "identical to" in capsys.readouterr().out
    assert sorted(p.name for p in (stored / "verdicts").iterdir()) == ["v1.json", "v2.json"]
    assert (stored / "events.jsonl").read_bytes() == journal
    path.write_text(path.read_text().replace("min = 0.5", "min = 0.4"))  # a new spec: stored
    assert main(["verify", str(stored), "--spec", str(path)]) == 0
    assert (stored / "verdicts" / "v3.json").is_file()


def test_limits_may_name_the_field_of_view_tables(tmp_path: Path) -> None:
    from benchlab.acceptance.spec import load_spec

    path = spec(tmp_path,
                limit(15.0, ident="radial-fov", table="field_of_view", column="value",
                      where='{ quantity = "radial_fov_deg" }'),
                limit(2.6, 2.7, ident="radial-26", table="image_height_mapping",
                      column="image_height_mm", where='{ view = "radial", field_angle_deg = -26 }'),
                limit(None, 0.5, ident="rings", table="radial_rings", column="rms_um",
                      where="{ position_mm = 12.0 }"),
                limit(-8.0, ident="barrel", table="distortion", column="rectilinear_pct",
                      where="{ field_angle_deg = 25.0 }"))
    assert [lim.id for lim in load_spec(path).limits] == ["radial-fov", "radial-26", "rings",
                                                         "barrel"]


# ---- the schema is what the procedures write ---------------------------------------------------
@pytest.mark.slow
def test_the_schema_holds_every_column_the_procedures_write(tmp_path: Path) -> None:
    """Simulated MTF, radiometry, characterisation and field-of-view runs: every table and
    column they write is in the schema, with the kind its values have."""
    kinds = {bool: "bool", int: "number", float: "number", str: "text", list: "list"}
    seen: set[str] = set()
    for procedure, params in (("mtf", MTF_SMALL), ("radiometry", RAD_SMALL),
                              ("characterise", FIXTURES / "characterise-small.toml"),
                              ("fov", FIXTURES / "fov-small.toml")):
        session = run_sim(procedure, tmp_path, params).session_path
        latest = Session.open(session).latest_results()
        assert latest is not None
        tables, _ = read_results(latest)
        for label, rows in tables.items():
            name = RESULT_FILE_STEMS.get(label, label)
            assert name in RESULTS_SCHEMA, name
            columns = RESULTS_SCHEMA[name]
            assert columns is not None
            seen.add(name)
            for row in rows:
                for column, value in row.items():
                    assert column in columns, (name, column)
                    if value is not None:
                        assert kinds[type(value)] == columns[column], (name, column, value)
    # the MTF tables, radiometry, characterisation and its two others, the five fov tables
    assert len(seen) >= 16
    assert {"field_of_view", "image_height_mapping", "radial_rings"} <= seen


def test_the_results_page_names_every_table_of_the_schema() -> None:
    page = (ROOT / "docs" / "formats" / "results.md").read_text(encoding="utf-8")
    missing = [name for name in RESULTS_SCHEMA if f"`{name}`" not in page]
    assert missing == []
