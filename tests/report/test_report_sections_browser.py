"""Every procedure's report section in a real headless browser (Debian's Chromium), checked as
the MTF section is: the page loads with no console errors; every plot has a caption just above
it saying what is compared with what; and every figure, read from its own artists (not
pixels), has its legends on no data point of any panel and its axes labelled with units."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import matplotlib
import pytest
from figure_checks import label_problems, legend_problems
from headless_browser import chromium, console_errors, needs_chromium
from sim_runs import FIXTURES, MTF_SMALL, RAD_SMALL, run_sim

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

import benchlab.report.characterise as characterise_report  # noqa: E402
import benchlab.report.depth as depth_report  # noqa: E402
import benchlab.report.fov as fov_report  # noqa: E402
import benchlab.report.html as report_html  # noqa: E402
import benchlab.report.mtf as mtf_report  # noqa: E402
import benchlab.report.render as render  # noqa: E402
import benchlab.report.sfr as sfr_report  # noqa: E402

#: (procedure, parameters, the section titles whose plots are checked, plots expected).
RUNS = [
    ("radiometry", RAD_SMALL, ("Radiometric fall-off",), 1),
    ("characterise", FIXTURES / "characterise-small.toml", ("Camera characterisation",), 3),
    ("depth", FIXTURES / "depth-small.toml", ("Through focus",), 4),
    ("mtf", MTF_SMALL, ("Slanted-edge MTF", "Measured vs simulated", "Table 4.15 verdict"), 3),
]


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[tuple[str, list[str]]]]:
    """Every figure the report draws: its alt text and what the checks found, read from the
    figure before it is written (and closed)."""
    seen: list[tuple[str, list[str]]] = []
    original = report_html.figure_img

    def keep(fig: Figure, alt: str) -> str:
        seen.append((alt, legend_problems(fig) + label_problems(fig)))
        return str(original(fig, alt))

    for module in (render, depth_report, sfr_report, characterise_report, mtf_report,
                   fov_report):
        monkeypatch.setattr(module, "figure_img", keep)
    yield seen


def _captions_before_plots(html: str) -> list[tuple[str, str]]:
    """(plot alt, the caption between the previous plot and it) for every plot of a page."""
    out = []
    start = 0
    for m in re.finditer(r"<img class=\"plot\" alt=\"([^\"]*)\"", html):
        captions = re.findall(r"<p class=\"note caption\">(.*?)</p>", html[start:m.start()],
                              re.S)
        out.append((m.group(1), captions[-1] if captions else ""))
        start = m.end()
    return out


def _words(caption: str) -> str:
    return re.sub(r"<[^>]+>", "", caption)


@needs_chromium
@pytest.mark.slow
@pytest.mark.parametrize(("procedure", "params", "titles", "plots"), RUNS,
                         ids=[r[0] for r in RUNS])
def test_each_sections_plots_are_captioned_labelled_and_legends_clear_of_data(
        procedure: str, params: Path, titles: tuple[str, ...], plots: int, tmp_path: Path,
        figures: list[tuple[str, list[str]]]) -> None:
    outcome = run_sim(procedure, tmp_path, params)
    page = render.write_report(outcome.session_path)
    assert len(figures) >= plots
    for alt, problems in figures:
        assert problems == [], alt
    dom = chromium(tmp_path, "--dump-dom", page.as_uri())
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert console_errors(dom.stderr) == []
    html = dom.stdout
    for title in titles:
        assert title in html
    captioned = _captions_before_plots(html)
    assert len(captioned) == len(figures)
    for alt, caption in captioned:
        words = _words(caption)
        assert words.startswith("Compared: "), alt
        assert " with " in words, (alt, words)  # X with Y: what is compared with what
    shot = tmp_path / "report.png"
    res = chromium(tmp_path, "--window-size=1200,2400", f"--screenshot={shot}", page.as_uri())
    assert res.returncode == 0 and shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _points_figure(legend_at: str) -> Any:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot([0.1, 0.5, 0.9], [0.9, 0.5, 0.9], "o", label="points")
    ax.plot([0.0, 1.0], [0.1, 0.1], "-", label="curve")
    ax.set_xlabel("frequency (lp/mm)")
    ax.set_ylabel("contrast (0-1)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    if legend_at == "below":
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.25))
    else:
        ax.legend(loc=legend_at)
    fig.subplots_adjust(bottom=0.4)
    return fig


@pytest.mark.parametrize(("where", "ok"), [("upper left", False), ("lower center", False),
                                           ("below", True), ("center left", True)])
def test_the_legend_check_sees_a_legend_on_points_or_on_a_curve(where: str, ok: bool) -> None:
    """The check that guards the report: a legend on a point (upper left) or across a curve
    (lower center) is found; one under the axes, or in an empty part of it, is not."""
    fig = _points_figure(where)
    assert (legend_problems(fig) == []) is ok
    fig.axes[0].set_ylabel("contrast")
    assert label_problems(fig) == ["panel '': y axis 'contrast' names no unit"]
