"""The unit's certificate: one self-contained HTML page rendered from a stored verdict record.

Rendered from ``verdicts/v<N>.json`` (never from a second verification), so what is filed is
what was decided: unit and lot, spec name, revision and the sha256 of its file, decision rule
and coverage, every limit's row (reading, interval, limit, margin, verdict and why), readings
of the unit's sessions that disagree beyond their uncertainties, the sessions with their
results version, the sha256 of every file of those results versions (the numbers certified)
and of every frame (what they were measured from), and the software version.
Nothing is fetched from outside the page; the print style sheet fits A4 portrait. The same
text is drawn as an A4 PDF by :mod:`benchlab.acceptance.certificate_pdf`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from benchlab.acceptance.agreement import Disagreement
from benchlab.acceptance.spec import describe_limit
from benchlab.report.html import esc, local_time
from benchlab.storage import printable_name

SHA_KEY = "Spec file sha256"
#: Said where a verdict record predates the results hashes (benchlab 0.2.0).
NO_RESULTS_HASHES = "not recorded (a verdict stored before the results hashes were recorded)"
MARGIN_NOTE = ("Margin: how far the reading lies inside the limit (negative: outside), in the "
               "quantity's unit.")
SIGNATURES = ("Inspected by, date", "Approved by, date")
VERDICT_COLOURS = {"pass": "#1e7b34", "fail": "#b3261e", "indeterminate": "#8a5a00"}

_CSS = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 60em; color: #222; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.1em; margin-top: 1.5em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; width: 100%; font-size: 0.85em; }
th, td { border: 1px solid #bbb; padding: 0.2em 0.4em; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr.note td { border-top: none; padding-top: 0; }
table.kv th { width: 14em; background: #f4f4f4; }
.verdict { font-weight: bold; text-transform: uppercase; }
.unit-verdict { font-size: 1.6em; padding: 0.2em 0.6em; border: 3px solid; display: inline-block; }
.hash { font-family: ui-monospace, monospace; font-size: 0.8em; word-break: break-all; }
.notes { font-size: 0.85em; color: #555; }
.sign { margin-top: 2em; display: flex; gap: 4em; }
.sign div { border-top: 1px solid #555; width: 16em; padding-top: 0.2em; font-size: 0.85em; }
@media print {
  @page { size: A4 portrait; margin: 15mm; }
  body { margin: 0; max-width: none; font-size: 10pt; }
  h2 { break-after: avoid; }
  tr { break-inside: avoid; }
}
"""


def _num(value: Any) -> str:
    if not isinstance(value, int | float) or isinstance(value, bool):
        return "-"
    return "-" if not math.isfinite(value) else f"{value:.4g}"


def _limit(row: Mapping[str, Any]) -> str:
    return describe_limit(row.get("min"), row.get("max"), row.get("unit") or "",
                          signs=("\u2265", "\u2264"))


@dataclass(frozen=True)
class LimitLine:
    """One row of the limits table, as text."""

    limit_id: str
    table: str
    row: str
    column: str
    reading: str
    interval: str
    limit: str
    margin: str
    rule: str
    verdict: str
    why: str


@dataclass(frozen=True)
class CertificateContent:
    """What a certificate says, as text: the HTML page and the PDF both draw this."""

    title: str
    verdict: str
    record_name: str  # the session and verdict file the certificate was rendered from
    identity: tuple[tuple[str, str], ...]
    coverage: float
    rule: str
    limits: tuple[LimitLine, ...]
    #: (session, procedure, started, results version, software it was acquired with)
    sessions: tuple[tuple[str, str, str, str, str], ...]
    #: (session, frame, sha256)
    frames: tuple[tuple[str, str, str], ...]
    #: (session, results file ``results/v<N>/<file>``, sha256)
    results: tuple[tuple[str, str, str], ...] = ()
    #: One line per reading of another session of the unit that disagrees with the one
    #: that decided (:mod:`benchlab.acceptance.agreement`).
    disagreements: tuple[str, ...] = ()


