"""Issue 42: the option strings have ``Literal`` aliases defined next to what defines the names,
kept equal to them, and strings from a command line or a file become those types only through
the checks that refuse an unknown name."""

from __future__ import annotations

from typing import get_args

import pytest

from benchlab.analysis.bars.estimators import ESTIMATORS, EstimatorChoice, EstimatorName
from benchlab.analysis.bars.roi import ORIENTATION_AXIS, BarOrientation
from benchlab.analysis.chart.layout import Orientation
from benchlab.analysis.sfr.measure import METHODS, SfrMethod
from benchlab.cli.frames.analysis import ORIENTATION_CHOICES
from benchlab.cli.frames.chart import CHART_KINDS, ChartKind
from benchlab.procedures import PROCEDURES, REGISTRY, ProcedureName, procedure_name
from benchlab.protocols.runs import UnknownEstimatorError, check_estimator


def _flat(alias: object) -> set[str]:
    out: set[str] = set()
    for arg in get_args(alias):
        out |= _flat(arg) if get_args(arg) else {arg}
    return out


def test_each_alias_names_exactly_what_the_registry_defines() -> None:
    assert set(get_args(EstimatorName)) == set(ESTIMATORS)
    assert _flat(EstimatorChoice) == set(ESTIMATORS) | {"auto"}
    assert set(get_args(BarOrientation)) == set(ORIENTATION_AXIS) == set(ORIENTATION_CHOICES)
    assert set(get_args(Orientation)) < set(get_args(BarOrientation))
    assert get_args(ProcedureName) == PROCEDURES == tuple(REGISTRY)
    assert get_args(SfrMethod) == METHODS
    assert get_args(ChartKind) == CHART_KINDS


def test_a_string_becomes_a_procedure_name_only_if_it_is_one() -> None:
    assert procedure_name("depth") == "depth"
    with pytest.raises(KeyError, match="unknown procedure 'mft'; known: mtf, radiometry"):
        procedure_name("mft")


def test_a_string_becomes_an_estimator_choice_only_if_it_is_one() -> None:
    assert check_estimator("histogram") == "histogram"
    assert check_estimator("auto") == "auto" and check_estimator(None) is None
    with pytest.raises(UnknownEstimatorError, match="unknown estimator 'histgram'; choose auto"):
        check_estimator("histgram")
