"""The forward view's geometry from rendered dot-grid frames with known truth: dots, disc, fit
and figures within the issue's targets, intervals that cover, and the refusals."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from benchlab.analysis.fov import figures as fig
from benchlab.analysis.fov.disc import Disc, DiscNotFoundError, find_disc
from benchlab.analysis.fov.dots import DotsError, detect, identify
from benchlab.analysis.fov.fit import Fit, FitError, fit_views, fit_with_clean_disc
from benchlab.analysis.fov.model import PIXEL_MM
from benchlab.drivers.sensor import rate_for_dn8
from benchlab.scenes.dots import DotChart, DotGridScene, FovLens

DISTANCES = (15.0, 25.0, 35.0)


def _frames(scene: DotGridScene, seed: int, distances: tuple[float, ...] = DISTANCES
            ) -> dict[float, npt.NDArray[np.float64]]:
    """8-bit frames with shot-like and read noise, clipped like the camera."""
    rng = np.random.default_rng(seed)
    per_dn = float(rate_for_dn8(1.0, 300.0))
    out = {}
    for d in distances:
        dn = scene.render(d, 1024, 1280) / per_dn
        out[d] = np.clip(rng.normal(dn, np.sqrt(0.05 * dn + 1.0)), 0.0, 255.0)
    return out


LENSES = {
    "equidistant": FovLens(),  # Table 4.14's field points
    "rectilinear-tilted-pupil": FovLens(barrel=0.0, tilt_deg=2.0, tilt_azimuth_deg=-60.0,
                                        entrance_pupil_mm=4.5),
}


@pytest.fixture(scope="module")
def analysed() -> dict[str, tuple[DotGridScene, Fit, Disc]]:
    """Each lens's frames analysed once (the render and the search take ~2 s a lens)."""
    out = {}
    for name, lens in LENSES.items():
        scene = DotGridScene(lens=lens)
        frames = _frames(scene, seed=3)
        disc = find_disc(np.max(np.stack(list(frames.values())), axis=0))
        views = [(d, identify(*detect(img, disc, 12.0))) for d, img in frames.items()]
        chart = scene.chart
        disc, fit, note = fit_with_clean_disc(frames, views, disc, chart.pitch_mm,
                                              chart.dot_mm, chart.half_count)
        assert note == ""  # the edge read clear of the dots
        out[name] = (scene, fit, disc)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", list(LENSES))
def test_figures_within_the_targets_and_covered(
        analysed: dict[str, tuple[DotGridScene, Fit, Disc]], name: str) -> None:
    scene, fit, disc = analysed[name]
    lens = scene.lens
    fov, (dov, _), pupil = fig.field_of_view(fit, disc), fig.direction_of_view(fit), \
        fig.entrance_pupil(fit)
    true_fov = 2.0 * math.degrees(scene.edge_angle_rad())
    assert abs(fov.value - true_fov) < 0.05  # target 0.5 deg
    assert fov.low <= true_fov <= fov.high
    assert abs(dov.value - lens.tilt_deg) < 0.01  # target 0.3 deg
    assert dov.low <= lens.tilt_deg <= dov.high
    assert abs(pupil.value - lens.entrance_pupil_mm) < 0.01  # target 0.3 mm
    h = lens.height_mm()
    for a in (5.0, 12.0, 16.0, 25.0):
        true = float(h(np.array([math.radians(a)]))[0])
        assert abs(fig.image_height(fit, a).value - true) < 0.001, a  # target 0.01 mm


@pytest.mark.slow
def test_the_disc_is_found_without_its_dots(
        analysed: dict[str, tuple[DotGridScene, Fit, Disc]]) -> None:
    scene, _, disc = analysed["equidistant"]
    cr, cc = scene.circles.centre_rc
    assert disc.centre_col == pytest.approx(cc, abs=0.01)
    assert disc.centre_row == pytest.approx(cr, abs=0.01)
    assert disc.radius_px == pytest.approx(scene.circles.disc_radius_px, abs=0.01)
    sig = disc.sigma  # the edge read clear of the dots: no bias, the interval covers
    assert abs(disc.radius_px - scene.circles.disc_radius_px) <= 3.0 * sig[2]


@pytest.mark.slow
def test_distortion_against_both_models_matches_the_lens(
        analysed: dict[str, tuple[DotGridScene, Fit, Disc]]) -> None:
    _, fit, _ = analysed["rectilinear-tilted-pupil"]  # h = f tan(theta)
    t = math.radians(20.0)
    rect = fig.local_distortion(fit, 20.0, "rectilinear")
    equi = fig.local_distortion(fit, 20.0, "equidistant")
    assert rect.value == pytest.approx(0.0, abs=0.01)
    assert equi.value == pytest.approx(100 * (math.tan(t) - t) / t, abs=0.01)  # +4.2 %
    assert PIXEL_MM == pytest.approx(0.0052)


def test_dots_are_identified_with_their_grid_index() -> None:
    scene = DotGridScene(lens=FovLens(barrel=2.0))
    img = _frames(scene, seed=2, distances=(25.0,))[25.0]
    disc = find_disc(img)
    xy, areas = detect(img, disc, 12.0)
    dots = identify(xy, areas)
    ij, true = scene.dot_centres(25.0)
    lut = {(int(i), int(j)): p for (i, j), p in zip(ij, true, strict=True)}
    assert len(dots.ij) > 400
    err = np.array([dots.xy[k] - lut[(int(i), int(j))] for k, (i, j) in enumerate(dots.ij)])
    assert float(np.abs(err).max()) < 0.15  # px: every dot named right, centroid unbiased


def test_a_chart_without_its_fiducial_is_refused() -> None:
    scene = DotGridScene(chart=DotChart(fiducial_scale=1.0))
    img = _frames(scene, seed=0, distances=(25.0,))[25.0]
    disc = find_disc(img)
    with pytest.raises(DotsError, match="no fiducial"):
        identify(*detect(img, disc, 12.0))


def test_one_distance_or_too_few_dots_is_refused() -> None:
    scene = DotGridScene()
    img = _frames(scene, seed=0, distances=(25.0,))[25.0]
    disc = find_disc(img)
    dots = identify(*detect(img, disc, 12.0))
    with pytest.raises(FitError, match="two distances"):
        fit_views([(25.0, dots)], disc, 1.0)
    with pytest.raises(FitError, match="dots identified at 25 mm"):
        fit_views([(25.0, dots), (35.0, dots)], disc, 1.0, min_dots=10000)


def test_a_dark_frame_has_no_disc() -> None:
    with pytest.raises(DiscNotFoundError):
        find_disc(np.random.default_rng(0).normal(3.0, 1.0, (1024, 1280)))


def test_rounding_keeps_a_narrow_interval_covering_what_it_covered() -> None:
    # a radial image height: its interval 3.2 nm wide, the table's 6 decimals are 1 nm
    f = fig.Figure(2.8324962, 2.8324946, 2.8324978)
    value, (low, high) = f.rounded(6)
    assert low <= 2.8324948 <= high  # inside the computed interval, so inside the stored one
    assert (value, low, high) == (2.8324962, 2.8324946, 2.8324978)  # 7 decimals: 0.1 nm
    # a wide interval keeps the digits asked for
    assert fig.Figure(52.61234, 52.5, 52.7).rounded(4) == (52.6123, [52.5, 52.7])