def certificate_content(record: Mapping[str, Any], session_id: str = "") -> CertificateContent:
    """The text of the certificate of one stored verdict record.

    Parameters
    ----------
    record : mapping
        A verdict record as stored by ``benchlab verify`` (``verdicts/v<N>.json``).
    session_id : str
        The session folder's name, printed with the record's version.

    Returns
    -------
    CertificateContent
        Every line of the certificate as text; numbers formatted, limits with their sign.
    """
    session_id = printable_name(session_id)  # the page is UTF-8 text only
    unit, spec = record["unit"], record["spec"]
    serial = unit.get("serial") or "(no serial number)"
    record_name = f"{session_id} verdicts/v{record.get('version', '?')}.json"
    identity = (
        ("Unit (serial number)", serial), ("Lot", unit.get("lot") or "-"),
        ("Specification", spec["name"]), ("Revision", spec.get("revision") or "-"),
        ("Spec file", spec.get("file", "")), (SHA_KEY, spec.get("sha256", "")),
        ("Spec format", f"{spec.get('format', '')} v{spec.get('format_version', '')}"),
        ("Decision rule", _rule_text(spec)),
        ("Verdict record", record_name),
        ("Decided", local_time(record.get("created_at"))),
        ("Software", f"benchlab {record.get('software_version', '')}"))
    limits = []
    for r in record["rows"]:
        why = "; ".join(r.get("notes") or [])
        if str(r.get("decided_by", "")).startswith("reading") and "reading decides" not in why:
            why = ("the reading decided (shared risk)" + ("; " + why if why else ""))
        interval = ("none" if r.get("low") is None or r.get("high") is None
                    else f"{_num(r.get('low'))} \u2013 {_num(r.get('high'))}")
        limits.append(LimitLine(
            limit_id=str(r["limit_id"]), table=str(r.get("table", "")), row=str(r.get("row") or ""),
            column=str(r["column"]), reading=_num(r.get("reading")), interval=interval,
            limit=_limit(r), margin=_num(r.get("margin")), rule=str(r.get("rule", "")),
            verdict=str(r["verdict"]), why=why))
    sessions, frames, results = [], [], []
    for s in record.get("sessions", []):
        sid = printable_name(str(s["id"]))
        sessions.append((sid, str(s.get("procedure", "")), local_time(s.get("started_at")),
                         f"v{s.get('results_version')}{' (partial)' if s.get('partial') else ''}",
                         str(s.get("software_version", ""))))
        frames += [(sid, str(name), str(digest))
                   for name, digest in sorted((s.get("frames_sha256") or {}).items())]
        if s.get("results_version") is None:
            continue
        folder = f"results/v{s['results_version']}"
        hashes = s.get("results_sha256")
        results += ([(sid, f"{folder}/{name}", str(digest))
                     for name, digest in sorted(hashes.items())] if hashes
                    else [(sid, folder, NO_RESULTS_HASHES)])
    return CertificateContent(
        title=f"Acceptance certificate - {serial}", verdict=str(record["verdict"]),
        record_name=record_name, identity=identity, coverage=float(spec.get("coverage", 0.95)),
        rule=_rule_text(spec), limits=tuple(limits), sessions=tuple(sessions), frames=tuple(frames),
        results=tuple(results),
        disagreements=tuple(printable_name(Disagreement.from_dict(d).text())
                            for d in record.get("disagreements") or []))


def _badge(verdict: str, css: str = "verdict") -> str:
    colour = VERDICT_COLOURS.get(verdict, "#444")
    return f"<span class='{css}' style='color:{colour};border-color:{colour}'>" \
           f"{esc(verdict)}</span>"


