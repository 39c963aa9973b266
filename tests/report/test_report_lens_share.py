"""The report compares the lens's share of each bar reading (measured / target contrast) with
the simulated lens, says so, and says what Table 4.15's verdicts place; results without a
target contrast are drawn as measured and said to be so."""

from __future__ import annotations

from typing import Any

import matplotlib
import numpy as np
import pytest
from figure_checks import legend_problems

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

import benchlab.report.mtf as report_mtf  # noqa: E402
from benchlab.protocols.mtf.curves import load_curves  # noqa: E402
from benchlab.report.render import _ctf_caption  # noqa: E402

TARGET = 0.8


def _row(f: float, m: float, share: bool) -> dict[str, Any]:
    row: dict[str, Any] = {"element": f"e{f:g}", "image_lp_per_mm": f}
    for o in ("sagittal", "tangential"):
        row.update({f"{o}_modulation": m, f"{o}_uncertainty": 0.01, f"{o}_resolved": True})
        if share:
            row.update({f"{o}_target_contrast": TARGET, f"{o}_lens_share": m / TARGET,
                        f"{o}_lens_share_uncertainty": 0.02})
    return row


def _figures(monkeypatch: pytest.MonkeyPatch, tables: dict[str, Any]) -> list[Figure]:
    seen: list[Figure] = []
    monkeypatch.setattr(report_mtf, "figure_img", lambda fig, alt: seen.append(fig) or "")
    report_mtf.ctf_figure(tables, load_curves(None))
    return seen


def _ys(ax: Any, label: str) -> list[float]:
    """The y values of a panel's artists whose legend label starts with ``label``."""
    out: list[float] = []
    for ln in ax.get_lines():
        if str(ln.get_label()).startswith(label):
            out += [float(v) for v in ln.get_ydata()]
    for c in ax.containers:  # error bars: their data line
        if str(c.get_label()).startswith(label):
            out += [float(v) for v in c.lines[0].get_ydata()]
    return out


def test_the_plot_draws_the_lens_share_and_the_raw_readings_beside_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    tables = {"table_4_11": [_row(50.0, 0.76, True), _row(70.0, 0.6, True)]}
    (fig,) = _figures(monkeypatch, tables)
    ax = fig.axes[0]
    assert sorted(_ys(ax, "lens share")) == pytest.approx([0.6 / TARGET, 0.76 / TARGET])
    assert sorted(_ys(ax, "measured CTF (lens and target)")) == pytest.approx([0.6, 0.76])
    assert ax.get_ylabel() == "lens share of the bar contrast (CTF)"


def test_results_without_a_target_contrast_are_drawn_and_said_as_measured(
        monkeypatch: pytest.MonkeyPatch) -> None:
    (fig,) = _figures(monkeypatch, {"table_4_11": [_row(50.0, 0.76, False)]})
    ax = fig.axes[0]
    assert _ys(ax, "lens share") == []
    assert _ys(ax, "measured CTF, target unknown") == pytest.approx([0.76])
    assert ax.get_ylabel() == "square-wave contrast (CTF)"
    text = _ctf_caption({})
    assert "Compared: <b>the lens's share" in text
    assert "forward: unknown (not recorded" in text and "radial: unknown" in text
    known = _ctf_caption({"forward": {"value": 0.814, "uncertainty": 0.004,
                                      "source": "measured: USAF G0E1"}})
    assert "forward: 0.814 +- 0.004, measured: USAF G0E1" in known


def _t415(share: bool) -> dict[str, Any]:
    row: dict[str, Any] = {
        "view": "forward", "mc_freq_lp_per_mm": 70.0, "measured_freq_lp_per_mm": 70.0,
        "sagittal_freq_lp_per_mm": 70.0, "sagittal_modulation": 0.76,
        "tangential_modulation": 0.68, "averaged_modulation": 0.72, "sagittal_resolved": True,
        "tangential_resolved": True, "p90": 0.46, "p80": 0.49, "p50": 0.53, "p20": 0.61,
        "p10": 0.62, "verdict": "above the 10% threshold (0.62)"}
    if share:
        row.update({"sagittal_lens_share": 0.95, "tangential_lens_share": 0.85,
                    "averaged_lens_share": 0.9, "averaged_lens_share_uncertainty": 0.01,
                    "verdict_basis": "lens share (measured / target contrast)"})
    return row


def test_the_verdict_section_says_what_its_verdicts_place(
        monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[Figure] = []

    def keep(fig: Figure, alt: str) -> str:
        seen.append(fig)
        return ""

    monkeypatch.setattr(report_mtf, "figure_img", keep)
    html = report_mtf.verdict_section([_t415(True)])
    assert "Verdicts use the lens&#x27;s share" in html or "Verdicts use the lens's share" in html
    assert "lens share averaged 0.900 +- 0.010 (S 0.950, T 0.850); measured averaged 0.720" \
        in html
    (bands,) = seen
    assert legend_problems(bands) == []  # the legend under the axes, on no marker
    xs = [float(np.asarray(c.lines[0].get_xdata())[0]) for c in bands.axes[0].containers]
    assert xs == [0.9]  # the averaged share is the verdict's marker
    seen.clear()
    old = report_mtf.verdict_section([_t415(False)])
    assert "Verdicts use the measured contrast" in old and "lens share averaged" not in old
