"""The spec file: limits on the results tables of a session, and the rule that decides them.

A spec is a TOML file of format ``benchlab.spec``, version 1 (docs/formats/spec.md)::

    format = "benchlab.spec"
    version = 1
    name = "dual-view objective, rev B"
    decision_rule = "guarded"          # guarded | simple
    coverage = 0.95

    [[limit]]
    id = "fwd-G2E2-S"
    table = "forward_view_modulation"
    where = { element = "G2E2" }
    column = "sagittal_modulation"
    min = 0.50

:func:`load_spec` checks the whole file before anything else is read and raises one
:class:`SpecError` listing every problem (file, limit id, field), so a quality engineer fixes
the file in one pass. Names are checked against the results tables the procedures write
(:mod:`benchlab.acceptance.results_schema`): an unknown table or column, a limit on a text
column or a ``where`` value of the wrong type is a problem of the file, never a verdict.
"""

from __future__ import annotations

import difflib
import hashlib
import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchlab.acceptance.results_schema import LIST, NUMBER, RESULTS_SCHEMA, TEXT
from benchlab.drivers.errors import BenchlabError
from benchlab.session import RESULT_FILE_STEMS

SPEC_FORMAT = "benchlab.spec"
SPEC_VERSIONS = (1,)
DECISION_RULES = ("guarded", "simple")
#: Fields of the file's top level and of one ``[[limit]]``; anything else is a problem (a
#: misspelt ``mni = 0.5`` must not silently drop a limit).
_TOP_FIELDS = frozenset({"format", "version", "name", "revision", "decision_rule", "coverage",
                         "description", "limit"})
_LIMIT_FIELDS = frozenset({"id", "table", "where", "column", "min", "max", "uncertainty",
                           "ci95", "unit", "description", "decision_rule"})
#: A ``where`` value: one cell value, or a list of them (the row matches any).
Scalar = str | int | float | bool
#: Largest spec file read (bytes): a spec is a page of limits; a bigger file is a mistake.
MAX_SPEC_BYTES = 1 << 20
#: Longest text of a name-like field (id, name, revision, unit): they are shown in tables.
MAX_NAME_CHARS = 200


class SpecError(BenchlabError):
    """A spec file with problems; ``problems`` lists each one (file, limit id, field)."""

    def __init__(self, path: Path, problems: list[str]) -> None:
        self.path = path
        self.problems = problems
        lines = "\n".join(f"  {path}: {p}" for p in problems)
        count = f"{len(problems)} problem{'s' if len(problems) != 1 else ''}"
        super().__init__(f"{path}: spec not usable ({count}):\n{lines}")


@dataclass(frozen=True)
class Limit:
    """One limit: ``min <= value <= max`` (either may be None) on ``column`` of the rows of
    ``table`` that match ``where``.

    ``uncertainty`` names a 1-sigma column and ``ci95`` a 95 % interval column (a half-width,
    or ``[low, high]``); when neither is given the column is found by name (see
    :func:`benchlab.acceptance.decide.interval_columns`).
    """

    id: str
    table: str
    column: str
    min: float | None = None
    max: float | None = None
    where: dict[str, tuple[Scalar, ...]] = field(default_factory=dict)
    uncertainty: str | None = None
    ci95: str | None = None
    unit: str = ""
    description: str = ""
    #: This limit's own rule (a table without uncertainties, decided by the reading), else
    #: the spec's.
    decision_rule: str | None = None

    def describe(self) -> str:
        """``>= 0.5``, ``<= 3``, ``0.5 .. 3`` (with the unit)."""
        return describe_limit(self.min, self.max, self.unit)


def describe_limit(low: float | None, high: float | None, unit: str = "", *,
                   signs: tuple[str, str] = (">=", "<=")) -> str:
    """A limit as text: ``>= 0.5``, ``<= 3``, ``0.5 .. 3``, with the unit; ``signs`` are the
    at-least and at-most signs (the certificate prints the mathematical ones)."""
    if low is not None and high is not None:
        text = f"{low:g} .. {high:g}"
    elif low is not None:
        text = f"{signs[0]} {low:g}"
    else:
        text = f"{signs[1]} {high:g}"
    return f"{text} {unit}".rstrip()


@dataclass(frozen=True)
class Spec:
    """A checked spec file."""

    path: Path
    name: str
    version: int
    decision_rule: str
    coverage: float
    limits: tuple[Limit, ...]
    revision: str = ""
    description: str = ""
    sha256: str = ""

    def header(self) -> dict[str, Any]:
        """What a stored verdict records of its spec (enough to find and check the file)."""
        return {"name": self.name, "revision": self.revision, "format": SPEC_FORMAT,
                "format_version": self.version, "file": str(self.path), "sha256": self.sha256,
                "decision_rule": self.decision_rule, "coverage": self.coverage}


