"""``benchlab verify``, ``units``, ``unit``, ``lot`` and ``certificate``: acceptance per unit.

``verify SESSION... --spec FILE`` decides every limit of the spec (pure rules in
:mod:`benchlab.acceptance.decide`), stores the verdict as a new version in each session and
in the catalogue, and exits 0 (pass), 1 (fail) or 3 (indeterminate); 2 stays the usage
error (a malformed spec among them).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from benchlab.cli import UsageError, positive_int
from benchlab.cli.config import SESSIONS_ROOT_HELP, sessions_root
from benchlab.cli.output import (
    add_output_option,
    check_output,
    forced,
    print_outcome,
    write_output,
)

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
    from benchlab.acceptance.spec import describe_limit

    return describe_limit(row.get("min"), row.get("max"), row.get("unit") or "")


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


def spec_summary(spec: Spec) -> str:
    """What a checked spec file holds: its header line, then one line per limit."""
    lines = [f"{spec.path}: {spec.name}" + (f" rev {spec.revision}" if spec.revision else "")
             + f", rule {spec.decision_rule}, coverage {spec.coverage:.0%}, "
             f"{len(spec.limits)} limit(s)"]
    for lim in spec.limits:
        where = " ".join(f"{k}={'|'.join(map(str, v))}" for k, v in lim.where.items())
        rule = lim.decision_rule or spec.decision_rule
        lines.append(f"  {lim.id}: {lim.table}.{lim.column}" + (f" [{where}]" if where else "")
                     + f" {lim.describe()} ({rule})")
    return "\n".join(lines)


def verify_command(args: argparse.Namespace) -> int:
    from benchlab import __version__
    from benchlab.acceptance.store import record_of, store_verdict
    from benchlab.acceptance.verify import check_sessions, group_units, verify_unit
    from benchlab.catalog.index import record_session

    if args.example_spec:
        from importlib.resources import files

        if args.sessions or args.spec is not None:
            raise UsageError("verify: --example-spec prints the example and takes no SESSION "
                             "or --spec")
        print(files("benchlab.acceptance").joinpath("example-spec.toml").read_text("utf-8"),
              end="")
        return 0
    if args.spec is None:
        raise UsageError("verify: give SESSION... and --spec FILE, or --spec FILE alone to check "
                         "the file (--example-spec prints a spec to start from)")
    spec = _load_spec(args.spec)  # every problem of the spec before any session is read
    if not args.sessions:
        print(spec_summary(spec))
        return 0
    sessions = check_sessions(args.sessions)
    units: list[UnitResult] = [verify_unit(group, spec) for group in group_units(sessions)]
    records = []
    for unit in units:
        record = record_of(unit, __version__)
        if not args.no_store:
            stored = []
            for s in unit.sessions:
                path, version, written = store_verdict(s.path, record)
                stored.append({"session": str(s.path), "file": str(path), "version": version,
                               "new": written})
                record_session(s.path)
            record["stored"] = stored
            versions = {item["version"] for item in stored}
            if len(versions) == 1:  # the version each session's file holds
                record["version"] = versions.pop()
        records.append(record)

    def text() -> None:
        for record in records:
            _print_unit(record)

    return print_outcome(args.json, lambda: records if len(records) > 1 else records[0], text,
                         status=worst_status([u.verdict for u in units]), indent=1)


def _print_unit(record: dict[str, Any]) -> None:
    from benchlab.storage import printable_name

    spec = record["spec"]
    unit = record["unit"]
    names = ", ".join(printable_name(s["id"]) for s in record["sessions"])
    print(f"unit {unit['serial'] or '(no serial)'}  lot {unit['lot'] or '-'}  sessions {names}")
    print(f"spec {spec['name']}{' rev ' + spec['revision'] if spec['revision'] else ''}  "
          f"rule {spec['decision_rule']}  coverage {spec['coverage']:.0%}")
    print(verdict_table(record["rows"]))
    if record.get("disagreements"):
        print(f"sessions of this unit disagree beyond their uncertainties on "
              f"{len(record['disagreements'])} reading(s): see the notes")
    for item in record.get("stored", []):
        file = printable_name(item["file"])
        print(f"stored: {file}" if item["new"] else
              f"identical to {file}: no new version written")
    print(f"unit verdict: {record['verdict'].upper()}\n")


def units_command(args: argparse.Namespace) -> int:
    from benchlab.catalog.index import Catalog

    with Catalog.open(sessions_root(args.root)) as catalog:
        units = catalog.units(lot=args.lot)
    return print_outcome(args.json, lambda: units, lambda: _units_text(units))


def _units_text(units: Sequence[dict[str, Any]]) -> str:
    """``units`` for a person: one line per unit, its latest verdict per spec."""
    if not units:
        return "no units (sessions carry a serial number with run --serial)"
    specs = sorted({name for u in units for name in u["verdicts"]})
    header = ["serial", "lot", "sessions", *specs]
    cells = [[u["serial"], u["lot"] or "-", str(len(u["sessions"])),
              *(_unit_verdict(u["verdicts"][n]) if n in u["verdicts"] else "-" for n in specs)]
             for u in units]
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, h in enumerate(header)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip()
             for line in [header, *cells]]
    if any(v.get("disagreements") for u in units for v in u["verdicts"].values()):
        lines.append("* sessions of the unit disagree beyond their uncertainties: the verdict's "
                     "notes name them (benchlab certificate SESSION)")
    return "\n".join(lines)


def _unit_verdict(verdict: dict[str, Any]) -> str:
    """A unit's stored verdict for ``units``: marked ``*`` when its sessions disagree."""
    return verdict["verdict"] + ("*" if verdict.get("disagreements") else "")


