"""Table 4.15 and the report: a reading that is not resolved (or aliased) is never a measured 0,
never averaged in, never given a verdict; results of an unfinished run are marked PARTIAL."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from many_sessions_helpers import copy_session, real_session
from sim_runs import reseal_results

from benchlab.protocols.mtf.analysis import _monte_carlo_rows
from benchlab.protocols.mtf.params import MtfParams
from benchlab.report.mtf import verdict_section
from benchlab.report.render import render_report
from benchlab.report.tables import TABLE_VIEWS, format_table
from benchlab.table_4_15 import verdict_rows


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return real_session(tmp_path_factory.mktemp("source"))


def _radial(obj: float, t_lp: float, s_lp: float, s: float, t: float, t_ok: bool,
            t_aliased: bool = False) -> dict[str, Any]:
    return {"object_lp_per_mm": obj, "image_lp_per_mm": t_lp, "aliased": t_aliased,
            "sagittal_image_lp_per_mm": s_lp, "sagittal_aliased": False,
            "tangential_image_lp_per_mm": t_lp, "tangential_aliased": t_aliased,
            "sagittal_modulation": s, "sagittal_resolved": True,
            "tangential_modulation": t, "tangential_resolved": t_ok}


# The radial rows of the reviewer's session (histogram estimator): T not resolved from 52.5.
RADIAL = [_radial(2, 35.0, 16.01, 0.813, 0.174, True),
          _radial(3, 52.5, 24.02, 0.812, 0.0, False),
          _radial(4, 70.0, 32.03, 0.808, 0.0, False),
          _radial(6, 105.0, 48.04, 0.778, 0.0, False, t_aliased=True)]


def test_table_4_15_does_not_average_a_reading_that_is_not_resolved() -> None:
    rows = {(r["view"], r["mc_freq_lp_per_mm"]): r
            for r in _monte_carlo_rows([], RADIAL, MtfParams())}
    at30, at60 = rows[("radial", 30.0)], rows[("radial", 60.0)]
    # 30 lp/mm: both resolved (S at 32.0, T at 35.0): Eq. 4.2 and a verdict as before.
    assert at30["averaged_modulation"] == pytest.approx((0.808 + 0.174) / 2)
    assert (at30["sagittal_resolved"], at30["tangential_resolved"]) == (True, True)
    assert at30["verdict"].startswith("between the 90% and 80%")
    # 60 lp/mm: T's nearest reading (52.5) is not resolved: no number, no average, no verdict.
    assert at60["tangential_resolved"] is False and at60["tangential_modulation"] is None
    assert at60["sagittal_modulation"] == 0.778 and at60["sagittal_resolved"] is True
    assert at60["averaged_modulation"] is None
    assert at60["averaged_lower_bound"] == pytest.approx(0.389)
    assert at60["verdict"] == "not available: T not resolved"


def test_old_results_with_a_stored_zero_are_shown_as_not_resolved() -> None:
    # Results written before the flags: T stored as 0.0, averaged with it, a verdict on it.
    old = {"view": "radial", "mc_freq_lp_per_mm": 60.0, "measured_freq_lp_per_mm": 52.5,
           "sagittal_modulation": 0.777624, "tangential_modulation": 0.0,
           "averaged_modulation": 0.388812, "p90": 0.21, "p80": 0.27, "p50": 0.45, "p20": 0.61,
           "p10": 0.63, "verdict": "between the 80% and 50% thresholds (0.27 .. 0.45)",
           "sagittal_freq_lp_per_mm": 48.04, "tangential_freq_lp_per_mm": 52.5}
    html = verdict_section([old])
    (line,) = re.findall(r"<li class='verdict'>(.*?)</li>", html)
    assert "T not resolved" in line and "S 0.778" in line
    assert "0.389 (S" not in line and "T 0.000" not in line and "80% and 50%" not in line
    assert "no average" in line and "average at least 0.389" in line
    (shown,) = verdict_rows([old])
    assert shown["tangential_modulation"] == "not resolved"
    assert shown["averaged_modulation"] == "N/A (T not resolved)"
    assert ">0.000<" not in html and ">0.389<" not in html
    from benchlab.tui.services import display_table  # the TUI's table reads the same

    _, headers, cells = display_table("table_4_15", [old])
    shown_tui = dict(zip(headers, cells[0], strict=True))
    assert (shown_tui["T"], shown_tui["avg"]) == ("not resolved", "N/A (T not resolved)")
    assert shown_tui["verdict"] == "not available: T not resolved (average at least 0.389)"


def test_tables_say_not_resolved_and_aliased_never_zero() -> None:
    view = TABLE_VIEWS["table_4_12"]
    text = format_table(RADIAL, view.columns)
    lines = text.splitlines()
    assert "0.174" in lines[1]
    assert "not resolved" in lines[2] and "not resolved" in lines[3]
    assert "aliased" in lines[4].split("0.778")[1]
    assert "0.000" not in text


@pytest.mark.slow
def test_report_of_old_results_with_an_unresolved_t(source: Path, tmp_path: Path) -> None:
    s = copy_session(source, tmp_path / "s")
    latest = s / "results" / "v1"
    t415 = json.loads((latest / "averaged_mtf_vs_monte_carlo.json").read_text())
    assert t415, "mtf-small compares at least one Monte Carlo frequency"
    row = t415[0]
    row.pop("sagittal_resolved", None)
    row.pop("tangential_resolved", None)
    row["tangential_modulation"] = 0.0  # as the analysis before the flags stored it
    row["averaged_modulation"] = row["sagittal_modulation"] / 2
    row["verdict"] = "between the 80% and 50% thresholds (0.27 .. 0.45)"
    (latest / "averaged_mtf_vs_monte_carlo.json").write_text(json.dumps(t415))
    reseal_results(latest)
    text = render_report(s)
    verdict = text[text.index("id='verdict'"):]
    first = re.findall(r"<li class='verdict'>(.*?)</li>", verdict)[0]
    assert "T not resolved" in first and "80% and 50%" not in first
    assert "T 0.000" not in first and "averaged" not in first
    assert "[PARTIAL]" not in text  # a finished run's results are not marked


def test_an_aliased_forward_reading_is_said_to_be_aliased() -> None:
    """Table 4.11 rows carry one ``aliased`` for the element (Table 4.12 rows one per
    orientation): above Nyquist the cell says "aliased", as the catalogue does, not "not
    resolved"."""
    from benchlab.report.tables import row_cell

    forward = {"element": "G2E5", "aliased": True, "sagittal_modulation": 0.0,
               "sagittal_resolved": False}
    assert row_cell(forward, "sagittal_modulation", ".3f") == "aliased"
    radial = {"sagittal_aliased": False, "sagittal_resolved": False, "sagittal_modulation": 0.0,
              "aliased": True}
    assert row_cell(radial, "sagittal_modulation", ".3f") == "not resolved"
    fine = {"aliased": False, "sagittal_resolved": True, "sagittal_modulation": 0.41234}
    assert row_cell(fine, "sagittal_modulation", ".3f") == "0.412"
