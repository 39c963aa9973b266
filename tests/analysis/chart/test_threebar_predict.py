"""The three-bar prediction: a set imaged through a known transfer, read by the chart reading's
estimator, equals that estimator's reading of the same set rendered independently; the optics
recovered from a slanted edge; the bench's edges predicting its bars."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.bars.knownbars import fit_three_bars, three_bar_pattern
from benchlab.analysis.bars.model import edge_response
from benchlab.analysis.bars.projection import across_coordinate
from benchlab.analysis.bars.result import eq29_modulation
from benchlab.analysis.chart.threebar import (
    ReadingSetup,
    eq29_of_image,
    footprint_gain,
    optics_from_edge,
    predict_reading,
)
from benchlab.analysis.sfr.measure import measure_sfr
from benchlab.synthetic.edges import synthetic_edge
from benchlab.synthetic.threebar import (
    BAR_LEVEL,
    GROUND_LEVEL,
    PsfSpec,
    render_three_bars,
)

CONTRAST = (GROUND_LEVEL - BAR_LEVEL) / (GROUND_LEVEL + BAR_LEVEL)


def _gauss(sigma: float):  # type: ignore[no-untyped-def]
    def transfer(f: np.ndarray) -> np.ndarray:
        return np.exp(-2.0 * math.pi**2 * sigma**2 * np.asarray(f) ** 2)

    return transfer


def _closed_form_set(shape: tuple[int, int], centre: tuple[float, float], w: float,
                     theta_deg: float, sigma: float) -> np.ndarray:
    """The set through a Gaussian and the pixel footprint, exactly (the knownbars model:
    :func:`three_bar_pattern` across, the bar ends along), on the synthetic target's levels."""
    t = math.radians(theta_deg)
    u = across_coordinate(shape, t, centre)
    v = across_coordinate(shape, t + 0.5 * math.pi, centre)
    across = three_bar_pattern(u, w, sigma, t)
    along = edge_response(v + 2.5 * w, sigma, t) - edge_response(v - 2.5 * w, sigma, t)
    return GROUND_LEVEL - (GROUND_LEVEL - BAR_LEVEL) * across * along


@pytest.mark.parametrize(("w", "theta", "sigma", "prior"), [
    (1.05, 0.0, 0.08, None),          # G2E4 on the sharp lens: 2.1 px per period, on axis
    (1.17, 0.0, 0.16, (0.14, 0.03)),  # G2E3 on the default lens, with a chart prior
    (1.5, 90.0, 0.3, None),           # tangential
    (1.3, 7.0, 0.25, None),           # oblique
    (2.0, 30.0, 0.5, (0.45, 0.05)),
])
def test_prediction_through_a_known_gaussian_is_the_estimators_reading_of_that_set(
    w: float, theta: float, sigma: float, prior: tuple[float, float] | None,
) -> None:
    shape, centre = (14, 11), (6.73, 5.21)
    roi = _closed_form_set(shape, centre, w, theta, sigma)
    noise = 0.002  # the frame's noise the reading stands for (ROI units)
    reading = fit_three_bars(roi, centre_rc=centre, bar_width_px=w, theta_deg=theta,
                             dark_bars=True, noise_floor=noise)
    if prior is not None:
        reading = reading.with_blur_prior(prior)
    setup = ReadingSetup((100, 200, 100 + shape[0], 200 + shape[1]),
                         (100 + centre[0], 200 + centre[1]), w, theta, True, prior,
                         noise_sigma=noise, ground_level=GROUND_LEVEL)
    pred = predict_reading(setup, _gauss(sigma), _gauss(sigma), contrast=CONTRAST)
    # the image through the tabulated spectrum is the closed form's, and so is its reading
    # (within the estimator's own steps: a refit or a parabola taken or not moves a reading
    # by up to 4e-4 for a change of 1e-6 in the pixels)
    assert np.abs(pred.image - roi).max() < 1e-5
    assert pred.modulation == pytest.approx(reading.result.modulation, abs=5e-4)
    # and its estimator-free Eq. 2.9 contrast is the closed form's
    p = three_bar_pattern(np.array([0.0, -w, w]), w, sigma, math.radians(theta))
    bar = GROUND_LEVEL - (GROUND_LEVEL - BAR_LEVEL) * p[0]
    space = GROUND_LEVEL - (GROUND_LEVEL - BAR_LEVEL) * 0.5 * (p[1] + p[2])
    assert pred.eq29 == pytest.approx(eq29_modulation(bar, space), abs=1e-5)


@pytest.mark.parametrize(("w", "theta", "sigma"), [(1.3, 7.0, 0.25), (1.05, 30.0, 0.2),
                                                   (1.5, 7.0, 0.6)])
def test_prediction_matches_the_estimator_on_an_independently_rendered_set(
    w: float, theta: float, sigma: float,
) -> None:
    # threebar_synthetic: supersampled 12x, the PSF applied in 2-D (not the model's form)
    s = render_three_bars(w, theta, PsfSpec("gauss", sigma), bits=None)
    h, c = s.roi.shape
    reading = fit_three_bars(s.roi, centre_rc=s.centre_rc, bar_width_px=w, theta_deg=theta,
                             dark_bars=True)
    setup = ReadingSetup((0, 0, h, c), s.centre_rc, w, theta, True, None,
                         ground_level=GROUND_LEVEL)
    pred = predict_reading(setup, _gauss(sigma), _gauss(sigma), contrast=CONTRAST)
    assert np.abs(pred.image - s.roi).max() < 5e-4
    assert pred.modulation == pytest.approx(reading.result.modulation, abs=5e-4)
    assert pred.eq29 == pytest.approx(s.truth_modulation, abs=0.01)


