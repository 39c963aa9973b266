"""The spec file: a good one loads; a malformed one gets one clear line per problem."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchlab.acceptance.spec import SpecError, load_spec

GOOD = """
format = "benchlab.spec"
version = 1
name = "dual-view objective"
revision = "B"
decision_rule = "simple"
coverage = 0.9

[[limit]]
id = "fwd-G2E2-S"
table = "forward_view_modulation"
where = { element = ["G2E2", "G2E3"] }
column = "sagittal_modulation"
min = 0.50
max = 1

[[limit]]
id = "gain"
table = "characterisation"
column = "system_gain_dn_per_e"
max = 0.3
decision_rule = "guarded"
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "spec.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_a_good_spec_loads(tmp_path: Path) -> None:
    spec = load_spec(write(tmp_path, GOOD))
    assert (spec.name, spec.revision, spec.decision_rule, spec.coverage) == \
        ("dual-view objective", "B", "simple", 0.9)
    first, second = spec.limits
    assert first.where == {"element": ("G2E2", "G2E3")}
    assert (first.min, first.max, second.min, second.max) == (0.5, 1.0, None, 0.3)
    assert second.decision_rule == "guarded"
    assert len(spec.sha256) == 64


def test_every_problem_reported_at_once_with_limit_and_field(tmp_path: Path) -> None:
    bad = """
format = "benchlab.spec"
version = 2
decision_rule = "strict"
coverage = 1.5
extra = 1

[[limit]]
id = "a"
table = "t"
column = "c"
min = 0.9
max = 0.1
mni = 3

[[limit]]
id = "a"
column = "c"

[[limit]]
table = "t"
column = "c"
min = "high"
where = { element = { nested = 1 } }
uncertainty = "u"
ci95 = "v"
"""
    with pytest.raises(SpecError) as info:
        load_spec(write(tmp_path, bad))
    problems = info.value.problems
    expected = [
        "field 'extra': unknown",
        "field 'version': must be one of [1]",
        "field 'name': required",
        "field 'decision_rule': must be one of guarded, simple, got 'strict'",
        "field 'coverage': must be a probability",
        "limit 'a' (#1): field 'mni': unknown",
        "limit 'a' (#1): field 'max': 0.1 is below min 0.9",
        "limit 'a' (#2): field 'table': required",
        "limit 'a' (#2): field 'min': a limit needs 'min', 'max' or both",
        "limit #3: field 'id': required",
        "limit #3: field 'min': must be a finite number, got 'high'",
        "limit #3: field 'ci95': give 'uncertainty' (1 sigma) or 'ci95', not both",
        "limit #3: field 'where.element': must be a string, number or boolean",
    ]
    for text in expected:
        assert any(p.startswith(text) for p in problems), (text, problems)
    assert len(problems) == len(expected)
    message = str(info.value)
    assert f"{tmp_path / 'spec.toml'}: spec not usable ({len(expected)} problems)" in message
    assert message.count(str(tmp_path / "spec.toml")) == len(expected) + 1


def test_duplicate_ids_are_a_problem(tmp_path: Path) -> None:
    text = GOOD.replace('id = "gain"', 'id = "fwd-G2E2-S"')
    with pytest.raises(SpecError) as info:
        load_spec(write(tmp_path, text))
    assert info.value.problems == ["limit 'fwd-G2E2-S' (#2): field 'id': the same id as "
                                   "limit #1; ids must be unique"]


def test_toml_syntax_error_names_the_line(tmp_path: Path) -> None:
    with pytest.raises(SpecError) as info:
        load_spec(write(tmp_path, 'format = "benchlab.spec"\nversion = \n'))
    assert "not valid TOML" in info.value.problems[0]
    assert "line 2" in info.value.problems[0]


def test_no_limit_is_a_problem(tmp_path: Path) -> None:
    with pytest.raises(SpecError) as info:
        load_spec(write(tmp_path, 'format = "benchlab.spec"\nversion = 1\nname = "x"\n'))
    assert info.value.problems == ["field 'limit': at least one [[limit]] table is required"]
