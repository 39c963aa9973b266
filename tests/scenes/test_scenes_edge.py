"""The forward view's slanted-edge target: exact where it is measured, truth = analytic MTF,
composed with the USAF chart without touching the bar ROIs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.chart import layout as chart
from benchlab.analysis.sfr.measure import measure_sfr
from benchlab.analysis.sfr.target import DEFAULT_SQUARES, edge_specs
from benchlab.drivers.sensor import AcquisitionState
from benchlab.scenes.edge import EdgeScene
from benchlab.scenes.usaf import UsafScene
from benchlab.scenes.world import SimWorld, parse_target
from benchlab.synthetic.edges import pixel_integrated_step

H, W = 1024, 1280
F_NYQ = np.linspace(0.0, 0.5, 51)


def _state(bench: dict[str, object] | None = None) -> AcquisitionState:
    return AcquisitionState(300.0, 1.0, 12, W, H, 0.0, 0, bench or {})


def test_every_noise_free_edge_measures_its_analytic_mtf() -> None:
    scene = EdgeScene()
    img = scene.render(H, W)
    specs = scene.edges()
    assert len(specs) == 4 * len(DEFAULT_SQUARES)
    for spec in specs:
        r0, c0, r1, c1 = spec.roi
        res = measure_sfr(img[r0:r1, c0:c1])
        err = np.abs(res.mtf_at(F_NYQ) - scene.truth_mtf(spec, F_NYQ))
        assert err.max() < 0.004, spec.label
        assert res.direction == ("horizontal" if spec.orientation == "sagittal" else "vertical")
        assert res.edge_angle_deg == pytest.approx(spec.square.rotation_deg, abs=0.05)


def test_render_along_a_side_is_the_exact_pixel_integrated_edge() -> None:
    scene = EdgeScene()
    img = scene.render(H, W)
    spec = next(e for e in scene.edges() if e.label == "E1R")
    sq = spec.square
    n = (math.cos(spec.normal_theta_rad), math.sin(spec.normal_theta_rad))
    sigma = scene.side_sigma_px(sq, spec.normal_theta_rad)
    r0, c0 = round(spec.midpoint_rc[0]), round(spec.midpoint_rc[1])
    checked = 0
    for r in range(r0 - 8, r0 + 9):
        for c in range(c0 - 3, c0 + 4):
            d = (c - sq.centre_rc[1]) * n[0] + (r - sq.centre_rc[0]) * n[1] - sq.side_px / 2
            inside = pixel_integrated_step(-d, sigma, n[0], n[1])  # 1 inside the square
            want = scene.bright_rate - (scene.bright_rate - scene.dark_rate) * inside
            assert img[r, c] == pytest.approx(want, rel=1e-9)
            checked += 0.05 < inside < 0.95
    assert checked >= 10  # transition pixels, not only the plateaus


def test_edges_keep_clear_of_the_chart_and_inside_the_disc() -> None:
    layout = chart.ChartLayout()
    bars = [chart.usaf_bar_group(layout, g, e, o) for g, e in layout.elements
            for o in chart.ORIENTATIONS]
    top = min(b.extent[0] for b in bars)
    for spec in edge_specs():
        r0, c0, r1, c1 = spec.roi
        assert r1 < top - 30  # the chart and its finder's search window lie below
        for rr, cc in ((r0, c0), (r0, c1), (r1, c0), (r1, c1)):
            radius = math.hypot(rr - chart.IMAGE_CENTRE_RC[0], cc - chart.IMAGE_CENTRE_RC[1])
            assert radius < chart.FORWARD_DISC_RADIUS_PX - 10


def test_usaf_frame_has_the_edges_and_unchanged_bars() -> None:
    world = SimWorld("usaf")
    composed = world(_state())
    chart_only = UsafScene().render(H, W)
    layout = chart.ChartLayout()
    for g, e in layout.elements:
        for o in chart.ORIENTATIONS:
            r0, c0, r1, c1 = chart.usaf_bar_group(layout, g, e, o).box
            pad = 30
            sl = (slice(r0 - pad, r1 + pad), slice(c0 - pad, c1 + pad))
            assert np.array_equal(composed[sl], chart_only[sl])
    r0, c0, r1, c1 = edge_specs()[0].roi
    assert composed[r0:r1, c0:c1].min() < 0.2 * composed[r0:r1, c0:c1].max()  # an edge there
    alone = world(_state({"target": "edge"}))
    assert np.array_equal(alone[r0:r1, c0:c1], composed[r0:r1, c0:c1])


def test_edge_target_is_a_world_target_and_follows_defocus() -> None:
    assert parse_target("edge") == ("edge",)
    world = SimWorld("edge")
    assert isinstance(world.scene_for("edge"), EdgeScene)
    sharp = world(_state())
    blurred = world(_state({"defocus_px": 1.5}))
    spec = edge_specs()[0]
    r0, c0, r1, c1 = spec.roi
    res = measure_sfr(blurred[r0:r1, c0:c1])
    truth = EdgeScene(defocus_px=1.5).truth_mtf(spec, F_NYQ)
    assert np.abs(res.mtf_at(F_NYQ) - truth).max() < 0.004
    assert res.mtf_nyquist < measure_sfr(sharp[r0:r1, c0:c1]).mtf_nyquist - 0.2


def test_chart_over_a_square_multiplies_transmissions_not_subtracts() -> None:
    # A moved chart (usaf:dx=110,dy=-90) lays bars across square E0: where chrome overlaps
    # chrome the light passes both (chart x square / bright), not the dark subtracted twice
    # and clamped at 0 (297 pixels read 0 there: fake clipping).
    from benchlab.scenes.usaf import usaf_scene_from_spec

    world = SimWorld("usaf", usaf=usaf_scene_from_spec("usaf:dx=110,dy=-90"))
    composed = world(_state())
    chart_only = world.usaf.render(H, W)
    alone = EdgeScene().render(H, W)
    bright, dark = EdgeScene().bright_rate, EdgeScene().dark_rate
    sl = (slice(440, 600), slice(600, 800))  # around square E0
    both_dark = (chart_only[sl] < 0.3 * bright) & (alone[sl] < 0.3 * bright)
    assert both_dark.sum() > 50  # the bars do cross the square
    np.testing.assert_allclose(composed[sl], chart_only[sl] * alone[sl] / bright, rtol=1e-12)
    assert composed[sl].min() >= dark * dark / bright * (1 - 1e-9)
