"""The certificate as an A4 PDF (``benchlab certificate --pdf``): its text read back with pypdf,
page breaks with the table header repeated, nothing drawn past the margins, bad options."""

from __future__ import annotations

import copy
import io
from pathlib import Path
from typing import Any

import pypdf
import pytest
from acceptance_sessions import limit, make_session, spec

from benchlab.acceptance.certificate import certificate_content
from benchlab.acceptance.certificate_pdf import (
    CHAR_IN,
    MARGIN_IN,
    PAGE_IN,
    _layout,
    _Text,
    certificate_pdf,
    text_width_in,
)
from benchlab.acceptance.store import read_verdict
from benchlab.cli.main import main


def _verified(tmp_path: Path) -> tuple[Path, dict[str, Any]]:
    s = make_session(tmp_path / "root", "s1", serial="SN-42", lot="L1")
    path = spec(tmp_path, limit(0.55), limit(max_=0.7, ident="G1E5-max",
                                              where='{ element = "G1E5" }'))
    assert main(["verify", str(s), "--spec", str(path)]) == 1  # G1E5 reads 0.8 > 0.7
    return s, read_verdict(s, None)


def _text(pdf: bytes) -> list[str]:
    return [page.extract_text() for page in pypdf.PdfReader(io.BytesIO(pdf)).pages]


@pytest.mark.slow
def test_pdf_certificate_holds_the_verdict_every_limit_and_the_hashes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    s, record = _verified(tmp_path)
    assert main(["certificate", str(s), "--pdf"]) == 0
    out = s / "certificate-v1.pdf"
    assert f"certificate: {out}  (unit SN-42: fail)" in capsys.readouterr().out
    pdf = out.read_bytes()
    assert pdf[:5] == b"%PDF-"
    reader = pypdf.PdfReader(io.BytesIO(pdf))
    assert reader.metadata is not None
    assert reader.metadata.title == "Acceptance certificate - SN-42"
    assert reader.metadata.subject == "unit verdict: fail"
    (page,) = _text(pdf)
    for text in ("Acceptance certificate - SN-42", "Unit verdict: FAIL", "L1", "objective",
                 record["spec"]["sha256"], "Guarded (ISO 14253-1)", "fwd-G2E2-S",
                 "sagittal_modulation", "0.6", "\u2265 0.55", "\u2264 0.7", "G1E5-max",
                 "element=G2E2", "Inspected by, date", "page 1 of 1"):
        assert text in page, text
    g1e5 = next(line for line in page.splitlines() if line.startswith("G1E5-max"))
    assert g1e5.split()[-1] == "fail" and "-0.1" in g1e5  # reading 0.8 against <= 0.7
    # Rendered from the stored record alone: the same record gives the same bytes.
    assert certificate_pdf(record, session_id="s1") == pdf


def test_an_out_name_ending_in_pdf_writes_a_pdf(tmp_path: Path) -> None:
    s, _ = _verified(tmp_path)
    out = tmp_path / "paper" / "SN-42.PDF"
    assert main(["certificate", str(s), "--out", str(out)]) == 0
    assert out.read_bytes()[:5] == b"%PDF-"
    assert not (s / "certificate-v1.html").exists()


def test_pdf_with_an_html_name_is_refused_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    s, _ = _verified(tmp_path)
    out = tmp_path / "cert.html"
    assert main(["certificate", str(s), "--pdf", "--out", str(out)]) == 2
    assert "--pdf writes a PDF, but --out names an HTML file" in capsys.readouterr().err
    assert not out.exists() and not list(s.glob("certificate-*"))


def _long_record(record: dict[str, Any], rows: int) -> dict[str, Any]:
    long = copy.deepcopy(record)
    template = long["rows"][0]
    long["rows"] = [{**template, "limit_id": f"L{i:03d}-" + "x" * (60 if i == 7 else 4),
                     "notes": ["a note " * 40] if i % 10 == 0 else []} for i in range(rows)]
    long["unit"]["serial"] = "SN-" + "\u00b5" * 150  # a serial longer than a line
    return long


@pytest.mark.slow
def test_long_tables_break_across_pages_with_the_header_repeated(tmp_path: Path) -> None:
    _, record = _verified(tmp_path)
    pages = _text(certificate_pdf(_long_record(record, 150), session_id="s1"))
    assert len(pages) >= 4
    for number, page in enumerate(pages, 1):
        assert f"page {number} of {len(pages)}" in page
    assert all("limit" in p and "verdict" in p for p in pages[:3])  # header on each page
    every_row = "".join(pages)
    assert all(f"L{i:03d}-" in every_row for i in range(150))


@pytest.mark.slow
def test_no_text_is_drawn_past_the_margins(tmp_path: Path) -> None:
    _, record = _verified(tmp_path)
    pages = _layout(certificate_content(_long_record(record, 40), session_id="s1"))
    texts = [t for page in pages for t in page if isinstance(t, _Text)]
    assert len(texts) > 100
    right_in, bottom_in = PAGE_IN[0] - MARGIN_IN, PAGE_IN[1] - MARGIN_IN
    for t in texts:
        assert t.x_in >= MARGIN_IN and MARGIN_IN <= t.y_in < bottom_in
        drawn_in = text_width_in(t.text, t.size_pt, t.bold, t.mono)
        assert t.x_in + drawn_in <= right_in + 1e-9, t.text
        if t.mono:  # the tables' column arithmetic: the font's advance is what was assumed
            assert drawn_in <= len(t.text) * CHAR_IN + 1e-9
    title = [t.text for t in texts if t.size_pt == 15.0]  # the long serial wraps the title
    assert len(title) > 2
    assert "".join(title).replace(" ", "") == "Acceptancecertificate-SN-" + "\u00b5" * 150


def test_certificate_of_a_folder_that_is_no_session_names_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["certificate", str(tmp_path / "nowhere"), "--pdf"]) == 1
    assert f"{tmp_path / 'nowhere'}: not a session folder (no session.json)" in (
        capsys.readouterr().err)
    assert not (tmp_path / "nowhere").exists()


@pytest.mark.slow
def test_a_record_with_no_rows_sessions_or_frames_still_prints(tmp_path: Path) -> None:
    _, record = _verified(tmp_path)
    empty = {**copy.deepcopy(record), "rows": [], "sessions": []}
    (page,) = _text(certificate_pdf(empty, session_id="s1"))
    assert "Unit verdict: FAIL" in page and "page 1 of 1" in page
    assert "limit" in page and "sha256" in page  # the empty tables keep their headers
