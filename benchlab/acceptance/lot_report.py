"""The lot report: yield, a table per limited quantity and its control chart, one HTML page."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from benchlab.report.html import esc, svg_plot


def _num(value: Any, fmt: str = ".4g") -> str:
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        return "-"
    return format(value, fmt)


def render_lot_report(result: Mapping[str, Any]) -> str:
    """One self-contained page of :func:`benchlab.acceptance.lot.lot_statistics` output."""
    c = result["verdicts"]
    spec = result["spec"]
    sections = []
    readings = result.get("readings", {})
    for q in result["quantities"]:
        key = f"{q['limit_id']} {q['row']}".strip()
        values = readings.get(key, [])
        drift = q.get("drift")
        hlines = []
        if drift is not None:
            hlines += [(drift["centre"], "#555", "mean"), (drift["ucl"], "#c0392b", "UCL"),
                       (drift["lcl"], "#c0392b", "LCL")]
        hlines += [(q[k], "#1e7b34", k) for k in ("min", "max") if q[k] is not None]
        chart = svg_plot([(list(range(1, len(values) + 1)), values, "#1f4e9c", key)],
                         hlines=hlines, width_px=640, height_px=200,
                         x_label="unit, in measurement order", y_label=q["column"])
        flags = "no drift flagged" if drift is None or not (drift["beyond_limits"]
                                                             or drift["runs"]) else (
            "beyond the control limits: " + (", ".join(drift["beyond_limits"]) or "none")
            + "; runs of 8 on one side: "
            + (", ".join(f"{a} .. {b}" for a, b in drift["runs"]) or "none"))
        if drift is None:
            flags = "fewer than 3 readings: no control chart"
        sections.append(
            f"<h2>{esc(key)} ({esc(q['column'])})</h2>"
            f"<p>n {q['n']} (no value: {q['no_value']}); mean {_num(q['mean'])}, s "
            f"{_num(q['std'])}, 5-95 % {_num(q['p05'])} .. {_num(q['p95'])}; Cpk "
            f"{_num(q['cpk'], '.2f')} (95 % {_num(q['cpk_low'], '.2f')} .. "
            f"{_num(q['cpk_high'], '.2f')}); verdicts: "
            + ", ".join(f"{esc(k)} {v}" for k, v in q["verdicts"].items())
            + f"</p>{chart}<p class='flags'>{esc(flags)}</p>")
    y = result.get("yield")
    yield_text = "-" if y is None else (f"{y:.1%} (95 % interval {result['yield_low']:.1%} .. "
                                        f"{result['yield_high']:.1%}, Clopper-Pearson)")
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Lot {esc(result['lot'])}</title>
<style>body {{ font-family: system-ui, sans-serif; margin: 2em auto; max-width: 60em; }}
h2 {{ font-size: 1.05em; border-bottom: 1px solid #ccc; }}</style></head><body>
<h1>Lot {esc(result['lot'])} against {esc(spec['name'])}
{esc(spec.get('revision') or '')}</h1>
<p id="yield">{result['units']} units: pass {c['pass']}, fail {c['fail']}, indeterminate
{c['indeterminate']}; yield {esc(yield_text)}; rule {esc(spec['decision_rule'])}.</p>
{''.join(sections)}
</body></html>
"""
