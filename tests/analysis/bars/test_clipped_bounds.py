"""Issue 29, item 1: plainly resolved bars that clip read as a bound (``>= x``, with the
reason), never as "not resolved" and never as a plain value - in the result, the CLI, JSON,
the results tables, the report and the catalogue; a dark level of 0 reads exactly 1."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tifffile

from benchlab.analysis.bars.estimators import ESTIMATORS, estimate_modulation
from benchlab.analysis.bars.result import ModulationResult, format_modulation
from benchlab.benchmarks.bars.extremes import extreme_cases, format_extremes, run_extremes
from benchlab.catalog.extract import figures_of
from benchlab.cli.main import main
from benchlab.report.roi import RoiReading, reading_text
from benchlab.report.tables import row_cell


def _bars(dark: int, bright: int, period: int = 20, shape: tuple[int, int] = (40, 50)
          ) -> np.ndarray:
    x = np.arange(shape[1])
    return np.tile(np.where(x % period < period // 2, bright, dark).astype(np.uint8),
                   (shape[0], 1))


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_the_issue_pattern_reads_exactly_one(name: str) -> None:
    """The issue's 0/255 pattern (20 px period, 40 x 50): "not resolved" by the default
    estimator before; dark level 0 -> exactly 1, a value, whatever the clipped bright."""
    for freq in (None, 0.05):
        r = estimate_modulation(_bars(0, 255), estimator=name, freq_cycles_per_px=freq)
        assert r.resolved and r.modulation == 1.0 and not r.lower_bound, r.warnings
        assert r.shown == "1.000"


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_a_clipped_bright_level_is_a_bound_with_its_reason(name: str) -> None:
    r = estimate_modulation(_bars(50, 255), estimator=name, freq_cycles_per_px=0.05)
    truth_at_least = (255 - 50) / (255 + 50)  # the bright bars are 255 or brighter
    assert r.resolved and r.lower_bound, r.warnings
    assert "clipped at code 255" in r.bound_reason or "plainly resolved" in r.bound_reason
    assert r.modulation == pytest.approx(truth_at_least, abs=0.01)
    assert r.shown == f"\u2265 {r.modulation:.3f}"
    doc = r.to_dict()
    assert doc["lower_bound"] is True and doc["shown"].startswith("\u2265")
    assert doc["bound_reason"] == r.bound_reason


def test_unclipped_readings_are_values_and_a_two_code_pattern_its_codes_contrast() -> None:
    r = estimate_modulation(_bars(50, 200), estimator="histogram", freq_cycles_per_px=0.05)
    assert r.resolved and not r.lower_bound and r.shown == "0.600"
    # Two codes, neither at full scale: the levels are the codes, a value (issue 37 point 4;
    # code 200 of an 8-bit frame is no saturation).
    r = estimate_modulation(_bars(50, 200), freq_cycles_per_px=0.05)
    assert r.resolved and not r.lower_bound and r.shown == "0.600"
    assert r.diagnostics.clipped_fraction == 0.0


def test_a_bound_without_its_reason_is_refused() -> None:
    r = estimate_modulation(_bars(50, 200), estimator="histogram", freq_cycles_per_px=0.05)
    with pytest.raises(ValueError, match="lower bound"):
        ModulationResult(**{**r.__dict__, "lower_bound": True})


def test_format_modulation_words() -> None:
    assert format_modulation(0.5) == "0.500"
    assert format_modulation(0.5, lower_bound=True) == "\u2265 0.500"
    assert format_modulation(0.0, resolved=False) == "not resolved"
    assert format_modulation(None, measurable=False) == "not measurable"


def test_cli_text_and_json_show_the_bound(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    image = tmp_path / "over.tif"
    tifffile.imwrite(image, _bars(50, 255))
    args = ["analyze", str(image), "--roi", "0,0,40,50", "--estimator", "histogram"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "modulation (Eq. 2.9)       \u2265 0.672" in out
    assert "lower bound                bright level clipped at code 255" in out
    assert main([*args, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["lower_bound"] is True and doc["shown"] == "\u2265 0.672"


def test_tables_report_and_catalogue_show_a_bound_never_a_plain_value() -> None:
    row = {"element": "G1E5", "sagittal_modulation": 0.672, "sagittal_resolved": True,
           "sagittal_lower_bound": True, "tangential_modulation": 0.6,
           "tangential_resolved": True, "aliased": False, "image_lp_per_mm": 20.0}
    assert row_cell(row, "sagittal_modulation", ".3f") == "\u2265 0.672"
    assert row_cell(row, "tangential_modulation", ".3f") == "0.600"
    assert row_cell({"modulation": 0.5, "lower_bound": True}, "modulation", ".3f") == \
        "\u2265 0.500"
    reading = RoiReading.from_row(row, "sagittal", label="G1E5 sagittal", view="forward",
                                  roi=(0, 0, 10, 10), estimator="profilefit")
    assert reading_text(reading).startswith("modulation \u2265 0.672 (lower bound")
    figures = {f.orientation: f for f in figures_of(2, {"table_4_11": [row]})}
    assert figures["sagittal"].text == "lower bound" and figures["sagittal"].value == 0.672
    assert figures["tangential"].text == "resolved"
    t415 = {"view": "forward", "mc_freq_lp_per_mm": 20.0, "sagittal_modulation": 0.672,
            "tangential_modulation": 0.6, "sagittal_resolved": True,
            "tangential_resolved": True, "averaged_modulation": 0.636,
            "averaged_modulation_lower_bound": True, "verdict": "at least: between ..."}
    assert row_cell(t415, "averaged_modulation", ".3f") == "\u2265 0.636"
    (fig,) = figures_of(2, {"table_4_15": [t415]})
    assert fig.text.startswith("lower bound: at least")


def test_the_extremes_bucket_reads_every_case_and_the_default_gives_its_answer() -> None:
    outcomes = run_extremes(("profilefit", "histogram"))
    assert len(outcomes) == 2 * len(extreme_cases())
    default = [o for o in outcomes if o.estimator == "profilefit"]
    assert all(o.result.resolved for o in default)  # never "not resolved" at the extremes
    missed = [(o.case.bucket, o.result.shown) for o in default if not o.ok]
    assert missed == []
    table = format_extremes(outcomes)
    assert "dark 0, bright clipped" in table and "16-bit holding 8-bit" in table
