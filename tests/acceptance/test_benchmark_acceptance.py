"""The acceptance benchmark: its lens model's truth, and the guarded rule's false-accept bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.benchmarks.acceptance import rule_figures, timing, true_modulation
from benchlab.cli.main import main


def test_true_modulation_of_a_gaussian_blur() -> None:
    # 3 um at 60 lp/mm: exp(-2 pi^2 (0.003 mm)^2 (60 /mm)^2)
    assert true_modulation(np.array([3.0]))[0] == pytest.approx(
        math.exp(-2 * math.pi**2 * 0.003**2 * 60**2))


def test_guarded_false_accepts_stay_within_the_coverage_tail() -> None:
    figures = rule_figures(units=400, seed=1)
    assert {f.rule for f in figures} == {"guarded", "simple"}
    for f in figures:
        assert f.truly_failing > 20  # each lot has failing units to judge
        if f.rule == "guarded":
            assert f.false_accepts <= 0.025 * f.truly_failing
        else:
            assert f.indeterminate == 0  # the simple rule always decides
    guarded = sum(f.false_accepts for f in figures if f.rule == "guarded")
    simple = sum(f.false_accepts for f in figures if f.rule == "simple")
    assert simple > guarded  # the guard band is what keeps false accepts down


def test_timing_reads_real_session_folders() -> None:
    t = timing(lot_units=5)
    assert t["lot_units"] == 5 and 0 < t["per_session_s"] and 0 < t["lot_s"]


def test_benchmark_command_exit_status(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["benchmark", "acceptance", "--units", "300", "--lot-units", "0"]) == 0
    out = capsys.readouterr().out
    assert "false accept % of failing" in out and "bound 2.5 %" in out
