"""The Run screen's bar-contrast plot draws the lens's share (reading / target contrast) when the
readings come with their target's contrast, and says so; raw readings otherwise."""

from __future__ import annotations

import pytest
from textual.app import App, ComposeResult

from benchlab.tui.drawing.plot import CtfPlot, PlotPoint, lens_shares


class _PlotApp(App[None]):
    def compose(self) -> ComposeResult:
        yield CtfPlot(id="plot")


def _shown(plot: CtfPlot) -> str:
    return str(plot.render())


@pytest.mark.asyncio
async def test_readings_with_a_target_contrast_are_drawn_as_the_lens_share() -> None:
    app = _PlotApp()
    async with app.run_test(size=(60, 12)) as pilot:
        plot = app.query_one("#plot", CtfPlot)
        plot.set_curves({"forward": [([0.0, 100.0], [1.0, 0.0])]}, nyquist=96.0)
        plot.add_point("forward", PlotPoint(20.0, 0.8, "sagittal", False, 0.8))
        plot.add_point("forward", PlotPoint(60.0, 0.4, "tangential", False, 0.8))
        plot.add_point("forward", PlotPoint(40.0, None, "sagittal", False, 0.8))
        await pilot.pause()
        shown, target = lens_shares(plot.points)
        assert target == 0.8
        assert [p.modulation for p in shown] == [pytest.approx(1.0), pytest.approx(0.5), None]
        lines = _shown(plot).splitlines()
        assert lines[0].startswith("forward share M/0.80 ")  # the legend names the basis
        assert "CTF" not in lines[0]
        # the 0.8 reading of a 0.8 target is the lens passing all of it: the top row
        assert "s" in lines[1][4:]
        # the raw reading (0.8) would have been drawn lower
        rows = len(lines) - 2  # legend and axis
        raw_row = int(round((1.0 - 0.8) * (rows * 4 - 1))) // 4
        assert raw_row > 0 and "s" not in lines[1 + raw_row][4:]


@pytest.mark.asyncio
async def test_without_a_target_contrast_the_plot_draws_the_raw_reading_and_says_so() -> None:
    app = _PlotApp()
    async with app.run_test(size=(60, 12)) as pilot:
        plot = app.query_one("#plot", CtfPlot)
        plot.set_curves({"radial": [([0.0, 100.0], [1.0, 0.0])]}, nyquist=96.0)
        plot.add_point("radial", PlotPoint(20.0, 0.8, "sagittal", False, 0.8))
        plot.add_point("radial", PlotPoint(30.0, 0.6, "tangential", False, None))
        await pilot.pause()
        shown, target = lens_shares(plot.points)
        assert target is None  # one reading without a target: no mixing of bases
        assert [p.modulation for p in shown] == [0.8, 0.6]
        legend = _shown(plot).splitlines()[0]
        assert legend.startswith("radial s t CTF") and "share" not in legend
