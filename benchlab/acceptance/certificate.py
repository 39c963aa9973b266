"""The unit's certificate: one self-contained HTML page rendered from a stored verdict record.

Rendered from ``verdicts/v<N>.json`` (never from a second verification), so what is filed is
what was decided: unit and lot, spec name, revision and the sha256 of its file, decision rule
and coverage, every limit's row (reading, interval, limit, margin, verdict and why), the
sessions with their results version and every frame's sha256, and the software version.
Nothing is fetched from outside the page; the print style sheet fits A4 portrait, so the
browser's Print -> PDF gives the paper copy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from benchlab.report.html import esc, local_time

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
    lo, hi = row.get("min"), row.get("max")
    text = (f"{lo:g} .. {hi:g}" if lo is not None and hi is not None
            else f"&ge; {lo:g}" if lo is not None else f"&le; {hi:g}")
    return f"{text} {esc(str(row.get('unit') or ''))}".strip()


def _badge(verdict: str, css: str = "verdict") -> str:
    colour = VERDICT_COLOURS.get(verdict, "#444")
    return f"<span class='{css}' style='color:{colour};border-color:{colour}'>" \
           f"{esc(verdict)}</span>"


def render_certificate(record: Mapping[str, Any], session_id: str = "") -> str:
    """The certificate page of one stored verdict record."""
    unit, spec = record["unit"], record["spec"]
    serial = unit.get("serial") or "(no serial number)"
    title = f"Acceptance certificate - {serial}"
    kv = [("Unit (serial number)", serial), ("Lot", unit.get("lot") or "-"),
          ("Specification", spec["name"]), ("Revision", spec.get("revision") or "-"),
          ("Spec file", spec.get("file", "")),
          ("Spec file sha256", f"<span class='hash'>{esc(spec.get('sha256', ''))}</span>"),
          ("Spec format", f"{esc(spec.get('format', ''))} v{spec.get('format_version', '')}"),
          ("Decision rule", _rule_text(spec)),
          ("Verdict record", f"{esc(session_id)} verdicts/v{record.get('version', '?')}.json"),
          ("Decided", esc(local_time(record.get("created_at")))),
          ("Software", f"benchlab {esc(record.get('software_version', ''))}")]
    rows_html = []
    for r in record["rows"]:
        why = "; ".join(r.get("notes") or [])
        if str(r.get("decided_by", "")).startswith("reading") and "reading decides" not in why:
            why = ("the reading decided (shared risk)" + ("; " + why if why else ""))
        interval = ("none" if r.get("low") is None or r.get("high") is None
                    else f"{_num(r.get('low'))} &ndash; {_num(r.get('high'))}")
        rows_html.append(
            "<tr>" + "".join([
                f"<td>{esc(r['limit_id'])}</td>",
                f"<td>{esc(r.get('table', ''))}<br><small>{esc(r.get('row') or '')}</small>"
                "</td>", f"<td>{esc(r['column'])}</td>",
                f"<td class='num'>{_num(r.get('reading'))}</td>",
                f"<td class='num'>{interval}</td>",
                f"<td class='num'>{_limit(r)}</td>",
                f"<td class='num'>{_num(r.get('margin'))}</td>",
                f"<td>{esc(r.get('rule', ''))}</td>", f"<td>{_badge(r['verdict'])}</td>"])
            + "</tr>")
        if why:
            rows_html.append(f"<tr class='note'><td></td><td colspan='8' class='notes'>"
                             f"{esc(why)}</td></tr>")
    sessions_html, frames_html = [], []
    for s in record.get("sessions", []):
        sessions_html.append(
            f"<tr><td>{esc(s['id'])}</td><td>{esc(s.get('procedure', ''))}</td>"
            f"<td>{esc(local_time(s.get('started_at')))}</td>"
            f"<td>v{esc(str(s.get('results_version')))}"
            f"{' (partial)' if s.get('partial') else ''}</td>"
            f"<td>{esc(s.get('software_version', ''))}</td></tr>")
        for name, digest in sorted((s.get("frames_sha256") or {}).items()):
            frames_html.append(f"<tr><td>{esc(s['id'])}</td><td>{esc(name)}</td>"
                               f"<td class='hash'>{esc(str(digest))}</td></tr>")
    kv_html = "".join(f"<tr><th>{esc(k)}</th><td>{v if k in _HTML_VALUES else esc(str(v))}"
                      f"</td></tr>" for k, v in kv)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{esc(title)}</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>{_CSS}</style></head>
<body>
<h1>{esc(title)}</h1>
<p>Unit verdict: {_badge(record['verdict'], 'verdict unit-verdict')}</p>
<table class="kv" id="identity">{kv_html}</table>
<h2>Limits</h2>
<table id="limits"><thead><tr><th>limit</th><th>table, row</th><th>quantity</th>
<th>reading</th><th>interval ({spec.get('coverage', 0.95):.0%})</th><th>limit</th>
<th>margin</th><th>rule</th><th>verdict</th></tr></thead>
<tbody>{''.join(rows_html)}</tbody></table>
<p class="notes">Margin: how far the reading lies inside the limit (negative: outside), in the
quantity's unit. {_rule_text(spec)}.</p>
<h2>Sessions</h2>
<table id="sessions"><thead><tr><th>session</th><th>procedure</th><th>started</th>
<th>results</th><th>acquired with</th></tr></thead><tbody>{''.join(sessions_html)}</tbody></table>
<h2>Frames (sha256 at acquisition)</h2>
<table id="frames"><thead><tr><th>session</th><th>frame</th><th>sha256</th></tr></thead>
<tbody>{''.join(frames_html)}</tbody></table>
<div class="sign"><div>Inspected by, date</div><div>Approved by, date</div></div>
</body></html>
"""


_HTML_VALUES = {"Spec file sha256", "Spec format", "Decision rule", "Verdict record", "Decided",
                "Software"}


def _rule_text(spec: Mapping[str, Any]) -> str:
    coverage = float(spec.get("coverage", 0.95))
    if spec.get("decision_rule") == "simple":
        return (f"Simple acceptance (shared risk): the reading is compared with the limit; "
                f"the {coverage:.0%} interval is shown")
    return (f"Guarded (ISO 14253-1): pass only when the whole {coverage:.0%} interval is "
            f"within the limits, fail only when it is wholly outside, else indeterminate")
