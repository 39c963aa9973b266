"""``benchlab verify``, ``units``, ``unit``, ``lot`` and ``certificate``: acceptance per unit.

``verify SESSION... --spec FILE`` decides every limit of the spec (pure rules in
:mod:`benchlab.acceptance.decide`), stores the verdict as a new version in each session and
in the catalogue, and exits 0 (pass), 1 (fail) or 3 (indeterminate); 2 stays the usage
error (a malformed spec among them).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from benchlab.cli import UsageError

if TYPE_CHECKING:
    from benchlab.acceptance.spec import Spec
    from benchlab.acceptance.verify import UnitResult

VERDICT_COLUMNS = ("limit_id", "row", "column", "reading", "low", "high", "limit", "margin",
                   "rule", "verdict")


def _load_spec(path: str) -> Spec:
    from benchlab.acceptance.spec import SpecError, load_spec

    try:
        return load_spec(path)
    except SpecError as exc:
        raise UsageError(str(exc)) from None


def _fmt(value: Any) -> str:
    from benchlab.acceptance.verify import format_number

    return format_number(value) if isinstance(value, float | int) or value is None \
        else str(value)


def _limit_text(row: dict[str, Any]) -> str:
    lo, hi, unit = row.get("min"), row.get("max"), row.get("unit") or ""
    text = (f"{lo:g} .. {hi:g}" if lo is not None and hi is not None
            else f">= {lo:g}" if lo is not None else f"<= {hi:g}")
    return f"{text} {unit}".strip()


def verdict_table(rows: Sequence[dict[str, Any]]) -> str:
    """The verdict rows as an aligned text table, notes under it."""
    cells = []
    for r in rows:
        verdict = r["verdict"] + (" (reading decides)" if r.get("decided_by", "").startswith(
            "reading") else "")
        cells.append([r["limit_id"], r["row"] or "-", r["column"], _fmt(r["reading"]),
                      _fmt(r["low"]), _fmt(r["high"]), _limit_text(r), _fmt(r["margin"]),
                      r["rule"], verdict])
    widths = [max([len(c)] + [len(row[i]) for row in cells])
              for i, c in enumerate(VERDICT_COLUMNS)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(VERDICT_COLUMNS, widths, strict=True))]
    lines += ["  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)) for row in cells]
    notes = [f"  {r['limit_id']}{' ' + r['row'] if r['row'] else ''}: {'; '.join(r['notes'])}"
             for r in rows if r.get("notes")]
    return "\n".join(line.rstrip() for line in lines) + ("\nnotes:\n" + "\n".join(notes)
                                                          if notes else "")


def worst_status(verdicts: Sequence[str]) -> int:
    """Exit status of several units: any fail 1, else any indeterminate 3, else 0."""
    from benchlab.acceptance.decide import EXIT_STATUS, combine

    return EXIT_STATUS[combine(verdicts)]


def verify_command(args: argparse.Namespace) -> int:
    from benchlab import __version__
    from benchlab.acceptance.store import record_of, store_verdict
    from benchlab.acceptance.verify import check_sessions, group_units, verify_unit
    from benchlab.catalog.index import record_session

    spec = _load_spec(args.spec)  # every problem of the spec before any session is read
    sessions = check_sessions(args.sessions)
    units: list[UnitResult] = [verify_unit(group, spec) for group in group_units(sessions)]
    records = []
    for unit in units:
        record = record_of(unit, __version__)
        if not args.no_store:
            stored = []
            for s in unit.sessions:
                path, version = store_verdict(s.path, record)
                stored.append({"session": str(s.path), "file": str(path), "version": version})
                record_session(s.path)
            record["stored"] = stored
        records.append(record)
    if args.json:
        print(json.dumps(records if len(records) > 1 else records[0], indent=1))
    else:
        for record in records:
            _print_unit(record)
    return worst_status([u.verdict for u in units])


def _print_unit(record: dict[str, Any]) -> None:
    spec = record["spec"]
    unit = record["unit"]
    names = ", ".join(s["id"] for s in record["sessions"])
    print(f"unit {unit['serial'] or '(no serial)'}  lot {unit['lot'] or '-'}  sessions {names}")
    print(f"spec {spec['name']}{' rev ' + spec['revision'] if spec['revision'] else ''}  "
          f"rule {spec['decision_rule']}  coverage {spec['coverage']:.0%}")
    print(verdict_table(record["rows"]))
    for item in record.get("stored", []):
        print(f"stored: {item['file']}")
    print(f"unit verdict: {record['verdict'].upper()}\n")


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction
             ) -> None:
    v = commands.add_parser(
        "verify", help="decide pass / fail / indeterminate per limit of a spec file",
        description="Verify sessions against a spec file (docs/formats/spec.md). Sessions with "
        "the same serial number are one unit. Every row gives the reading, its interval, the "
        "limit, the margin and the rule; the verdict is stored in each session (a new "
        "version) and in the catalogue. Exit status: 0 pass, 1 fail, 3 indeterminate "
        "(the worst unit), 2 usage error (a malformed spec).")
    v.add_argument("sessions", nargs="+", metavar="SESSION", help="session folder(s)")
    v.add_argument("--spec", required=True, metavar="FILE", help="spec file (TOML)")
    v.add_argument("--json", action="store_true", help="print the verdict record(s) as JSON")
    v.add_argument("--no-store", action="store_true",
                   help="decide only; store nothing in the sessions or the catalogue")
    v.set_defaults(func=verify_command)