def unit_command(args: argparse.Namespace) -> int:
    """Change a session's serial number or lot: session.json rewritten, the change journalled
    (old and new values, the reason) and the catalogue updated."""
    from benchlab.catalog.index import record_session
    from benchlab.session import Session

    if args.serial is None and args.lot is None:
        raise UsageError("unit: give --serial, --lot or both")
    session = Session.open(Path(args.session))
    meta = session.meta
    new = {k: v for k, v in (("sample", args.serial), ("lot", args.lot)) if v is not None}
    old = {k: meta.get(k, "") for k in new}
    if old == new:
        print(f"{session.path}: unchanged")
        return 0
    session.hold(command="benchlab unit")
    try:
        session.log_event("unit_relabelled", old=old, new=new, reason=args.reason)
        session.update_meta(**new)
    finally:
        session.release()
    record_session(session.path)
    print(f"{session.path}: " + ", ".join(f"{'serial' if k == 'sample' else k} "
                                          f"{old[k] or '-'} -> {v or '-'}" for k, v in new.items()))
    return 0


def lot_command(args: argparse.Namespace) -> int:
    from benchlab.acceptance.lot import lot_statistics
    from benchlab.acceptance.verify import check_sessions, group_units, verify_unit
    from benchlab.catalog.index import Catalog, session_folder

    spec = _load_spec(args.spec)
    root = sessions_root(args.root)
    if args.html:  # before any work
        check_output(args.html, force=forced(args), option="--html")
    with Catalog.open(root) as catalog:
        paths = [session_folder(s["path"])
                 for s in catalog.sessions(lot=args.lot, descending=False)]
    if not paths:
        raise UsageError(f"no session of lot {args.lot!r} under {root}")
    units = [verify_unit(g, spec) for g in group_units(check_sessions(paths))]
    result = lot_statistics(units)
    result.update(lot=args.lot, spec=spec.header())
    if args.html:
        from benchlab.acceptance.lot_report import render_lot_report

        write_output(args.html, render_lot_report(result), force=forced(args), option="--html")
    return print_outcome(args.json, lambda: result, lambda: _lot_text(result) + (
        f"\nreport: {args.html}" if args.html else ""))


