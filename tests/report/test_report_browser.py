"""The report in a real headless browser (Debian's Chromium; `.ci/run` installs it): the page
loads with no console errors, a screenshot is taken, and the DOM holds a panel per ROI."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from headless_browser import chromium, console_errors, needs_chromium
from sim_runs import MTF_SMALL, run_sim

from benchlab.report.render import write_report

pytestmark = needs_chromium


@pytest.mark.slow
def test_report_loads_in_chromium_with_a_panel_per_roi(tmp_path: Path) -> None:
    outcome = run_sim("mtf", tmp_path, MTF_SMALL)
    page = write_report(outcome.session_path)
    dom = chromium(tmp_path, "--dump-dom", page.as_uri())
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert console_errors(dom.stderr) == []
    html = dom.stdout
    panels = re.findall(r"<div class=\"roi-panel\" data-roi=\"([^\"]+)\" data-state=\"(\w+)\"",
                        html)
    labels = {label for label, _ in panels}
    assert labels == {"G1E5 sagittal", "G1E5 tangential", "G2E1 sagittal", "G2E1 tangential",
                      "radial 0.5 lp/mm sagittal", "radial 0.5 lp/mm tangential",
                      "radial 2 lp/mm sagittal", "radial 2 lp/mm tangential"}
    for _label, state in panels:  # every state shown is labelled on the page
        assert state in {"resolved", "unresolved", "aliased"}
    assert html.count("class=\"state state-") == len(panels)
    shot = tmp_path / "report.png"
    res = chromium(tmp_path, "--window-size=1300,3000", f"--screenshot={shot}", page.as_uri())
    assert res.returncode == 0 and shot.stat().st_size > 50_000
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
