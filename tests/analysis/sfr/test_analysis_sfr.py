"""Slanted-edge SFR: accuracy against the closed-form edge, the refusals and warnings, the
extremes (0 deg, 45 deg, clipped, 20 rows, noise only) and the uncertainty."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.special import ndtr

from benchlab.analysis.sfr.measure import SfrRefused, _rise_10_90, full_scale_of, measure_sfr
from benchlab.synthetic.edges import (
    edge_truth_mtf,
    edge_truth_mtf50,
    pixel_integrated_step,
    synthetic_edge,
)

F_NYQ = np.linspace(0.0, 0.5, 51)


def _max_err(res, angle_deg: float, sigma: float) -> float:  # type: ignore[no-untyped-def]
    truth = edge_truth_mtf(F_NYQ, sigma, math.radians(angle_deg))
    return float(np.max(np.abs(res.mtf_at(F_NYQ) - truth)))


@pytest.mark.parametrize("angle_deg,sigma", [(0.0, 0.5), (5.0, 0.3), (30.0, 1.0), (45.0, 0.05)])
def test_closed_form_edge_matches_supersampled_pixel_integration(
    angle_deg: float, sigma: float
) -> None:
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    d = np.linspace(-3.0, 3.0, 13)
    g = (np.arange(300) + 0.5) / 300 - 0.5
    xx, yy = np.meshgrid(g, g)
    numeric = np.array([ndtr((di + xx * c + yy * s) / sigma).mean() for di in d])
    assert np.max(np.abs(pixel_integrated_step(d, sigma, c, s) - numeric)) < 2e-6


def test_truth_mtf_is_gaussian_times_projected_pixel_aperture() -> None:
    f = np.array([0.0, 0.25, 0.5])
    got = edge_truth_mtf(f, 0.7, 0.0)
    want = np.exp(-2 * math.pi**2 * 0.49 * f**2) * np.sinc(f)
    assert np.allclose(got, want) and got[0] == 1.0
    # At 45 deg the square pixel is wider along the normal's projection: sinc^2(f / sqrt 2).
    assert edge_truth_mtf([0.5], 0.0, math.pi / 4)[0] == pytest.approx(np.sinc(0.5 / 2**0.5) ** 2)
    assert edge_truth_mtf(np.array([edge_truth_mtf50(0.7, 0.2)]), 0.7, 0.2)[0] == pytest.approx(
        0.5, abs=1e-9)


@pytest.mark.parametrize("angle_deg", [2.5, 5.0, 14.04, 18.43, 26.57, 33.0, 40.0])
@pytest.mark.parametrize("sigma", [0.3, 1.0, 3.0])
def test_noise_free_edges_match_the_analytic_mtf(angle_deg: float, sigma: float) -> None:
    img = synthetic_edge((100, 100), angle_deg, sigma, offset_px=0.37)
    res = measure_sfr(img)
    assert res.edge_angle_deg == pytest.approx(angle_deg, abs=0.05)
    # At atan(1/4) the pixel lattice (0.243 px) beats with the 1/4-px bins, which then hold one
    # or two positions each: the in-bin averaging is uneven (MTF Mapper avoids ~14 deg too).
    assert _max_err(res, angle_deg, sigma) < (0.016 if angle_deg == 14.04 else 0.006)
    truth50 = edge_truth_mtf50(sigma, math.radians(angle_deg))
    assert res.mtf50_cycles_per_px == pytest.approx(truth50, rel=0.02 if angle_deg == 14.04
                                                    else 0.005)


def test_noisy_12_bit_edge_meets_the_mtf50_figure_and_its_analytic_sigma_is_honest() -> None:
    rng = np.random.default_rng(3)
    truth50 = edge_truth_mtf50(1.0, math.radians(7.0))
    f = np.array([0.3, 0.5])  # where the noise, not the 0.002 floor, makes the sigma
    readings, m50_sigmas, curves, sigmas = [], [], [], []
    for _ in range(16):
        img = synthetic_edge((100, 100), 7.0, 1.0, noise_sigma=0.006, bits=12, rng=rng)
        res = measure_sfr(img.astype(np.uint16))
        assert res.uncertainty_method == "analytic"
        assert res.mtf50_cycles_per_px == pytest.approx(truth50, rel=0.02)
        assert res.mtf_sigma is not None and res.mtf_sigma[0] == 0.0
        assert res.mtf50_sigma is not None and res.mtf50_sigma > 0
        readings.append(res.mtf50_cycles_per_px)
        m50_sigmas.append(res.mtf50_sigma)
        curves.append(res.mtf_at(f))
        sigmas.append(res.sigma_at(f))
    # The propagated sigma matches the scatter of repeated readings (scaled 1.2 on purpose,
    # plus a 0.002 floor): neither a token number nor a gross overstatement.
    spread = float(np.std(readings, ddof=1))
    assert 0.6 < float(np.median(m50_sigmas)) / spread < 2.5
    ratio = np.median(sigmas, axis=0) / np.std(curves, axis=0, ddof=1)
    assert np.all((ratio > 0.7) & (ratio < 2.0)), ratio


def test_bootstrap_on_request_replaces_the_analytic_sigma() -> None:
    rng = np.random.default_rng(4)
    img = synthetic_edge((60, 60), 6.0, 1.0, noise_sigma=0.01, bits=12, rng=rng)
    boot = measure_sfr(img.astype(np.uint16), bootstrap=8, seed=2)
    plain = measure_sfr(img.astype(np.uint16))
    assert boot.uncertainty_method == "bootstrap" and plain.uncertainty_method == "analytic"
    assert np.array_equal(boot.mtf, plain.mtf)  # same reading, other uncertainty
    assert boot.mtf_sigma is not None and plain.mtf_sigma is not None
    assert not np.allclose(boot.mtf_sigma, plain.mtf_sigma)


def test_noise_does_not_read_as_mtf_beyond_the_cutoff() -> None:
    # sigma 3 px: the true MTF at 0.4-0.5 cycles/px is < 1e-6. The modulus of pure noise
    # would read ~1.25 sigma on average; the noise power is subtracted, so the mean reading
    # stays well under the sigma and the +-1.96 sigma interval holds the truth.
    rng = np.random.default_rng(6)
    f = np.array([0.4, 0.45, 0.5])
    got, sig = [], []
    for _ in range(24):
        img = synthetic_edge((100, 100), 5.0, 3.0, noise_sigma=0.6 / 50, bits=12, rng=rng)
        res = measure_sfr(img.astype(np.uint16))
        got.append(res.mtf_at(f))
        sig.append(res.sigma_at(f))
    assert float(np.mean(got)) < 0.7 * float(np.mean(sig))
    assert float(np.mean(np.asarray(got) <= 1.96 * np.asarray(sig))) >= 0.9


def test_off_centre_edge_at_low_snr_keeps_its_low_frequencies() -> None:
    # The edge 20 px off the ROI centre: the LSF window must sit on the edge, not be dragged
    # towards the ROI's middle by the plateaus' noise (that cut the LSF and lifted the MTF).
    rng = np.random.default_rng(7)
    f = np.array([0.05, 0.1, 0.2])
    errs = []
    for _ in range(20):
        ang = float(rng.uniform(3, 30))
        img = synthetic_edge((100, 100), ang, 1.0, offset_px=20.0, noise_sigma=0.6 / 20,
                             bits=12, rng=rng)
        res = measure_sfr(img.astype(np.uint16))
        errs.append(res.mtf_at(f) - edge_truth_mtf(f, 1.0, math.radians(ang)))
    assert np.all(np.abs(np.mean(errs, axis=0)) < 0.01), np.mean(errs, axis=0)


def test_hot_and_dead_pixels_at_the_edge_are_clipped_with_a_warning() -> None:
    # One hot and one dead pixel beside a 2 px blurred edge: unclipped they put a spike in
    # the ESF and a ripple of 0.03-0.05 over the MTF; clipped to 5 noise sigmas, they do not.
    worst_clean, worst_bad = 0.0, 0.0
    for seed in range(4):
        rng = np.random.default_rng(seed)
        img = synthetic_edge((100, 100), 7.0, 2.0, noise_sigma=0.006, bits=12, rng=rng)
        clean = measure_sfr(img.astype(np.uint16))
        bad = img.copy()
        bad[40 + seed, 46 + seed] = 3900.0
        bad[70 + seed, 52] = 100.0
        res = measure_sfr(bad.astype(np.uint16))
        assert any("2 pixel(s) more than 5 noise sigmas" in w for w in res.warnings)
        assert not any("noise sigmas" in w for w in clean.warnings)
        worst_clean = max(worst_clean, _max_err(clean, 7.0, 2.0))
        worst_bad = max(worst_bad, _max_err(res, 7.0, 2.0))
    assert worst_bad < worst_clean + 0.005


def test_rise_is_interpolated_between_coarse_samples() -> None:
    u = np.arange(-10, 11) * 0.7071  # the 45 deg lattice
    esf = np.clip((u + 4.0) / 8.0, 0.0, 1.0)  # linear ramp over 8 px: 10-90 % rise 6.4 px
    assert _rise_10_90(u, esf) == pytest.approx(6.4, abs=1e-9)  # samples alone: 5.66


def test_horizontal_edge_and_reversed_polarity_give_the_same_curve() -> None:
    base = synthetic_edge((90, 90), 6.0, 0.8)
    ref = measure_sfr(base)
    flipped = measure_sfr(base[:, ::-1])  # bright on the left
    assert flipped.dark < flipped.bright
    assert np.allclose(flipped.mtf_at(F_NYQ), ref.mtf_at(F_NYQ), atol=2e-3)
    horizontal = measure_sfr(base.T)  # intensity varies down the rows
    assert horizontal.direction == "vertical" and ref.direction == "horizontal"
    assert np.allclose(horizontal.mtf_at(F_NYQ), ref.mtf_at(F_NYQ), atol=2e-3)
    assert math.degrees(ref.normal_theta_rad) == pytest.approx(6.0, abs=0.05)
    assert math.degrees(horizontal.normal_theta_rad) == pytest.approx(84.0, abs=0.05)


def test_zero_degree_edge_is_refused_with_the_reason() -> None:
    with pytest.raises(SfrRefused) as exc:
        measure_sfr(synthetic_edge((100, 100), 0.0, 1.0))
    assert "pixel axis" in str(exc.value) and exc.value.reasons
    with pytest.raises(SfrRefused, match="pixel axis"):
        measure_sfr(synthetic_edge((100, 100), 1.0, 1.0))


def test_just_above_the_refusal_angle_is_measured_with_a_warning() -> None:
    res = measure_sfr(synthetic_edge((100, 100), 1.7, 1.0))
    assert any("deg from the pixel axis" in w for w in res.warnings)
    assert _max_err(res, 1.7, 1.0) < 0.01


def test_45_degree_edge_is_measured_with_the_coarse_lattice_warning() -> None:
    res = measure_sfr(synthetic_edge((100, 100), 45.0, 0.6))
    assert res.edge_angle_deg == pytest.approx(45.0, abs=0.1)
    assert any("coarse lattice" in w for w in res.warnings)
    assert _max_err(res, 45.0, 0.6) < 0.03  # aliasing of the 0.71 px lattice limits it
    # sigma 1 px at 45 deg: the rise read off the coarse lattice sets the LSF windows
    assert _max_err(measure_sfr(synthetic_edge((100, 100), 45.0, 1.0)), 45.0, 1.0) < 0.006


def test_clipped_edge_is_refused_and_slight_clipping_is_warned() -> None:
    img = synthetic_edge((100, 100), 5.0, 1.0, dark=0.3, bright=1.4, bits=8)  # bright side clips
    with pytest.raises(SfrRefused, match="clipped"):
        measure_sfr(img.astype(np.uint8))
    rng = np.random.default_rng(0)
    ok = synthetic_edge((100, 100), 5.0, 1.0, bits=8, noise_sigma=0.01, rng=rng)
    ok[3, 3] = 255  # one hot pixel: 0.01 %
    res = measure_sfr(ok.astype(np.uint8))
    assert any("clipped" in w for w in res.warnings)
    assert res.clipped_fraction == pytest.approx(1e-4)


def test_twenty_row_edge_is_measured_with_a_short_edge_warning() -> None:
    res = measure_sfr(synthetic_edge((20, 60), 8.0, 0.8))
    assert res.edge_rows == 20
    assert any("short edge" in w for w in res.warnings)
    assert _max_err(res, 8.0, 0.8) < 0.01
    with pytest.raises(SfrRefused, match="px long"):
        measure_sfr(synthetic_edge((8, 60), 8.0, 0.8))
    with pytest.raises(SfrRefused, match="too short for its angle"):
        measure_sfr(synthetic_edge((20, 60), 2.0, 0.8))  # 0.7 px of shift: not one phase cycle


def test_noise_only_and_flat_rois_are_refused() -> None:
    rng = np.random.default_rng(2)
    with pytest.raises(SfrRefused, match="no edge"):
        measure_sfr(rng.normal(1000.0, 20.0, (80, 80)))
    with pytest.raises(SfrRefused, match="no edge"):
        measure_sfr(np.full((50, 50), 7, np.uint8))


def test_low_contrast_is_warned() -> None:
    res = measure_sfr(synthetic_edge((80, 80), 5.0, 1.0, dark=0.5, bright=0.6))
    assert any("low contrast" in w for w in res.warnings)
    assert res.contrast == pytest.approx(0.1 / 1.1, abs=2e-3)


def test_bad_input_raises_value_error() -> None:
    with pytest.raises(ValueError, match="2-D"):
        measure_sfr(np.zeros((3, 10, 10)))
    img = synthetic_edge((40, 40), 5.0, 1.0)
    img[0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        measure_sfr(img)
    with pytest.raises(ValueError, match="fit_order"):
        measure_sfr(synthetic_edge((40, 40), 5.0, 1.0), fit_order=5)


def test_curved_edge_needs_the_polynomial_fit() -> None:
    rows, cols, sigma = 100, 80, 0.6
    y = np.arange(rows, dtype=np.float64)[:, None] - (rows - 1) / 2
    x = np.arange(cols, dtype=np.float64)[None, :] - (cols - 1) / 2
    bend = 0.0012 * y**2  # 3 px of bow over the edge (lens distortion)
    slope = math.tan(math.radians(5.0))
    d = (x - (slope * y + bend)) / math.hypot(1.0, slope)
    img = 0.2 + 0.6 * pixel_integrated_step(d, sigma, 1.0, slope)
    truth50 = edge_truth_mtf50(sigma, math.atan(slope))
    curved = measure_sfr(img, fit_order=2)
    assert curved.mtf50_cycles_per_px == pytest.approx(truth50, rel=0.03)
    # The straight fit leaves the bow in the ESF (it read MTF50 more than 10 % off before the
    # quality gate): refused as a bent edge, by name.
    with pytest.raises(SfrRefused, match=r"bent edge: the edge bows 2\.[6-9]\d px .*fit_order 2"):
        measure_sfr(img, fit_order=1)


def test_full_scale_and_json_summary() -> None:
    assert full_scale_of(np.arange(256, dtype=np.uint8)) == 255
    assert full_scale_of(np.array([0, 4095], np.uint16)) == 4095
    assert full_scale_of(np.arange(0, 65521, 16, dtype=np.uint16)) == 65520  # 12-bit MSB
    assert full_scale_of(np.array([0, 65535], np.uint16)) == 65535
    assert full_scale_of(np.zeros(3)) is None
    assert full_scale_of(np.array([5, 900], np.int16)) == 4095  # any integer type
    res = measure_sfr(synthetic_edge((60, 60), 5.0, 1.0), bootstrap=5)
    doc = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert doc["freqs_cycles_per_px"][50] == 0.5
    assert doc["mtf"][50] == pytest.approx(res.mtf_nyquist, abs=1e-6)
    assert len(doc["mtf_sigma"]) == len(doc["mtf"])


def test_complex_data_is_a_value_error() -> None:
    edge = synthetic_edge((80, 80), 5.0, 1.0)
    with pytest.raises(ValueError, match="real numbers"):
        measure_sfr(edge.astype(complex))


def test_edge_crossed_by_a_bar_is_refused_not_read() -> None:
    # A dark chart bar (8 px wide) crossing the ROI across the edge: before the quality gate
    # this read as an "ok" edge (fit RMS ~10 px or a negative contrast, MTF above 1).
    rng = np.random.default_rng(3)
    img = synthetic_edge((60, 40), 5.0, 0.8, noise_sigma=0.004, bits=8, rng=rng)
    clean = measure_sfr(img.astype(np.uint8))
    assert clean.contrast > 0.5 and clean.fit.rms_px < 1.0
    crossed = img.copy()
    crossed[20:28, :] = 20.0  # a dark bar, as dark as the edge's dark side
    with pytest.raises(SfrRefused, match="other structure in the ROI") as exc:
        measure_sfr(crossed.astype(np.uint8))
    assert len(exc.value.reasons) >= 1


def test_edge_with_a_bar_end_inside_is_refused() -> None:
    # The end of a bar reaching half-way into the ROI on the bright side.
    rng = np.random.default_rng(4)
    img = synthetic_edge((60, 40), 5.0, 0.8, noise_sigma=0.004, bits=8, rng=rng)
    img[10:50, 28:34] = 20.0
    # Its far side is a second edge of the edge's own sign: named as such (it was "n % of the
    # pixels are more than 5 noise sigmas off the edge profile").
    with pytest.raises(SfrRefused, match=r"the ROI holds a second edge \(two parallel edges of "
                                         r"the same sign"):
        measure_sfr(img.astype(np.uint8))


def test_bright_side_clipped_below_full_scale_is_refused() -> None:
    # Full well at gain 0.5 reads 8-bit code 127: the bright plateau sits on that code with
    # no noise while the dark side is noisy. Before: measured, MTF50 ~2x the truth.
    rng = np.random.default_rng(5)
    img = synthetic_edge((60, 40), 5.0, 1.0, dark=0.09, bright=0.9, noise_sigma=0.002, bits=8,
                         rng=rng)
    clipped = np.minimum(img, 127.0).astype(np.uint8)
    with pytest.raises(SfrRefused, match="bright side clipped at code 127 below full scale"):
        measure_sfr(clipped)
    # The same edge with the bright side unclipped (and quieter than the dark side is not
    # possible here: shot noise) is measured.
    ok = synthetic_edge((60, 40), 5.0, 1.0, dark=0.09, bright=0.45, noise_sigma=0.002, bits=8,
                        rng=rng)
    assert measure_sfr(ok.astype(np.uint8)).mtf50_cycles_per_px is not None
    # Noise-free quantised data (both plateaus on one code) is not mistaken for clipping.
    quiet = synthetic_edge((60, 40), 5.0, 1.0, dark=0.09, bright=0.45, bits=8)
    assert measure_sfr(quiet.astype(np.uint8)).mtf50_cycles_per_px is not None
    # The known ceiling passed in (the camera's full well at that gain) refuses it too.
    with pytest.raises(SfrRefused, match=r"clipped at 0 or full scale \(127\)"):
        measure_sfr(clipped, full_scale=127.0)
