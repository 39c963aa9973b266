"""Radial view: rolled bar patterns in the annulus."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from benchlab.analysis.chart.layout import RADIAL_ROI_BOX, RadialLayout, box_centroid
from benchlab.analysis.views.synthesis import cylinder_map
from benchlab.drivers.sensor import AcquisitionState
from benchlab.scenes.radial import RADIAL_TARGETS_LP_PER_MM, RadialScene, radial_truth_table

H, W = 1024, 1280
CIRCLES = RadialLayout()
CR, CC = CIRCLES.centre_rc
REF = box_centroid(RADIAL_ROI_BOX)
R_REF = CIRCLES.radius_px(REF)
THETA_REF = math.atan2(REF[0] - CR, REF[1] - CC)


def _peak_period(signal: np.ndarray, step_px: float) -> float:
    """Period (px) of the strongest non-DC FFT bin, refined by parabolic interpolation."""
    sig = (signal - signal.mean()) * np.hanning(signal.size)
    n = 16 * signal.size
    spec = np.abs(np.fft.rfft(sig, n))
    k = int(np.argmax(spec[1:])) + 1
    a, b, c = np.log(spec[k - 1 : k + 2])
    k_fine = k + 0.5 * (a - c) / (a - 2 * b + c)
    return n * step_px / k_fine


@pytest.mark.parametrize("lp", [1.0, 3.0])
def test_sagittal_spokes_have_the_period_along_the_arc(lp: float) -> None:
    scene = RadialScene(lp, "sagittal")
    img = scene.render(H, W)
    step = 0.25
    arc = np.arange(-150, 150, step)  # px of arc length through the ROI centroid
    theta = THETA_REF + arc / R_REF
    rows, cols = CR + R_REF * np.sin(theta), CC + R_REF * np.cos(theta)
    signal = map_coordinates(img, [rows, cols], order=3)
    assert _peak_period(signal, step) == pytest.approx(scene.px_per_period, rel=0.01)
    # spokes: no variation along the radius through the ROI
    radial = np.arange(R_REF - 15, R_REF + 15, 1.0)
    along = map_coordinates(
        img, [CR + radial * math.sin(THETA_REF), CC + radial * math.cos(THETA_REF)], order=1
    )
    assert np.ptp(along) < 0.1 * np.ptp(signal)


@pytest.mark.parametrize("lp", [1.0, 2.0])
def test_tangential_rings_have_the_period_of_the_ray_trace_table(lp: float) -> None:
    """Rings follow the table's axial magnification: Eq. 4.1's 17.5 at the reference point,
    a different local period nearer the inner edge (the modelled table is not linear)."""
    scene = RadialScene(lp, "tangential")
    img = scene.render(H, W)
    step = 0.25
    cyl = cylinder_map(scene.ray_table, scene.object_radius_mm)
    for centre_px in (R_REF, 370.0):
        radial = np.arange(centre_px - 45, centre_px + 45, step)
        rows = CR + radial * math.sin(THETA_REF)
        cols = CC + radial * math.cos(THETA_REF)
        signal = map_coordinates(img, [rows, cols], order=3)
        local_mag = cyl.axial_magnification(centre_px * 5.2e-3)
        expected = 1.0 / (lp * local_mag * 5.2e-3)
        assert _peak_period(signal, step) == pytest.approx(expected, rel=0.01)
    assert scene.px_per_period == pytest.approx(1.0 / (lp * 17.5 * 5.2e-3), rel=1e-4)
    assert scene.image_lp_per_mm == pytest.approx(17.5 * lp, rel=1e-4)
    assert cyl.axial_magnification(370 * 5.2e-3) < 17.0  # the table's own, not a constant


def test_sagittal_period_is_the_geometric_one_not_eq_4_1() -> None:
    """Around the circle the magnification is object radius / image radius (rotational
    symmetry), 19.88 mm / 2.48 mm = 8.0 at the radial ROI, not Eq. 4.1's 17.5."""
    scene = RadialScene(0.5, "sagittal")
    assert scene.magnification == pytest.approx(19.88 / (R_REF * 5.2e-3), rel=1e-9)
    assert scene.px_per_period == pytest.approx(2.0 * R_REF / 19.88, rel=1e-9)


