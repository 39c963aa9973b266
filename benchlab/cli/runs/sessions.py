"""``benchlab sessions reindex|list|show|trend`` and ``benchlab benchmark catalog``.

Everything reads the catalogue (``ROOT/catalog.sqlite``, :mod:`benchlab.catalog.index`), which is
created or rebuilt from the session folders when it is missing or damaged.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from benchlab.cli import positive_int
from benchlab.cli.config import SESSIONS_ROOT_HELP, sessions_root
from benchlab.cli.output import (
    add_output_option,
    check_output,
    forced,
    print_outcome,
    write_output,
)

if TYPE_CHECKING:  # the catalogue (numpy, tifffile) is imported by the commands that use it
    from benchlab.catalog.index import Catalog, TrendPoint

LIST_COLUMNS = ("id", "procedure", "status", "sample", "operator", "started_at",
                "results_version", "estimator", "serials")
#: What ``sessions list`` prints by default: within 80 columns (the id holds the start time
#: and the procedure; ``--wide``, ``--json`` and ``--csv`` give every column).
NARROW_LIST_COLUMNS = ("id", "status", "sample", "operator", "results_version", "estimator")
#: Short headers of the narrow listing.
NARROW_HEADERS = {"results_version": "ver"}
TREND_COLUMNS = ("session_id", "started_at", "sample", "version", "estimator", "element",
                 "orientation", "freq_lp_per_mm", "value", "text")

#: Trend markers of a figure with no value, by its catalogue text.
NO_VALUE_MARKERS: dict[str, dict[str, Any]] = {
    "unresolved": {"marker": "v", "color": "#c0392b", "mfc": "none"},
    "aliased": {"marker": "x", "color": "#8e44ad"},
    "clipped": {"marker": "^", "color": "#d35400", "mfc": "none"},
}
NO_VALUE_WORDS = {"unresolved": "not resolved", "aliased": "aliased", "clipped": "clipped"}


def _shown(figure: dict[str, Any]) -> dict[str, Any]:
    """A catalogue figure as listed: words for no value, ``>= x`` for a lower bound (a clipped
    reading, text "lower bound..."), else as stored."""
    value, text = figure["value"], str(figure.get("text") or "")
    if value is None:
        return {**figure, "value": NO_VALUE_WORDS.get(text, "-")}
    if text.startswith("lower bound"):
        from benchlab.analysis.bars.result import AT_LEAST

        return {**figure, "value": f"{AT_LEAST} {_cell(value)}"}
    return figure


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _table(rows: Sequence[dict[str, Any]], columns: Sequence[str], *, wide: bool = True,
           headers: dict[str, str] | None = None) -> str:
    """Left-aligned columns, one line per row (``wide``), or folded to the terminal's width
    (blocks of columns, each led by the row's name)."""
    from benchlab.report.text_table import fit_table, one_line_table

    cells = [[_cell(r.get(c)) for c in columns] for r in rows]
    names = [(headers or {}).get(c, c) for c in columns]
    if wide:
        return one_line_table(names, cells, right=False)
    return fit_table(names, cells, right=False)


def _write_csv(rows: Sequence[dict[str, Any]], columns: Sequence[str], target: str,
               force: bool) -> None:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(columns), extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    if target == "-":
        sys.stdout.write(buf.getvalue())
    else:
        write_output(target, buf.getvalue(), force=force, option="--csv")


def _open(args: argparse.Namespace) -> Catalog:
    from benchlab.catalog.index import Catalog

    return Catalog.open(sessions_root(args.root))


def _filters(args: argparse.Namespace) -> dict[str, Any]:
    return {"procedure": args.procedure, "since": args.since, "sample": args.sample,
            "status": args.status}


def reindex_command(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    with _open(args) as catalog:
        n = catalog.reindex()
    print(f"{catalog.path}: {n} sessions indexed in {time.perf_counter() - t0:.2f} s")
    return 0


def list_command(args: argparse.Namespace) -> int:
    from benchlab.catalog.index import check_list_query

    check_list_query(sort=args.sort, since=args.since)  # usage errors before any work
    if args.csv and args.csv != "-" and not args.json:
        check_output(args.csv, force=forced(args), option="--csv")
    with _open(args) as catalog:
        rows = catalog.sessions(**_filters(args), sort=args.sort, descending=not args.ascending,
                                limit=args.limit, devices=args.json)
    for row in rows:  # a newest version that cannot be read is said, never hidden
        bad = row.get("unreadable_version")
        row["problem"] = f"v{bad} unreadable" if bad else ("error" if row.get("error") else "")

    def text() -> str | None:
        if args.csv:
            _write_csv(rows, (*LIST_COLUMNS, "problem", "error"), args.csv, forced(args))
            return None
        columns = LIST_COLUMNS if args.wide else NARROW_LIST_COLUMNS
        if any(r["problem"] for r in rows):
            columns = (*columns, "problem")
        lines = [_table(rows, columns, wide=args.wide,
                        headers=None if args.wide else NARROW_HEADERS) if rows
                 else "no sessions match"]
        lines += [f"{row['id']}: {row['problem'] or 'error'}: {row['error']}"
                  for row in rows if row.get("error")]
        return "\n".join(lines)

    return print_outcome(args.json, lambda: rows, text)


def show_command(args: argparse.Namespace) -> int:
    with _open(args) as catalog:
        info = catalog.show(args.id)
    return print_outcome(args.json, lambda: info, lambda: _show_text(info))


def _show_text(info: dict[str, Any]) -> str:
    """``sessions show`` for a person: the session's fields, its results versions, and the
    key figures of its latest version."""
    lines = [f"{key:<17} {info[key]}" for key in (
        "id", "path", "procedure", "status", "sample", "operator", "serials", "started_at",
        "finished_at", "software_version", "report", "error") if info.get(key)]
    lines += ["\nresults versions", _table(info["results"], ("version", "estimator", "created_at"))]
    if info["figures"]:
        figures = [_shown(f) for f in info["figures"]]
        lines += [f"\nfigures of v{info['results_version']}",
                  _table(figures, ("view", "element", "orientation", "freq_lp_per_mm",
                                   "quantity", "value", "text"))]
    return "\n".join(lines)


def _plot(points: Sequence[TrendPoint], title: str, quantity: str, target: Path,
          force: bool) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ids = list(dict.fromkeys(p.session_id for p in points))
    order = {sid: i for i, sid in enumerate(ids)}
    fig, ax = plt.subplots(figsize=(max(6.0, 0.25 * len(ids)), 4.0))
    series: dict[str, list[TrendPoint]] = {}
    for p in points:
        series.setdefault(f"{p.element or p.orientation} {p.orientation}".strip(), []).append(p)
    for label, pts in series.items():
        measured = [p for p in pts if p.value is not None]
        if not measured:
            continue
        ax.plot([order[p.session_id] for p in measured], [float(p.value or 0.0) for p in measured],
                marker="o", label=label)
    # No value (not resolved, aliased): a labelled marker along the bottom edge, in axes
    # coordinates, so it is neither drawn as a measured 0 nor stretches the value axis.
    bottom = ax.get_xaxis_transform()
    for text, style in NO_VALUE_MARKERS.items():
        xs = [order[p.session_id] for p in points if p.value is None and p.text == text]
        if xs:
            ax.plot(xs, [0.03] * len(xs), ls="none", ms=8, transform=bottom,
                    label=f"{NO_VALUE_WORDS[text]} (no value)", **style)
    if any(p.value is None for p in points) and not any(p.value is not None for p in points):
        ax.set_yticks([])  # nothing measured: no value axis to read a number from
    labels = [next(p.sample or p.session_id for p in points if p.session_id == sid)
              for sid in ids]
    ax.set_xticks(range(len(ids)), labels, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel(quantity)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if len(series) > 1 or any(p.value is None for p in points):
        ax.legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    write_output(target, buf.getvalue(), force=force, option="--plot")


def trend_command(args: argparse.Namespace) -> int:
    from benchlab.catalog.index import check_trend_query

    check_trend_query(element=args.element, freq_lp_per_mm=args.freq,
                      orientation=args.orientation, since=args.since)  # before any work
    if args.csv and args.csv != "-" and not args.json:
        check_output(args.csv, force=forced(args), option="--csv")
    if args.plot:
        check_output(args.plot, force=forced(args), option="--plot")
    with _open(args) as catalog:
        points = catalog.trend(view=args.view, element=args.element,
                               orientation=args.orientation, freq_lp_per_mm=args.freq,
                               quantity=args.quantity, **_filters(args))
    rows = [p._asdict() for p in points]
    shown = [_shown(r) for r in rows]
    what = " ".join(x for x in (args.view, args.element or "",
                                f"{args.freq:g} lp/mm" if args.freq else "",
                                args.orientation or "", args.quantity) if x)

    def text() -> str | None:
        if args.csv:
            _write_csv(rows, TREND_COLUMNS, args.csv, forced(args))
            return None
        return _table(shown, TREND_COLUMNS) if rows else f"no session has {what}"

    status = print_outcome(args.json, lambda: rows, text)
    if points and args.plot != "":
        _plot(points, f"{what} across {len({p.session_id for p in points})} sessions",
              args.quantity, Path(args.plot), forced(args))
        print(f"plot: {Path(args.plot).absolute()}", file=sys.stderr)  # default: the cwd
    return status


def benchmark_catalog_command(args: argparse.Namespace) -> int:
    """Query times over a synthetic catalogue of ``--sessions`` sessions."""
    from benchlab.benchmarks.batch import run_catalog_benchmark

    print(run_catalog_benchmark(n_sessions=args.sessions, source=args.source))
    return 0


def _add_filters(p: argparse.ArgumentParser) -> None:
    p.add_argument("--root", default=None, help=SESSIONS_ROOT_HELP)
    p.add_argument("--procedure", help="only this procedure (mtf, radiometry)")
    p.add_argument("--since", metavar="DATE", help="only sessions started on or after DATE "
                   "(YYYY-MM-DD or ISO time, UTC)")
    p.add_argument("--sample", metavar="ID", help="only this lens/sample (run --sample)")
    p.add_argument("--status", help="only this status (completed, failed, running, ...)")


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``sessions`` and ``benchmark catalog``."""
    top = commands.add_parser(
        "sessions", help="catalogue of sessions: list, show, trends across lenses",
        description="Query the session catalogue (ROOT/catalog.sqlite), a cache of the session "
        "folders kept up to date by every run, resume, analysis and report; missing or "
        "damaged, it is rebuilt from the folders.",
    )
    sub = top.add_subparsers(dest="sessions_command", metavar="WHAT", required=True)
    r = sub.add_parser("reindex", help="rebuild the catalogue from the session folders",
                       description="Rebuild every catalogue row from the session folders.")
    r.add_argument("--root", default=None, help=SESSIONS_ROOT_HELP)
    r.set_defaults(func=reindex_command)

    ls = sub.add_parser("list", help="sessions matching filters, newest first",
                        description="List catalogued sessions matching every filter given.")
    _add_filters(ls)
    ls.add_argument("--sort", default="started_at", help="column to sort by (default "
                    "started_at: id, procedure, status, sample, operator, results_version)")
    ls.add_argument("--ascending", action="store_true", help="oldest / smallest first")
    ls.add_argument("--limit", type=positive_int, metavar="N", help="at most N sessions")
    ls.add_argument("--wide", action="store_true", help="every column (procedure, start "
                    "time, serials too), one line per session however wide; by default the "
                    "table fits the terminal (COLUMNS, else 80)")
    ls.add_argument("--json", action="store_true", help="print a JSON list")
    add_output_option(ls, "--csv", metavar="FILE",
                      help="write CSV for spreadsheets ('-': stdout)")
    ls.set_defaults(func=list_command)

    sh = sub.add_parser("show", help="one session: devices, results versions, key figures",
                        description="Show one catalogued session and its latest figures.")
    sh.add_argument("id", help="session id (its folder name)")
    sh.add_argument("--root", default=None, help=SESSIONS_ROOT_HELP)
    sh.add_argument("--json", action="store_true", help="print one JSON object")
    sh.set_defaults(func=show_command)

    t = sub.add_parser(
        "trend", help="one figure across sessions: table and PNG plot",
        description="One key figure across sessions, oldest first, from each session's latest "
        "results version: e.g. --view forward --element G2E2 --orientation S, or --view "
        "forward --freq 70 (Table 4.15's averaged modulation; with --orientation S/T the "
        "element nearest 70 lp/mm within 20 %).",
    )
    _add_filters(t)
    t.add_argument("--view", required=True,
                   help="forward, radial, radiometry, or a results table name")
    t.add_argument("--element", help="USAF element (G2E2), radial '2lp', radiometry '5mm'")
    t.add_argument("--orientation", help="S (sagittal), T (tangential), A (averaged)")
    t.add_argument("--freq", type=float, metavar="LP_PER_MM", help="image frequency, lp/mm")
    t.add_argument("--quantity", default="modulation",
                   help="figure name (default modulation; radiometry: measured_normalised)")
    add_output_option(t, "--plot", default="trend.png", metavar="FILE.png",
                      help="PNG plot to write (default trend.png in the current folder; '' for "
                      "none)")
    t.add_argument("--json", action="store_true", help="print a JSON list")
    add_output_option(t, "--csv", metavar="FILE",
                      help="write CSV for spreadsheets ('-': stdout)")
    t.set_defaults(func=trend_command)

    b = benchmarks.add_parser(
        "catalog", help="catalogue query time over a synthetic catalogue of many sessions",
        description="Fill a temporary catalogue with N synthetic sessions (the figures of one "
        "real session, varied) and time list and trend queries (min and median of repeats).",
    )
    b.add_argument("--sessions", type=positive_int, default=10_000,
                   help="synthetic sessions (10000)")
    b.add_argument("--source", help="a real session folder to copy figures from "
                   "(default: one simulated MTF run made for the benchmark)")
    b.set_defaults(func=benchmark_catalog_command)
