"""``benchlab benchmark characterise``: how a characterisation summary is judged against the
simulator's truth (the tolerances of the issue), and what the table prints."""

from __future__ import annotations

from typing import Any

import pytest

from benchlab.benchmarks.characterise import (
    LINEARISED_TOLERANCE,
    TOLERANCES,
    all_pass,
    figures_rows,
    format_benchmark,
    format_figures,
)

TRUTH = {"system_gain_dn_per_e": 0.25, "read_noise_e": 8.0, "saturation_dn": 4000.0,
         "linearity_error_pct": [0.0, 0.0], "dsnu_dn": 2.0, "prnu_pct": 1.0}


def _summary(measured: dict[str, Any]) -> dict[str, Any]:
    return {"summary": {"configs": [{"gain": 1.0, "bits": 12, "measured": measured,
                                     "simulator_truth": TRUTH}]}}


def _by_quantity(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    return {r["quantity"]: r for r in rows}


def test_each_figure_is_judged_by_its_own_tolerance() -> None:
    measured = {"system_gain_dn_per_e": 0.2549,  # 1.96 % off: inside 2 %
                "read_noise_e": 8.5,  # 6.25 % off: outside 5 %
                "saturation_dn": 4000.0,
                "linearity_error_pct": [0.15, -0.25],  # 0.25 pp: outside 0.2 pp
                "dsnu_dn": 2.1, "prnu_pct": 1.05}
    rows = _by_quantity(figures_rows(_summary(measured)))
    assert set(rows) == set(TOLERANCES)
    assert rows["system_gain_dn_per_e"]["error"] == pytest.approx(0.0196)
    assert rows["system_gain_dn_per_e"]["pass"] is True
    assert rows["read_noise_e"]["error"] == pytest.approx(0.0625)
    assert rows["read_noise_e"]["pass"] is False
    assert rows["saturation_dn"]["error"] == 0.0 and rows["saturation_dn"]["pass"] is True
    assert rows["linearity_error_pct"]["error"] == pytest.approx(0.25)
    assert rows["linearity_error_pct"]["pass"] is False
    assert rows["dsnu_dn"]["pass"] is True and rows["prnu_pct"]["pass"] is True


def test_unresolved_skipped_or_missing_figures_are_not_judged() -> None:
    measured = {"system_gain_dn_per_e": 0.5, "read_noise_e": 30.0, "read_noise_resolved": False,
                "saturation_dn": None, "linearity_error_pct": [0.0, 0.0],
                "dsnu_dn": 2.0, "prnu_pct": 1.0}
    rows = _by_quantity(figures_rows(_summary(measured), skip=("system_gain_dn_per_e",)))
    assert rows["system_gain_dn_per_e"]["error"] == pytest.approx(1.0)
    assert rows["system_gain_dn_per_e"]["pass"] is None  # skipped: shown, not judged
    assert rows["read_noise_e"]["pass"] is None  # below 1 DN: not resolved
    assert rows["saturation_dn"]["error"] is None and rows["saturation_dn"]["pass"] is False
    text = format_figures(list(rows.values()))
    assert "n/a" in text and "NO" in text and "100.00%" in text


def _benchmark(worst_linearised: float, wall_s: float, pass_: bool | None) -> dict[str, Any]:
    row = {"gain": 1.0, "bits": 12, "quantity": "saturation_dn", "measured": 4000.0,
           "truth": 4000.0, "error": 0.0, "tolerance": 0.02, "kind": "rel", "pass": pass_}
    rad = [{"position_mm": z, "linear_truth_gray": 100.0, "nonlinear_gray": 95.0,
            "linearised_gray": 100.0 * (1 + e), "nonlinear_error": -0.05,
            "linearised_error": e} for z, e in ((15.0, 0.001), (25.0, worst_linearised))]
    return {"rows": [row], "nonlinear_rows": [row], "wall_s": wall_s, "cpu_s": 3.0,
            "radiometry": rad, "frames": 120}


def test_the_benchmark_passes_only_when_every_part_does() -> None:
    assert all_pass(_benchmark(0.004, 20.0, True))
    assert all_pass(_benchmark(-0.004, 20.0, None))  # a figure not judged does not fail it
    assert not all_pass(_benchmark(0.004, 20.0, False))
    assert not all_pass(_benchmark(0.004, 31.0, True))  # slower than 30 s
    assert not all_pass(_benchmark(LINEARISED_TOLERANCE + 1e-4, 20.0, True))
    assert not all_pass(_benchmark(float("nan"), 20.0, True))


def test_the_printed_benchmark_gives_the_worst_errors_and_verdicts() -> None:
    text = format_benchmark(_benchmark(-0.003, 12.5, True))
    assert "procedure wall time: 12.5 s for 120 frames (target <= 30 s)  yes" in text
    assert "worst reading error: 5.00% raw, 0.30% linearised (target <= 0.5%)  yes" in text
    assert "    25   100.000    95.000     99.700   -5.00%   -0.30%" in text
    assert "(target <= 0.5%)  NO" in format_benchmark(_benchmark(0.006, 12.5, True))
    assert "nan% linearised (target <= 0.5%)  NO" in format_benchmark(
        _benchmark(float("nan"), 12.5, True))