@pytest.mark.parametrize(
    "lp,orientation",
    [(2.0, "sagittal"), (4.0, "sagittal"), (0.5, "tangential"), (1.0, "tangential")],
)
def test_truth_modulation_matches_the_noise_free_roi(lp: float, orientation: str) -> None:
    """The ROI's pixels sample every phase of the pattern, so their extremes near the reference
    radius are the truth's dark and bright levels."""
    scene = RadialScene(lp, orientation)  # type: ignore[arg-type]
    img = scene.render(H, W)
    r0, c0, r1, c1 = RADIAL_ROI_BOX
    rr, cc = np.mgrid[r0:r1, c0:c1]
    # sagittal: a thin arc through the centroid; tangential: the bar there and the spaces beside
    half_width = 1.5 if orientation == "sagittal" else 0.6 * scene.px_per_period + 1
    band = np.abs(np.hypot(rr - CR, cc - CC) - R_REF) < half_width
    values = img[r0:r1, c0:c1][band]
    dark, bright = scene.truth_levels()
    assert values.min() == pytest.approx(dark, rel=0.02)
    assert values.max() == pytest.approx(bright, rel=0.01)
    measured = (values.max() - values.min()) / (values.max() + values.min())
    assert scene.truth_modulation() == pytest.approx(measured, abs=0.01)


def test_tangential_is_blurrier_than_sagittal_like_table_4_12() -> None:
    for lp in RADIAL_TARGETS_LP_PER_MM[1:]:
        s = RadialScene(lp, "sagittal").truth_modulation()
        t = RadialScene(lp, "tangential").truth_modulation()
        assert t < s
    # thesis: tangential unresolved from 3 lp/mm; sagittal still ~0.5-0.6 at 4-5 lp/mm
    assert RadialScene(3.0, "tangential").truth_modulation() < 0.05
    assert RadialScene(4.0, "sagittal").truth_modulation() > 0.5
    # and in the rendered pixels: the ROI's spread at 2 lp/mm
    r0, c0, r1, c1 = RADIAL_ROI_BOX
    spread = {
        o: np.ptp(RadialScene(2.0, o).render(H, W)[r0:r1, c0:c1])  # type: ignore[arg-type]
        for o in ("sagittal", "tangential")
    }
    assert spread["tangential"] < 0.5 * spread["sagittal"]


def test_annulus_only_and_clipped_by_the_frame() -> None:
    scene = RadialScene(1.0, "sagittal")
    img = scene.render(H, W)
    rr, cc = np.mgrid[0:H, 0:W]
    radius = np.hypot(rr - CR, cc - CC)
    assert np.all(img[radius < CIRCLES.annulus_inner_radius_px - 10] < 1e-9)
    assert np.all(img[radius > CIRCLES.annulus_outer_radius_px + 10] < 1e-9)
    ring = (radius > CIRCLES.annulus_inner_radius_px + 10) & (
        radius < CIRCLES.annulus_outer_radius_px - 10
    )
    assert img[ring].min() >= scene.dark_rate * 0.999
    assert img[H - 1].max() > scene.dark_rate  # the annulus runs off the bottom edge
    for box in (RADIAL_ROI_BOX, (249, 999, 290, 1050)):
        assert CIRCLES.box_in_annulus(box)


def test_call_returns_a_copy_and_invalid_patterns_are_refused() -> None:
    scene = RadialScene(5.0, "tangential")
    state = AcquisitionState(300.0, 1.0, 8, W, H, 0.0, 0, {})
    a = scene(state)
    a[:] = 0
    assert scene(state).max() > 0
    with pytest.raises(ValueError, match="orientation"):
        RadialScene(1.0, "diagonal")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="frequency"):
        RadialScene(0.0, "sagittal")


def test_truth_table_lists_every_pattern() -> None:
    rows = radial_truth_table()
    assert len(rows) == 14
    for row in rows:
        scene = RadialScene(row["object_lp_per_mm"], row["orientation"])  # type: ignore[arg-type]
        assert row["modulation"] == pytest.approx(scene.truth_modulation())
        assert row["px_per_period"] == pytest.approx(scene.px_per_period)
