"""One registry of procedures (benchlab.procedures): every interface reads it, every entry
resolves, and an unknown procedure is an error everywhere (never another procedure's)."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from typing import get_args

import pytest

from benchlab.procedures import PROCEDURES, REGISTRY, ProcedureName, entry, entry_of
from benchlab.protocols.params import ParamsError, load_params, params_to_dict, parse_params
from benchlab.protocols.runs import make_procedure


def test_names_are_the_literal_type_and_the_order_offered() -> None:
    assert PROCEDURES == ("mtf", "radiometry", "characterise", "depth", "fov")
    assert set(get_args(ProcedureName)) == set(REGISTRY)


@pytest.mark.parametrize("name", PROCEDURES)
def test_every_entry_resolves_and_round_trips(name: str) -> None:
    e = entry(name)
    params = load_params(name)
    assert isinstance(params, e.load("params_class"))
    assert entry_of(params) is e
    as_file = params_to_dict(params)
    assert as_file["procedure"] == name
    # What a session records reads back to the same parameters.
    assert params_to_dict(parse_params(name, as_file)) == as_file
    procedure = make_procedure(params)
    assert type(procedure) is e.load("procedure_class")
    assert e.label and e.checklist_title


@dataclass(frozen=True)
class MtfParams:  # the same class name as a real one, from no registered module
    bits: int = 8


def test_unknown_procedure_is_an_error_everywhere() -> None:
    with pytest.raises(KeyError, match="unknown procedure 'fvo'; known: mtf, radiometry"):
        entry("fvo")
    with pytest.raises(ParamsError, match="unknown procedure 'fvo'"):
        parse_params("fvo", {})
    with pytest.raises(TypeError, match="MtfParams is the parameter class of no procedure"):
        entry_of(MtfParams())
    with pytest.raises(ParamsError, match="parameter class of no procedure"):
        make_procedure(MtfParams())  # type: ignore[arg-type]
    with pytest.raises(ParamsError, match="parameter class of no procedure"):
        params_to_dict(MtfParams())  # type: ignore[arg-type]


def test_the_registry_imports_nothing_heavy() -> None:
    code = ("import sys, benchlab.cli, benchlab.procedures; print(sorted(m for m in "
            "sys.modules if m.startswith(('numpy', 'benchlab.protocols'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize(("procedure", "known"), [("depth", "best_focus_mm"),
                                                  ("fov", "barrel")])
def test_a_simulated_lens_table_names_each_bad_key_and_value(procedure: str, known: str) -> None:
    raw = {**params_to_dict(load_params(procedure)),
           "simulator": {"nope": 1.0, known: "x"}}
    with pytest.raises(ParamsError) as err:
        parse_params(procedure, raw)
    text = str(err.value)
    assert "simulator.nope: unknown parameter; known:" in text
    assert f"simulator.{known}: must be a number, got 'x'" in text


def test_the_package_entry_points_are_the_typed_functions() -> None:
    import inspect

    import benchlab.protocols as protocols
    from benchlab.protocols import runs

    for name in ("start_run", "resume_run", "reanalyze"):
        assert getattr(protocols, name) is getattr(runs, name)
    params = inspect.signature(protocols.start_run).parameters
    assert {"bench", "params", "root", "prompt", "abort"} <= set(params)
    assert not any(p.kind is p.VAR_KEYWORD for p in params.values())  # no **kwargs: Any
    with pytest.raises(AttributeError, match="no attribute 'start_runs'"):
        protocols.start_runs  # noqa: B018