def _lot_text(result: dict[str, Any]) -> str:
    c = result["verdicts"]
    y = result["yield"]
    lines = [f"lot {result['lot']}  spec {result['spec']['name']}  "
             f"rule {result['spec']['decision_rule']}  units {result['units']}",
             f"pass {c['pass']}  fail {c['fail']}  indeterminate {c['indeterminate']}  yield "
             + ("-" if y is None else f"{y:.1%} (95 % interval {result['yield_low']:.1%} .. "
                                       f"{result['yield_high']:.1%}, Clopper-Pearson)"), ""]
    header = ["limit", "row", "n", "mean", "std", "p05", "p95", "limit", "Cpk", "Cpk 95 %",
              "drift"]
    cells = []
    for q in result["quantities"]:
        drift = q["drift"]
        flags = "-" if drift is None else ", ".join(
            [f"{len(drift['beyond_limits'])} beyond limits"] * bool(drift["beyond_limits"])
            + [f"run {a}..{b}" for a, b in drift["runs"]]) or "none"
        cpk_ci = "-" if q["cpk_low"] is None else f"{q['cpk_low']:.2f} .. {q['cpk_high']:.2f}"
        cells.append([q["limit_id"], q["row"] or "-", str(q["n"]), _fmt(q["mean"]),
                      _fmt(q["std"]), _fmt(q["p05"]), _fmt(q["p95"]), _limit_text(q),
                      "-" if q["cpk"] is None else f"{q['cpk']:.2f}", cpk_ci, flags])
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, h in enumerate(header)]
    for line in [header, *cells]:
        lines.append("  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip())
    return "\n".join(lines)


def certificate_command(args: argparse.Namespace) -> int:
    from benchlab.acceptance.certificate import render_certificate
    from benchlab.acceptance.certificate_pdf import certificate_pdf
    from benchlab.acceptance.store import read_verdict
    from benchlab.storage import printable_name

    pdf = args.pdf or (args.out is not None and Path(args.out).suffix.lower() == ".pdf")
    if args.pdf and args.out and Path(args.out).suffix.lower() in (".html", ".htm"):
        raise UsageError(f"--pdf writes a PDF, but --out names an HTML file: {args.out}")
    folder = Path(args.session)
    record = read_verdict(folder, args.version)
    out = (Path(args.out) if args.out
           else folder / f"certificate-v{record['version']}.{'pdf' if pdf else 'html'}")
    option = "--out" if args.out else "certificate"
    check_output(out, force=forced(args), option=option)  # before rendering
    if pdf:
        write_output(out, certificate_pdf(record, session_id=folder.name), force=forced(args),
                     option=option)
    else:
        write_output(out, render_certificate(record, session_id=folder.name),
                     force=forced(args), option=option)
    print(f"certificate: {printable_name(out)}  (unit {record['unit']['serial'] or '-'}: "
          f"{record['verdict']})")
    return 0


def benchmark_command(args: argparse.Namespace) -> int:
    from benchlab.benchmarks.acceptance import FREQ_LP_PER_MM, LIMIT_MIN, rule_figures, timing

    rows = [f.row() for f in rule_figures(args.units, args.seed)]
    print(f"limit: modulation >= {LIMIT_MIN} at {FREQ_LP_PER_MM:g} lp/mm; {args.units} "
          "units per lot; coverage 95 %")
    header = list(rows[0])
    cells = [[f"{v:.2f}" if isinstance(v, float) else str(v) for v in r.values()] for r in rows]
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, h in enumerate(header)]
    for line in [header, *cells]:
        print("  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True)).rstrip())
    worst = max(r["false accept % of failing"] for r in rows if r["rule"] == "guarded")
    print(f"guarded: worst false accepts {worst:.2f} % of truly failing units (bound 2.5 %)")
    if args.lot_units:
        t = timing(args.lot_units, args.seed)
        print(f"verify time: {t['per_session_s'] * 1e3:.1f} ms per session (read + decide); "
              f"{t['lot_s']:.2f} s per {t['lot_units']}-unit lot")
    return 0 if worst <= 2.5 else 1


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction
             ) -> None:
    v = commands.add_parser(
        "verify", help="decide pass / fail / indeterminate per limit of a spec file",
        description="Verify sessions against a spec file (docs/formats/spec.md). Sessions with "
        "the same serial number are one unit. Every row gives the reading, its interval, the "
        "limit, the margin and the rule; the verdict is stored in each session (a new "
        "version) and in the catalogue. Exit status: 0 pass, 1 fail, 3 indeterminate "
        "(the worst unit), 2 usage error: a malformed spec, or one naming a table, column or "
        "where value the results do not have (docs/formats/results.md); nothing is stored "
        "then. A verification identical to the newest stored one stores no new version.")
    v.add_argument("sessions", nargs="*", metavar="SESSION", help="session folder(s)")
    v.add_argument("--spec", metavar="FILE",
                   help="spec file (TOML); without SESSION the file is only checked and listed")
    v.add_argument("--example-spec", action="store_true",
                   help="print a commented example spec file and exit: benchlab verify "
                   "--example-spec > spec.toml. Its bar and slanted-edge limits (both decision "
                   "rules) are decided on an MTF session alone; its camera limits, for a unit "
                   "that also has a characterisation session, are commented out")
    v.add_argument("--json", action="store_true", help="print the verdict record(s) as JSON")
    v.add_argument("--no-store", action="store_true",
                   help="decide only; store nothing in the sessions or the catalogue")
    v.set_defaults(func=verify_command)

    u = commands.add_parser(
        "units", help="list units under test with their latest verdict per spec",
        description="List the units (sessions' serial numbers) under a sessions folder, with "
        "their lot and the latest stored verdict per spec (from the catalogue).")
    u.add_argument("--root", default=None, help=SESSIONS_ROOT_HELP)
    u.add_argument("--lot", help="only the units of this lot")
    u.add_argument("--json", action="store_true", help="print JSON")
    u.set_defaults(func=units_command)

    e = commands.add_parser(
        "unit", help="change a session's serial number or lot (journalled)",
        description="Change the serial number or lot a session carries. session.json is "
        "rewritten and the change (old, new, reason) is journalled in events.jsonl; stored "
        "verdicts keep the values they were decided with.")
    e.add_argument("session", metavar="SESSION")
    e.add_argument("--serial", help="new serial number")
    e.add_argument("--lot", help="new lot")
    e.add_argument("--reason", required=True, help="why (journalled)")
    e.set_defaults(func=unit_command)

    lot = commands.add_parser(
        "lot", help="yield, capability (Cpk) and drift of a lot against a spec",
        description="Verify every unit of a lot (sessions with --lot LOT) against a spec "
        "(nothing stored) and print the yield with its binomial interval, per-limit "
        "distributions, Cpk with its interval and drift flags (individuals control chart).")
    lot.add_argument("lot", metavar="LOT")
    lot.add_argument("--spec", required=True, metavar="FILE", help="spec file (TOML)")
    lot.add_argument("--root", default=None, help=SESSIONS_ROOT_HELP)
    lot.add_argument("--json", action="store_true", help="print JSON")
    add_output_option(lot, "--html", metavar="FILE", help="also write an HTML lot report with "
                      "a control chart per limited quantity")
    lot.set_defaults(func=lot_command)

    c = commands.add_parser(
        "certificate", help="the unit's certificate (HTML or PDF) from its stored verdict",
        description="Render a stored verdict (benchlab verify) as one self-contained HTML "
        "page, or with --pdf an A4 PDF: unit, spec, rule, every limit's row, frame hashes, "
        "software version.")
    c.add_argument("session", metavar="SESSION")
    c.add_argument("--version", type=positive_int, help="verdict version (default: latest)")
    c.add_argument("--pdf", action="store_true",
                   help="write an A4 PDF (also chosen by an --out name ending in .pdf)")
    add_output_option(c, "--out", metavar="FILE",
                      help="output file (default SESSION/certificate-v<N>.html, .pdf with --pdf)")
    c.set_defaults(func=certificate_command)

    b = benchmarks.add_parser(
        "acceptance", help="decision rules on simulated lots: false accepts and rejects",
        description="Judge simulated lots (a lens-variation model with known truth per "
        "unit) with the guarded and simple rules; print false-accept and false-reject rates "
        "and the indeterminate share, and the verification time per session and per lot. "
        "Exit 1 if the guarded rule accepts more than 2.5 % of truly failing units.")
    b.add_argument("--units", type=positive_int, default=2000,
                   help="units per simulated lot (default 2000)")
    b.add_argument("--lot-units", type=int, default=1000,
                   help="session folders of the timed lot (default 1000; 0: no timing)")
    b.add_argument("--seed", type=int, default=0, help="random seed")
    b.set_defaults(func=benchmark_command)
