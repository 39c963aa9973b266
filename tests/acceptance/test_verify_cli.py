"""``benchlab verify / units / unit / lot / certificate`` on sessions with known readings."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from acceptance_sessions import limit, make_session, spec

from benchlab.acceptance.store import read_verdict, verdict_versions
from benchlab.catalog.index import Catalog
from benchlab.cli.main import main
from benchlab.session import Session

K95 = 1.959963984540054


@pytest.mark.parametrize(("min_", "status", "verdict"), [
    (0.55, 0, "pass"), (0.65, 1, "fail"), (0.60, 3, "indeterminate")])
def test_verdict_and_exit_status_for_limits_below_above_and_at_the_reading(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], min_: float, status: int,
        verdict: str) -> None:
    s = make_session(tmp_path / "root", "s1", serial="SN1")
    assert main(["verify", str(s), "--spec", str(spec(tmp_path, limit(min_))), "--json"]) \
        == status
    record = json.loads(capsys.readouterr().out)
    assert record["verdict"] == verdict
    (row,) = record["rows"]
    assert row["reading"] == 0.60
    assert (row["low"], row["high"]) == pytest.approx((0.60 - 0.01 * K95, 0.60 + 0.01 * K95))
    assert row["margin"] == pytest.approx(0.60 - min_)
    assert (row["rule"], row["row"], row["min"]) == ("guarded", "element=G2E2", min_)


def test_simple_rule_at_the_reading_passes_and_says_the_reading_decided(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    s = make_session(tmp_path / "root", "s1")
    assert main(["verify", str(s), "--spec", str(spec(tmp_path, limit(0.60), rule="simple"))]) \
        == 0
    out = capsys.readouterr().out
    assert "pass (reading decides)" in out
    assert "simple acceptance: the interval straddles the limit" in out


def test_a_not_resolved_reading_never_passes(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    s = make_session(tmp_path / "root", "s1", resolved=False)
    for rule in ("guarded", "simple"):
        assert main(["verify", str(s), "--spec", str(spec(tmp_path, limit(0.1), rule=rule)),
                     "--json", "--no-store"]) == 3
        (row,) = json.loads(capsys.readouterr().out)["rows"]
        assert row["verdict"] == "indeterminate"
        assert "not resolved (sagittal_resolved): never a pass" in row["notes"]


def test_a_missing_table_or_row_is_indeterminate_never_pass(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    s = make_session(tmp_path / "root", "s1")
    path = spec(tmp_path, limit(0.1, where='{ element = "G9E9" }'),
                limit(0.1, ident="gain", table="characterisation",
                      column="system_gain_dn_per_e", where="{}"))
    assert main(["verify", str(s), "--spec", str(path), "--json", "--no-store"]) == 3
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [r["verdict"] for r in rows] == ["indeterminate", "indeterminate"]
    assert "no row of forward_view_modulation in s1 matches element = 'G9E9'" in rows[0]["notes"]
    assert "table 'characterisation' is in no results of s1" in rows[1]["notes"][0]


def test_malformed_spec_is_a_usage_error_listing_every_problem_before_reading(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = spec(tmp_path, '\n[[limit]]\nid = "x"\ntable = "t"\ncolumn = "c"\nmni = 1\n',
               rule="strict")
    missing_session = tmp_path / "no-such-session"
    assert main(["verify", str(missing_session), "--spec", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: spec not usable (3 problems)" in err
    assert f"{bad}: field 'decision_rule'" in err
    assert f"{bad}: limit 'x' (#1): field 'mni': unknown" in err
    assert f"{bad}: limit 'x' (#1): field 'min': a limit needs" in err
    assert "no-such-session" not in err  # the spec was refused before any session was read


def test_reverification_adds_a_version_and_never_edits(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    s = make_session(tmp_path / "root", "s1", serial="SN1", lot="L1")
    assert main(["verify", str(s), "--spec", str(spec(tmp_path, limit(0.55)))]) == 0
    first = (s / "verdicts" / "v1.json").read_bytes()
    assert main(["verify", str(s), "--spec", str(spec(tmp_path, limit(0.65)))]) == 1
    assert verdict_versions(s) == [1, 2]
    assert (s / "verdicts" / "v1.json").read_bytes() == first
    assert read_verdict(s)["verdict"] == "fail" and read_verdict(s, 1)["verdict"] == "pass"
    events = [json.loads(x) for x in (s / "events.jsonl").read_text().splitlines()]
    assert [e["version"] for e in events if e["kind"] == "verdict_written"] == [1, 2]
    with Catalog.open(tmp_path / "root") as catalog:  # the catalogue has them too
        rows = catalog.conn.execute("SELECT version, verdict, serial, lot, spec_revision FROM "
                                    "verdicts ORDER BY version").fetchall()
        assert [tuple(r) for r in rows] == [(1, "pass", "SN1", "L1", "B"),
                                            (2, "fail", "SN1", "L1", "B")]
        catalog.reindex()  # rebuilt from the folders: the same rows
        assert catalog.conn.execute("SELECT count(*) FROM verdicts").fetchone()[0] == 2
    capsys.readouterr()


def test_sessions_of_one_serial_are_one_unit(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "root"
    mtf = make_session(root, "mtf", serial="SN7")
    cam = make_session(root, "cam", serial="SN7", modulation=None, gain=0.205,
                       started="2000-01-01T00:00:00+00:00")  # older: the MTF comes from `mtf`
    # (a reading of its own that disagreed with `mtf` would be flagged: test_sessions_disagree)
    path = spec(tmp_path, limit(0.55), limit(max_=0.21, ident="gain", table="characterisation",
                                              column="system_gain_dn_per_e", where="{}"))
    assert main(["verify", str(mtf), str(cam), "--spec", str(path), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["limits"] == {"fwd-G2E2-S": "pass", "gain": "pass"}
    assert [s["id"] for s in record["sessions"]] == ["mtf", "cam"]
    assert verdict_versions(mtf) == verdict_versions(cam) == [1]


def test_units_unit_and_certificate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "root"
    s = make_session(root, "s1", serial="SN1", lot="L1")
    make_session(root, "s2", serial="SN2", lot="L1")
    assert main(["verify", str(s), "--spec", str(spec(tmp_path, limit(0.55)))]) == 0
    capsys.readouterr()
    assert main(["units", "--root", str(root)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["serial", "lot", "sessions", "objective"]
    assert lines[1].split() == ["SN1", "L1", "1", "pass"]
    assert lines[2].split() == ["SN2", "L1", "1", "-"]
    assert main(["unit", str(s), "--lot", "L2", "--reason", "wrong lot typed"]) == 0
    meta = json.loads((s / "session.json").read_text())
    assert (meta["sample"], meta["lot"]) == ("SN1", "L2")
    (event,) = [json.loads(x) for x in (s / "events.jsonl").read_text().splitlines()
                if "unit_relabelled" in x]
    assert (event["old"], event["new"], event["reason"]) == ({"lot": "L1"}, {"lot": "L2"},
                                                             "wrong lot typed")
    capsys.readouterr()
    assert main(["units", "--root", str(root), "--lot", "L2", "--json"]) == 0
    (unit,) = json.loads(capsys.readouterr().out)
    assert unit["serial"] == "SN1" and unit["verdicts"]["objective"]["verdict"] == "pass"
    assert main(["certificate", str(s)]) == 0
    page = (s / "certificate-v1.html").read_text()
    for text in ("SN1", "objective", "Guarded (ISO 14253-1)", "fwd-G2E2-S", "element=G2E2",
                 "0.6", "\u2265 0.55", read_verdict(s)["spec"]["sha256"], "benchlab "):
        assert text in page, text
    assert "@media print" in page and "http" not in page.replace("http-equiv", "")


def test_lot_reports_yield_and_cpk_on_a_simulated_lot(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    root = tmp_path / "root"
    rng = np.random.default_rng(28)
    readings = rng.normal(0.62, 0.02, size=30)
    for i, m in enumerate(readings):
        make_session(root, f"u{i:02d}", serial=f"SN{i:02d}", lot="L9", modulation=float(m),
                     sigma=0.005, started=f"2026-01-01T00:{i:02d}:00+00:00")
    make_session(root, "other", serial="X", lot="L8")
    path = spec(tmp_path, limit(0.58))
    html = tmp_path / "lot.html"
    assert main(["lot", "L9", "--spec", str(path), "--root", str(root), "--json",
                 "--html", str(html)]) == 0
    result = json.loads(capsys.readouterr().out)
    low_end, high_end = readings - 0.005 * K95, readings + 0.005 * K95
    passed = int(np.sum(low_end >= 0.58))
    failed = int(np.sum(high_end < 0.58))
    assert result["units"] == 30
    assert result["verdicts"] == {"pass": passed, "fail": failed,
                                  "indeterminate": 30 - passed - failed}
    (q,) = result["quantities"]
    mean, s = float(np.mean(readings)), float(np.std(readings, ddof=1))
    assert q["mean"] == pytest.approx(mean)
    assert q["cpk"] == pytest.approx((mean - 0.58) / (3 * s))
    assert q["cpk_low"] < q["cpk"] < q["cpk_high"]
    assert result["yield"] == pytest.approx(passed / 30)
    assert result["yield_low"] < passed / 30 < result["yield_high"]
    assert "<svg" in html.read_text() and "UCL" in html.read_text()


def test_verify_refuses_a_session_another_process_writes(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    s = make_session(tmp_path / "root", "s1")
    writer = Session.open(s)
    writer.hold(command="benchlab run mtf")  # a run in progress holds the owner lock
    try:
        assert main(["verify", str(s), "--spec", str(spec(tmp_path, limit(0.55)))]) == 1
    finally:
        writer.release()
    assert "session is in use by" in capsys.readouterr().err
    assert verdict_versions(s) == []


def test_unit_needs_a_change(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    s = make_session(tmp_path / "root", "s1", serial="SN1")
    assert main(["unit", str(s), "--reason", "x"]) == 2
    assert "give --serial, --lot or both" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exited:  # --reason is required: every change says why
        main(["unit", str(s), "--lot", "L1"])
    assert exited.value.code == 2
    assert "--reason" in capsys.readouterr().err