def load_spec(path: str | Path) -> Spec:
    """Read and check a spec file.

    Raises
    ------
    SpecError
        Listing every problem of the file at once; the file itself is only read.
    OSError
        When the file cannot be read at all (the CLI names it).
    """
    path = Path(path)
    size = path.stat().st_size
    if size > MAX_SPEC_BYTES:
        raise SpecError(path, [f"the file is {size} bytes; a spec is at most "
                               f"{MAX_SPEC_BYTES} bytes (1 MiB)"])
    data = path.read_bytes()
    try:
        doc = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise SpecError(path, [f"not UTF-8 text (byte {exc.start})"]) from None
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(path, [f"not valid TOML: {exc}"]) from None
    return parse_spec(doc, path, sha256=hashlib.sha256(data).hexdigest())


def parse_spec(doc: dict[str, Any], path: Path, sha256: str = "") -> Spec:
    """Check a parsed TOML document; :class:`SpecError` lists every problem."""
    problems: list[str] = []
    for key in sorted(set(doc) - _TOP_FIELDS):
        problems.append(f"field {key!r}: unknown (expected one of "
                        f"{', '.join(sorted(_TOP_FIELDS))})")
    if doc.get("format") != SPEC_FORMAT:
        problems.append(f"field 'format': must be {SPEC_FORMAT!r}, got {doc.get('format')!r}")
    version = doc.get("version")
    if type(version) is not int or version not in SPEC_VERSIONS:
        problems.append(f"field 'version': must be one of {list(SPEC_VERSIONS)} (a newer "
                        f"benchlab may read it), got {version!r}")
    name = doc.get("name")
    if not isinstance(name, str) or not name.strip():
        problems.append("field 'name': required, a non-empty string")
    elif len(name) > MAX_NAME_CHARS:
        problems.append(f"field 'name': {len(name)} characters; at most {MAX_NAME_CHARS}")
    revision = _optional_text(doc, "revision", "", problems)
    if len(revision) > MAX_NAME_CHARS:
        problems.append(f"field 'revision': {len(revision)} characters; at most "
                        f"{MAX_NAME_CHARS}")
    description = _optional_text(doc, "description", "", problems)
    rule = doc.get("decision_rule", "guarded")
    if rule not in DECISION_RULES:
        problems.append(f"field 'decision_rule': must be one of {', '.join(DECISION_RULES)}, "
                        f"got {rule!r}")
    coverage = doc.get("coverage", 0.95)
    if not _is_number(coverage) or not 0.5 <= float(coverage) < 1.0:
        problems.append(f"field 'coverage': must be a probability in [0.5, 1), got {coverage!r}")
    raw_limits = doc.get("limit")
    limits: list[Limit] = []
    if not isinstance(raw_limits, list) or not raw_limits:
        problems.append("field 'limit': at least one [[limit]] table is required")
        raw_limits = []
    seen: dict[str, int] = {}
    for index, raw in enumerate(raw_limits, start=1):
        limit = _parse_limit(raw, index, problems)
        if limit is None:
            continue
        if limit.id in seen:
            problems.append(f"limit {limit.id!r} (#{index}): field 'id': the same id as limit "
                            f"#{seen[limit.id]}; ids must be unique")
        seen.setdefault(limit.id, index)
        limits.append(limit)
    if problems:
        raise SpecError(path, problems)
    assert isinstance(name, str) and type(version) is int
    return Spec(path=path, name=name.strip(), version=version, decision_rule=str(rule),
                coverage=float(coverage), limits=tuple(limits), revision=revision,
                description=description, sha256=sha256)


