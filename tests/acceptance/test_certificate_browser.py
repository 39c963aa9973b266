"""The certificate in a real headless browser (Debian's Chromium; `.ci/run` installs it): it
loads with no console errors, holds the unit verdict and a row per limit, and prints to PDF."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest
from acceptance_sessions import limit, make_session, spec

from benchlab.cli.main import main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-logging=stderr", "--v=0"]

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="needs chromium (.ci/run installs it)")


def _chromium(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    assert CHROMIUM is not None
    return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}", *args],
                          capture_output=True, text=True, timeout=90, check=False)


def test_certificate_renders_in_chromium_and_prints_to_pdf(tmp_path: Path) -> None:
    s = make_session(tmp_path / "root", "s1", serial="SN-42", lot="L1")
    path = spec(tmp_path, limit(0.55), limit(max_=0.7, ident="G1E5-max",
                                              where='{ element = "G1E5" }'))
    assert main(["verify", str(s), "--spec", str(path)]) == 1  # G1E5 reads 0.8 > 0.7
    page = tmp_path / "cert.html"
    assert main(["certificate", str(s), "--out", str(page)]) == 0
    dom = _chromium(tmp_path, "--dump-dom", page.as_uri())
    assert dom.returncode == 0, dom.stderr[-2000:]
    console = [ln for ln in dom.stderr.splitlines() if "CONSOLE" in ln or "Uncaught" in ln]
    assert console == []
    html = dom.stdout
    assert re.search(r"Unit verdict: <span class=\"verdict unit-verdict\"[^>]*>fail</span>", html)
    body = html.split('<table id="limits">')[1].split("</table>")[0]
    assert body.count("<tr>") == 3  # the header and one row per limit
    assert "fwd-G2E2-S" in body and "G1E5-max" in body
    pdf = tmp_path / "cert.pdf"
    res = _chromium(tmp_path, f"--print-to-pdf={pdf}", "--no-pdf-header-footer", page.as_uri())
    assert res.returncode == 0 and pdf.read_bytes()[:5] == b"%PDF-"
    assert pdf.stat().st_size > 10_000
