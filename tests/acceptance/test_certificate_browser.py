"""The certificate in a real headless browser (Debian's Chromium; `.ci/run` installs it): it
loads with no console errors, holds the unit verdict and a row per limit, and prints to PDF."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from acceptance_sessions import limit, make_session, spec
from headless_browser import chromium, console_errors, needs_chromium

from benchlab.cli.main import main

pytestmark = needs_chromium


@pytest.mark.slow
def test_certificate_renders_in_chromium_and_prints_to_pdf(tmp_path: Path) -> None:
    s = make_session(tmp_path / "root", "s1", serial="SN-42", lot="L1")
    path = spec(tmp_path, limit(0.55), limit(max_=0.7, ident="G1E5-max",
                                              where='{ element = "G1E5" }'))
    assert main(["verify", str(s), "--spec", str(path)]) == 1  # G1E5 reads 0.8 > 0.7
    page = tmp_path / "cert.html"
    assert main(["certificate", str(s), "--out", str(page)]) == 0
    dom = chromium(tmp_path, "--dump-dom", page.as_uri())
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert console_errors(dom.stderr) == []
    html = dom.stdout
    assert re.search(r"Unit verdict: <span class=\"verdict unit-verdict\"[^>]*>fail</span>", html)
    body = html.split('<table id="limits">')[1].split("</table>")[0]
    assert body.count("<tr>") == 3  # the header and one row per limit
    assert "fwd-G2E2-S" in body and "G1E5-max" in body
    pdf = tmp_path / "cert.pdf"
    res = chromium(tmp_path, f"--print-to-pdf={pdf}", "--no-pdf-header-footer", page.as_uri())
    assert res.returncode == 0 and pdf.read_bytes()[:5] == b"%PDF-"
    assert pdf.stat().st_size > 10_000