def render_certificate(record: Mapping[str, Any], session_id: str = "") -> str:
    """The certificate page of one stored verdict record."""
    c = certificate_content(record, session_id)
    rows_html = []
    for r in c.limits:
        rows_html.append(
            "<tr>" + "".join([
                f"<td>{esc(r.limit_id)}</td>",
                f"<td>{esc(r.table)}<br><small>{esc(r.row)}</small></td>",
                f"<td>{esc(r.column)}</td>", f"<td class='num'>{esc(r.reading)}</td>",
                f"<td class='num'>{esc(r.interval)}</td>", f"<td class='num'>{esc(r.limit)}</td>",
                f"<td class='num'>{esc(r.margin)}</td>", f"<td>{esc(r.rule)}</td>",
                f"<td>{_badge(r.verdict)}</td>"])
            + "</tr>")
        if r.why:
            rows_html.append(f"<tr class='note'><td></td><td colspan='8' class='notes'>"
                             f"{esc(r.why)}</td></tr>")
    sessions_html = "".join("<tr>" + "".join(f"<td>{esc(v)}</td>" for v in s) + "</tr>"
                            for s in c.sessions)
    frames_html, results_html = (
        "".join(f"<tr><td>{esc(sid)}</td><td>{esc(name)}</td>"
                f"<td class='hash'>{esc(digest)}</td></tr>" for sid, name, digest in rows)
        for rows in (c.frames, c.results))
    disagree_html = (
        "<h2>Sessions that disagree</h2><ul id='disagreements'>"
        + "".join(f"<li>{esc(d)}</li>" for d in c.disagreements)
        + "</ul><p class='notes'>Readings of the unit's sessions that differ beyond their "
        "uncertainties (E<sub>n</sub> &gt; 1, ISO 13528): such a row is never a pass.</p>"
        if c.disagreements else "")
    kv_html = "".join(
        f"<tr><th>{esc(k)}</th><td>"
        + (f"<span class='hash'>{esc(v)}</span>" if k == SHA_KEY else esc(v)) + "</td></tr>"
        for k, v in c.identity)
    title = c.title
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{esc(title)}</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>{_CSS}</style></head>
<body>
<h1>{esc(title)}</h1>
<p>Unit verdict: {_badge(c.verdict, 'verdict unit-verdict')}</p>
<table class="kv" id="identity">{kv_html}</table>
<h2>Limits</h2>
<table id="limits"><thead><tr><th>limit</th><th>table, row</th><th>quantity</th>
<th>reading</th><th>interval ({c.coverage:.0%})</th><th>limit</th>
<th>margin</th><th>rule</th><th>verdict</th></tr></thead>
<tbody>{''.join(rows_html)}</tbody></table>
<p class="notes">{MARGIN_NOTE} {esc(c.rule)}.</p>
{disagree_html}
<h2>Sessions</h2>
<table id="sessions"><thead><tr><th>session</th><th>procedure</th><th>started</th>
<th>results</th><th>acquired with</th></tr></thead><tbody>{sessions_html}</tbody></table>
<h2>Results (sha256 of the files certified)</h2>
<table id="results"><thead><tr><th>session</th><th>file</th><th>sha256</th></tr></thead>
<tbody>{results_html}</tbody></table>
<h2>Frames (sha256 at acquisition)</h2>
<table id="frames"><thead><tr><th>session</th><th>frame</th><th>sha256</th></tr></thead>
<tbody>{frames_html}</tbody></table>
<div class="sign">{''.join(f"<div>{esc(t)}</div>" for t in SIGNATURES)}</div>
</body></html>
"""


def _rule_text(spec: Mapping[str, Any]) -> str:
    coverage = float(spec.get("coverage", 0.95))
    if spec.get("decision_rule") == "simple":
        return (f"Simple acceptance (shared risk): the reading is compared with the limit; "
                f"the {coverage:.0%} interval is shown")
    return (f"Guarded (ISO 14253-1): pass only when the whole {coverage:.0%} interval is "
            f"within the limits, fail only when it is wholly outside, else indeterminate")
