"""Live view chart overlay: c finds the chart and draws its elements; ] and a click pick one."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_tui_helpers import make_app, open_live, wait_until

from benchlab.analysis.chart.finder import find_chart
from benchlab.scenes.usaf import UsafScene
from benchlab.tui.drawing.chart_overlay import ChartFrameView, pick_element, roi_of


@pytest.mark.slow
@pytest.mark.asyncio
async def test_chart_overlay_and_picking(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        live = await open_live(pilot, 2)
        await pilot.press("c")
        await wait_until(pilot, lambda: live.chart_fit is not None, what="chart found")
        fit = live.chart_fit
        view = live.query_one(ChartFrameView)
        await wait_until(pilot, lambda: len(view._boxes) == len(fit.found) >= 30,
                         what="overlay drawn")
        await pilot.press("right_square_bracket")
        first = fit.found[0]
        assert live.roi == roi_of(first) and live.orientation == first.posed.orientation
        # a click on another element picks it: find the cell over G1E1T's centre
        target = next(e for e in fit.found if e.label == "G1E1T")
        cell = next((x, y) for y in range(view.size.height) for x in range(view.size.width)
                    if (p := view.cell_to_frame(x, y)) is not None
                    and pick_element(fit, p) is target)
        await pilot.click(ChartFrameView, offset=cell)
        assert live.roi == roi_of(target) and live.orientation == "tangential"
        await pilot.press("c")
        assert live.chart_fit is None and view._boxes == []


def test_pick_element_takes_the_set_under_the_point() -> None:
    scene = UsafScene()
    fit = find_chart(scene.render(1024, 1280))
    g0 = fit.element(0, 1, "sagittal")
    assert pick_element(fit, g0.posed.centre_rc) is g0
    assert pick_element(fit, (5.0, 5.0)) is None  # far from every set


def test_graphics_view_draws_the_overlay_too() -> None:
    import numpy as np

    from benchlab.tui.drawing.chart_overlay import FOUND_RGB, ChartGraphicsFrameView, set_overlay

    view = ChartGraphicsFrameView("kitty")
    preview = np.full((256, 320), 100, np.uint8)  # a 1024 x 1280 frame shown at 1/4
    set_overlay(view, [(400, 500, 440, 560)], (1024, 1280))
    view.show(preview, None, 255.0)
    assert view.last_rgb is not None
    assert tuple(view.last_rgb[100, 130]) == FOUND_RGB  # top edge at row 400 / 4
    assert tuple(view.last_rgb[105, 130]) == (100, 100, 100)  # inside: untouched