def _parse_limit(raw: Any, index: int, problems: list[str]) -> Limit | None:
    if not isinstance(raw, dict):
        problems.append(f"limit #{index}: must be a table ([[limit]]), got {type(raw).__name__}")
        return None
    ident = raw.get("id")
    where_text = f"limit {ident!r} (#{index})" if isinstance(ident, str) and ident else \
        f"limit #{index}"
    before = len(problems)

    def bad(field_name: str, message: str) -> None:
        problems.append(f"{where_text}: field {field_name!r}: {message}")

    for key in sorted(set(raw) - _LIMIT_FIELDS):
        bad(key, f"unknown (expected one of {', '.join(sorted(_LIMIT_FIELDS))})")
    if not isinstance(ident, str) or not ident.strip():
        bad("id", "required, a non-empty string")
    elif len(ident) > MAX_NAME_CHARS:
        bad("id", f"{len(ident)} characters; at most {MAX_NAME_CHARS}")
    for key in ("table", "column"):
        if not isinstance(raw.get(key), str) or not raw[key].strip():
            bad(key, "required, a non-empty string")
    bounds: dict[str, float | None] = {}
    for key in ("min", "max"):
        value = raw.get(key)
        if value is None:
            bounds[key] = None
        elif not _is_number(value) or not math.isfinite(float(value)):
            bad(key, f"must be a finite number, got {value!r}")
            bounds[key] = None
        else:
            bounds[key] = float(value)
    if "min" not in raw and "max" not in raw:
        bad("min", "a limit needs 'min', 'max' or both")
    low, high = bounds["min"], bounds["max"]
    if low is not None and high is not None and low > high:
        bad("max", f"{high:g} is below min {low:g}")
    for key in ("uncertainty", "ci95"):
        if key in raw and (not isinstance(raw[key], str) or not raw[key].strip()):
            bad(key, "must name a column (a non-empty string)")
    if "decision_rule" in raw and raw["decision_rule"] not in DECISION_RULES:
        bad("decision_rule", f"must be one of {', '.join(DECISION_RULES)}, "
            f"got {raw['decision_rule']!r}")
    if "uncertainty" in raw and "ci95" in raw:
        bad("ci95", "give 'uncertainty' (1 sigma) or 'ci95', not both")
    for key in ("unit", "description"):
        if key in raw and not isinstance(raw[key], str):
            bad(key, "must be a string")
    where: dict[str, tuple[Scalar, ...]] = {}
    raw_where = raw.get("where", {})
    if not isinstance(raw_where, dict):
        bad("where", "must be a table of column = value, e.g. { element = \"G2E2\" }")
    else:
        for column, value in raw_where.items():
            values = value if isinstance(value, list) else [value]
            if not values or not all(isinstance(v, str | int | float | bool) for v in values):
                bad(f"where.{column}", "must be a string, number or boolean, or a list of them")
                continue
            where[column] = tuple(values)
    if len(problems) == before:
        _check_names(raw, where, bad)
    if len(problems) > before:
        return None
    return Limit(id=str(ident).strip(), table=str(raw["table"]).strip(),
                 column=str(raw["column"]).strip(), min=low, max=high, where=where,
                 uncertainty=raw.get("uncertainty"), ci95=raw.get("ci95"),
                 unit=str(raw.get("unit", "")), description=str(raw.get("description", "")),
                 decision_rule=raw.get("decision_rule"))


def _check_names(raw: dict[str, Any], where: dict[str, tuple[Scalar, ...]],
                 bad: Callable[[str, str], None]) -> None:
    """The limit's table, columns and ``where`` against the results schema."""
    table = str(raw["table"]).strip()
    stem = RESULT_FILE_STEMS.get(table, table)
    if stem not in RESULTS_SCHEMA:
        bad("table", f"no results table {table!r}{_did_you_mean(table, _table_names())} "
            "(the tables: docs/formats/results.md)")
        return
    columns = RESULTS_SCHEMA[stem]
    if columns is None:
        return  # rows vary with what was found: only the name is checked

    def kind_of(field_name: str, column: str) -> str | None:
        kind = columns.get(column)
        if kind is None:
            bad(field_name, f"{table} has no column {column!r}"
                f"{_did_you_mean(column, list(columns))}")
        return kind

    column = str(raw["column"]).strip()
    kind = kind_of("column", column)
    if kind is not None and kind != NUMBER:
        bad("column", f"{table}.{column} holds {kind}, not a number: a limit needs a number")
    for key, allowed in (("uncertainty", (NUMBER,)), ("ci95", (NUMBER, LIST))):
        if isinstance(raw.get(key), str):
            kind = kind_of(key, raw[key].strip())
            if kind is not None and kind not in allowed:
                bad(key, f"{table}.{raw[key]} holds {kind}, not an interval")
    for key, values in where.items():
        kind = kind_of(f"where.{key}", key)
        if kind is None:
            continue
        wrong = [v for v in values if not _of_kind(v, kind)]
        if kind == LIST:
            bad(f"where.{key}", f"{table}.{key} holds lists; a row cannot be picked by it")
        elif wrong:
            hint = " (text goes in quotes)" if kind == TEXT else ""
            bad(f"where.{key}", f"{table}.{key} holds {kind}; got {wrong[0]!r}{hint}")


def _of_kind(value: Scalar, kind: str) -> bool:
    if kind == TEXT:
        return isinstance(value, str)
    if kind == NUMBER:
        return _is_number(value)
    return isinstance(value, bool)


def _table_names() -> list[str]:
    return [*RESULTS_SCHEMA, *RESULT_FILE_STEMS]


def _did_you_mean(name: str, choices: list[str]) -> str:
    close = difflib.get_close_matches(name, choices, n=1, cutoff=0.75)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _optional_text(doc: dict[str, Any], key: str, default: str, problems: list[str]) -> str:
    value = doc.get(key, default)
    if not isinstance(value, str):
        problems.append(f"field {key!r}: must be a string, got {value!r}")
        return default
    return value


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)
