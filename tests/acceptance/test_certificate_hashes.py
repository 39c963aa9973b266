"""A certificate states the sha256 of the results it certifies as well as of the frames they
were measured from (issue 38): the numbers are covered, not only the raw data."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import pypdf
import pytest
from acceptance_sessions import limit, make_session, spec
from sim_runs import MTF_SMALL, run_sim

from benchlab.acceptance.certificate import NO_RESULTS_HASHES, render_certificate
from benchlab.acceptance.store import read_verdict
from benchlab.cli.main import main


def _summary(session: Path) -> dict[str, dict[str, str]]:
    return json.loads((session / "results" / "v1" / "summary.json").read_text())


@pytest.mark.slow
def test_certificate_states_the_results_and_frames_hashes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    session = run_sim("mtf", tmp_path / "root", MTF_SMALL, sample="OBJ-1").session_path
    path = spec(tmp_path, limit(0.3, where='{ element = "G1E5" }'))
    assert main(["verify", str(session), "--spec", str(path)]) == 0
    summary = _summary(session)
    results, frames = summary["files_sha256"], summary["frames_sha256"]
    assert "forward_view_modulation.json" in results and len(frames) >= 1
    (stored,) = read_verdict(session)["sessions"]
    assert stored["results_sha256"] == results
    assert main(["certificate", str(session)]) == 0
    page = (session / "certificate-v1.html").read_text()
    table = re.search(r"<table id=\"results\">.*?</table>", page, re.S)
    assert table is not None
    for name, digest in results.items():
        assert f"<td>results/v1/{name}</td><td class='hash'>{digest}</td>" in table.group(0)
    for digest in frames.values():
        assert digest in page
    assert main(["certificate", str(session), "--pdf"]) == 0
    pdf = pypdf.PdfReader(io.BytesIO((session / "certificate-v1.pdf").read_bytes()))
    text = "".join(p.extract_text() for p in pdf.pages)
    assert "Results (sha256 of the files certified)" in text
    for name, digest in [*results.items(), *frames.items()]:
        assert digest in text, name
    capsys.readouterr()


def test_a_verdict_stored_before_the_results_hashes_says_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    session = make_session(tmp_path / "root", "s1", serial="SN1")
    assert main(["verify", str(session), "--spec", str(spec(tmp_path, limit(0.55)))]) == 0
    record = read_verdict(session)
    digest = _summary(session)["files_sha256"]["forward_view_modulation.json"]
    assert f"<td>results/v1/forward_view_modulation.json</td><td class='hash'>{digest}</td>" \
        in render_certificate(record, "s1")
    for s in record["sessions"]:  # as an older benchlab stored it
        del s["results_sha256"]
    page = render_certificate(record, "s1")
    assert f"<td>results/v1</td><td class='hash'>{NO_RESULTS_HASHES}</td>" in page
    capsys.readouterr()