def test_negative_target_is_predicted_with_its_polarity() -> None:
    w, sigma = 1.4, 0.3
    setup = ReadingSetup((0, 0, 14, 11), (6.5, 5.2), w, 0.0, False, None)
    pred = predict_reading(setup, _gauss(sigma), _gauss(sigma), contrast=0.6)
    positive = predict_reading(ReadingSetup((0, 0, 14, 11), (6.5, 5.2), w, 0.0, True, None),
                               _gauss(sigma), _gauss(sigma), contrast=0.6)
    assert pred.image.min() == pytest.approx(1.0 - 0.6)  # a dark ground ...
    assert pred.image.max() > 1.2  # ... under bright bars
    assert pred.modulation is not None and 0.3 < pred.modulation < 0.6
    assert pred.eq29 > 0 and positive.eq29 > 0


@pytest.mark.parametrize(("angle", "sigma"), [(5.0, 0.3), (7.0, 0.1), (10.0, 0.6)])
def test_optics_recovered_from_a_slanted_edge(angle: float, sigma: float) -> None:
    res = measure_sfr(synthetic_edge((60, 50), angle, sigma, bits=12))
    optics = optics_from_edge(res)
    f = np.linspace(0.0, 2.0, 201)
    truth = np.exp(-2.0 * math.pi**2 * sigma**2 * f * f)
    # measured (the edge MTF over the footprint) to ~0.8 cycle/px, the fitted Gaussian beyond
    assert 0.75 < optics.measured_to < 0.85
    assert np.abs(optics(f) - truth).max() < 0.01
    assert optics.tail_sigma_px == pytest.approx(sigma, abs=0.005)
    # the footprint the division removed is the edge's own
    assert footprint_gain(np.array([0.5]), math.radians(angle))[0] == pytest.approx(
        np.sinc(0.5 * math.cos(math.radians(angle))) * np.sinc(0.5 * math.sin(
            math.radians(angle))))


def test_a_set_predicted_from_a_measured_edge_reads_as_the_set_itself() -> None:
    # One Gaussian lens: an edge at 5 deg measured, a G2E3-like set (2.34 px per period) on
    # the pixel axis predicted from it, and that set rendered independently and read.
    sigma, w = 0.15, 1.17
    optics = optics_from_edge(measure_sfr(synthetic_edge((60, 50), 5.0, sigma, bits=12)))
    s = render_three_bars(w, 0.0, PsfSpec("gauss", sigma), bits=12)
    reading = fit_three_bars(s.roi, centre_rc=s.centre_rc, bar_width_px=w, theta_deg=0.0,
                             dark_bars=True)
    h, c = s.roi.shape
    top = float((1 << 12) - 1)
    setup = ReadingSetup((0, 0, h, c), s.centre_rc, w, 0.0, True, None,
                         noise_sigma=0.5, ground_level=GROUND_LEVEL * top)
    pred = predict_reading(setup, optics, optics, contrast=CONTRAST)
    assert pred.modulation == pytest.approx(reading.result.modulation, abs=0.005)
    assert pred.eq29 == pytest.approx(eq29_of_image(w, 0.0, _gauss(sigma), ground=0.8,
                                                    bars=0.2), abs=0.003)


def test_reading_setup_round_trips_through_its_dict() -> None:
    setup = ReadingSetup((1, 2, 13, 12), (7.25, 6.5), 1.3, 90.011, True, (0.2, 0.03),
                         noise_sigma=1.2, ground_level=180.5)
    assert ReadingSetup.from_dict(setup.to_dict()) == setup
    bare = ReadingSetup((1, 2, 13, 12), (7.25, 6.5), 1.3, 0.0, None)
    assert ReadingSetup.from_dict(bare.to_dict()) == bare
    with pytest.raises(ValueError, match="contrast"):
        predict_reading(bare, _gauss(0.2), _gauss(0.2), contrast=1.2)
    with pytest.raises(ValueError, match="noise_floor"):
        fit_three_bars(np.ones((9, 9)), centre_rc=(4, 4), bar_width_px=1.3, theta_deg=0.0,
                       noise_floor=-1.0)


def test_bench_check_prints_the_predicted_comparison_and_its_target() -> None:
    from benchlab.benchmarks.sfr.bench import BARS_PREDICTED_TOL, BenchCheck, format_bench_check

    def row(element: str, bar: float, pred: float | None) -> dict[str, object]:
        return {"element": element, "orientation": "sagittal", "image_lp_per_mm": 82.15,
                "bar_modulation": bar, "bar_modulation_predicted": pred, "ctf": 0.97,
                "bar_mtf": 0.765, "bar_mtf_coltman": 0.765, "edge_mtf": 0.709,
                "simulated_mtf": None}

    sharp = BenchCheck(8, 0.5, [], [row("G2E3", 0.792, 0.799), row("G2E4", 0.756, 0.753)], 20.0)
    text = format_bench_check([sharp])
    assert "blur x 0.5" in text and BARS_PREDICTED_TOL == 0.02
    assert ("bars vs the edges' predicted three-bar reading (2 of 2 readings): worst 0.007 "
            "(pass, target 0.02)") in text
    assert "worst 0.056 (FAIL, criterion 0.05)" in text  # Coltman, on the same rows
    unpredicted = BenchCheck(8, 1.0, [], [row("G2E3", 0.792, None)], 20.0)
    text = format_bench_check([unpredicted])
    assert "(0 of 1 readings): worst 0.000 (FAIL" in text and "blur x" not in text
