"""The speed-ups of the histogram and profilefit paths (issue 9) give exactly what the code they
replace gives: each shortcut against the straightforward computation, bit for bit, on
hypothesis-generated inputs including extremes (one pixel, one line, flat, huge values)."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from benchlab.analysis.bars import profilefit
from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.bars.geometry import (
    QUICK_MIN_Z,
    detrend,
    fundamental_is_clear,
    measure_geometry,
    quick_fundamental,
    quick_geometry,
)
from benchlab.analysis.bars.projection import across_coordinate, bin_profiles, filled_bin_means
from benchlab.analysis.bars.roi import _axis_and_sums, detect_axis, prepare_roi, robust_noise_sigma
from benchlab.analysis.bars.uncertainty import bootstrap_result
from benchlab.synthetic.bars import BarCase, render

_finite = st.floats(-1e6, 1e6, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(
    u=arrays(np.float64, st.integers(1, 300), elements=st.floats(-50, 50)),
    width=st.sampled_from([1 / 64, 1 / 32, 0.25, 1.0, 3.0]),
    seed=st.integers(0, 1000),
)
def test_filled_bin_means_are_bin_profiles_in_the_filled_bins(
    u: np.ndarray, width: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    values = [rng.normal(100, 30, u.size).round(), rng.normal(0, 1, u.size), u * u]
    count, means = filled_bin_means(u, values, width)
    profiles = bin_profiles(u, values, width)
    filled = profiles[0].filled
    assert np.array_equal(count, profiles[0].count[filled])
    for got, prof in zip(means, profiles, strict=True):
        assert np.array_equal(got, prof.mean[filled])
    with pytest.raises(ValueError, match="differ in size"):
        filled_bin_means(u, [np.zeros(u.size + 1)], width)


@settings(max_examples=200, deadline=None)
@given(
    rows=st.integers(1, 60), cols=st.integers(1, 60),
    theta=st.floats(-4.0, 4.0, allow_nan=False),
)
def test_abs_max_from_the_corners_is_the_whole_grids(rows: int, cols: int, theta: float) -> None:
    """The refinement reads the largest |u| and |v| off the ROI's corners: the same number
    as a pass over every pixel, at any angle and shape (1 x 1 and single lines included)."""
    for angle in (theta, theta + math.pi / 2):
        coord = across_coordinate((rows, cols), angle).ravel()
        want = float(np.abs(coord).max())
        assert profilefit._abs_max(coord, (rows, cols), True) == want
        assert profilefit._abs_max(coord, (rows, cols), False) == want


def _symmetric(n: int, seed: int, scale: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n)) * scale
    return a @ a.T + np.eye(n) * scale


@settings(max_examples=100, deadline=None)
@given(n=st.integers(1, 8), seed=st.integers(0, 10_000),
       scale=st.sampled_from([1e-8, 1.0, 1e6]))
def test_lapack_shortcuts_are_numpys_linalg(n: int, seed: int, scale: float) -> None:
    a = _symmetric(n, seed, scale)
    b = np.random.default_rng(seed + 1).normal(size=n)
    assert np.array_equal(profilefit._inv(a), np.linalg.inv(a))
    assert np.array_equal(profilefit._solve(a, b), np.linalg.solve(a, b))
    vals, vecs = profilefit._eigh(a)
    want_vals, want_vecs = np.linalg.eigh(a)
    assert np.array_equal(vals, want_vals) and np.array_equal(vecs, want_vecs)


def test_lapack_shortcuts_raise_on_singular_matrices_quietly() -> None:
    """A singular matrix raises LinAlgError as numpy does (the fit catches it), and under the
    fit's error state no warning leaks."""
    zero = np.zeros((3, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(invalid="ignore"):
            with pytest.raises(np.linalg.LinAlgError):
                profilefit._inv(zero)
            with pytest.raises(np.linalg.LinAlgError):
                profilefit._solve(zero, np.ones(3))
        # What LAPACK cannot decompose falls back to numpy's own call: the same outcome.
        nan = np.full((2, 2), np.nan)
        with np.errstate(invalid="ignore"):
            got = profilefit._eigh(nan)
            want = np.linalg.eigh(nan)
        assert all(np.array_equal(g, w, equal_nan=True) for g, w in zip(got, want, strict=True))


def _reference_coefficients(model: profilefit._Model, delta: float, duty: float,
                            var: float) -> np.ndarray:
    """The model's coefficients as first written (one row at a time)."""
    n = model.k.size
    gain = np.exp(model._blur * var) * model.footprint
    pk = math.pi * duty * model.k
    ang = model._two_pi_k * delta
    cos_a, sin_a = np.cos(ang), np.sin(ang)
    amp = model._two_over_pik * np.sin(pk) * gain
    amp_duty = 2.0 * np.cos(pk) * gain
    out = np.empty((4, 2 * n))
    out[0, :n], out[0, n:] = cos_a * amp, sin_a * amp
    out[1, :n] = out[0, n:] * model._minus_two_pi_k
    out[1, n:] = out[0, :n] * model._two_pi_k
    out[2, :n], out[2, n:] = cos_a * amp_duty, sin_a * amp_duty
    out[3] = out[0] * model._blur2
    return out


@settings(max_examples=150, deadline=None)
@given(
    n_harm=st.integers(1, 48), delta=st.floats(-0.5, 0.5), duty=st.floats(0.2, 0.8),
    var=st.floats(0.0, 400.0), freq=st.floats(0.03, 0.5), theta=st.floats(-1.6, 1.6),
)
def test_stacked_coefficients_are_the_row_by_row_ones(
    n_harm: int, delta: float, duty: float, var: float, freq: float, theta: float
) -> None:
    w = np.linspace(0.0, 1.0, 17, endpoint=False)
    model = profilefit._Model(w, freq, theta, n_harm, np.full(w.size, 1e-3))
    want = _reference_coefficients(model, delta, duty, var)
    assert np.array_equal(model._coefficients(delta, duty, var), want)
    first = model.coefficients(delta, duty, var)
    assert np.array_equal(first, want)
    # The copies on other samples share the recent coefficients: the same numbers.
    assert model.at(None).coefficients(delta, duty, var) is first
    assert np.array_equal(model.coefficients(delta + 0.01, duty, var),
                          _reference_coefficients(model, delta + 0.01, duty, var))


@settings(max_examples=150, deadline=None)
@given(img=arrays(np.float64, st.tuples(st.integers(1, 40), st.integers(1, 40)),
                  elements=_finite))
def test_profile_sums_give_the_same_axis_and_plane(img: np.ndarray) -> None:
    """prepare_roi's column and row sums (kept for the plane fit) pick the same axis as
    detect_axis and give the same detrended ROI as computing them again."""
    axis, sums = _axis_and_sums(img)
    assert axis == detect_axis(img)
    if min(img.shape) < 2:
        assert sums is None
        return
    assert sums is not None
    assert np.array_equal(sums[0], img.sum(axis=0)) and np.array_equal(sums[1], img.sum(axis=1))
    assert np.array_equal(detrend(img, sums), detrend(img))
    # Sums of another shape (a crop, a selection) are not used.
    assert np.array_equal(detrend(img[:, :-1], sums), detrend(img[:, :-1]))


@pytest.mark.parametrize("shape", [(16, 16), (40, 50), (300, 280)])
def test_geometry_with_profile_sums_is_the_same(shape: tuple[int, int]) -> None:
    roi = render(BarCase(shape=shape, px_per_period=7.0, angle_deg=31.0, noise_sigma=2.0,
                         shading=0.2), np.random.default_rng(3))
    prep = prepare_roi(roi, freq_cycles_per_px=1 / 7.0)
    assert prep.profile_sums is None  # measured with the axis, on first use
    assert prep.axis == detect_axis(prep.pixels)
    assert prep.profile_sums is not None
    img = prep.pixels
    assert quick_geometry(img, prep.noise_sigma, 1 / 7.0, sums=prep.profile_sums) == (
        quick_geometry(img, prep.noise_sigma, 1 / 7.0))
    got = measure_geometry(img, prep.noise_sigma, 1 / 7.0, quick_start=True,
                           sums=prep.profile_sums)
    assert got == measure_geometry(img, prep.noise_sigma, 1 / 7.0, quick_start=True)


def test_profile_sums_only_where_the_orientation_was_detected() -> None:
    roi = render(BarCase(shape=(30, 40), px_per_period=6.0, noise_sigma=1.0),
                 np.random.default_rng(0))
    assert prepare_roi(roi).measured().profile_sums is not None
    assert prepare_roi(roi, orientation="horizontal").measured().profile_sums is None
    prep = prepare_roi(roi).measured()
    same = prep.selected(prep.pixels, 1.0, prep.vmin, prep.vmax)
    assert same.sums_for(same.pixels) is not None
    other = prep.selected(prep.pixels[:, :20], 1.0, prep.vmin, prep.vmax)
    assert other.sums_for(other.pixels) is None
    resampled = dataclasses.replace(prep, pixels=prep.pixels.copy())
    assert resampled.sums_for(resampled.pixels) is None


def test_bootstrap_resamples_do_not_reuse_the_roi_profile_sums() -> None:
    """Resampled lines are other pixels: their geometry must come from their own sums (with
    the original's, the resamples would read a different, wrong plane)."""
    roi = render(BarCase(shape=(40, 50), px_per_period=8.0, angle_deg=0.0, noise_sigma=3.0,
                         shading=0.25), np.random.default_rng(5))
    with_sums = prepare_roi(roi, freq_cycles_per_px=0.125).measured()
    assert with_sums.profile_sums is not None
    without = dataclasses.replace(with_sums, profile_sums=None)
    fit = profilefit.profile_fit(with_sums)
    assert fit.resolved
    a = bootstrap_result(with_sums, fit, profilefit.profile_fit, 12, seed=1)
    b = bootstrap_result(without, fit, profilefit.profile_fit, 12, seed=1)
    assert a.uncertainty_method == "bootstrap"
    assert a.interval == b.interval and a.uncertainty == b.uncertainty


def test_fit_diagnostics_carry_the_fit_noise_not_the_rois() -> None:
    """diagnostics_with overrides the shared fields (what dataclasses.replace did)."""
    roi = render(BarCase(shape=(40, 50), px_per_period=8.0, angle_deg=25.0, noise_sigma=2.0),
                 np.random.default_rng(2))
    r = estimate_modulation(roi, estimator="profilefit", freq_cycles_per_px=0.125)
    prep = prepare_roi(roi, freq_cycles_per_px=0.125)
    assert r.diagnostics.noise_sigma != prep.noise_sigma
    assert r.diagnostics.noise_sigma == pytest.approx(2.0, rel=0.15)
    assert r.diagnostics.uncertainty_model is not None and r.diagnostics.duty is not None
    d = prep.diagnostics_with(noise_sigma=1.5, duty=0.4)
    assert (d.noise_sigma, d.duty, d.n_pixels) == (1.5, 0.4, 2000)


def test_fit_falls_back_to_numpys_linalg_without_the_lapack_gufuncs(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Another numpy without the private gufuncs: the fit reads the same through np.linalg."""
    roi = render(BarCase(shape=(40, 50), px_per_period=8.0, angle_deg=25.0, noise_sigma=2.0),
                 np.random.default_rng(4))
    fast = estimate_modulation(roi, estimator="profilefit", freq_cycles_per_px=0.125)
    assert profilefit._lapack is not None
    monkeypatch.setattr(profilefit, "_lapack", None)
    slow = estimate_modulation(roi, estimator="profilefit", freq_cycles_per_px=0.125)
    assert (fast.modulation, fast.interval) == (slow.modulation, slow.interval)


@pytest.mark.parametrize("shape", [(40, 50), (16, 16), (300, 280), (12, 40)])
def test_quick_fundamental_is_quick_geometry_without_its_uncertainties(
    shape: tuple[int, int],
) -> None:
    roi = render(BarCase(shape=shape, px_per_period=6.0, angle_deg=52.0, noise_sigma=2.0),
                 np.random.default_rng(9))
    prep = prepare_roi(roi, freq_cycles_per_px=1 / 6.0)
    geom = quick_geometry(prep.pixels, prep.noise_sigma, 1 / 6.0, sums=prep.profile_sums)
    parts = quick_fundamental(prep.pixels, prep.noise_sigma, 1 / 6.0, None, prep.profile_sums)
    assert geom is not None and parts is not None
    assert (parts.theta_rad, parts.freq_cycles_per_px, parts.amplitude) == (
        geom.theta_rad, geom.freq_cycles_per_px, geom.amplitude)
    assert parts.phase_cycles == geom.phase_cycles
    # Without a noise, the noise test is the caller's: the same fundamental, and the test
    # passes at this noise and fails at one the fundamental does not stand clear of.
    unchecked = quick_fundamental(prep.pixels, None, 1 / 6.0, None, prep.profile_sums)
    assert unchecked == parts
    assert fundamental_is_clear(parts, prep.noise_sigma)
    n = parts.shape[0] * parts.shape[1]
    z_limit = parts.amplitude / (QUICK_MIN_Z * math.sqrt(2.0 / n))  # the noise at the limit
    assert fundamental_is_clear(parts, 0.99 * z_limit)
    assert not fundamental_is_clear(parts, 1.01 * z_limit)
    assert not fundamental_is_clear(parts._replace(power=3 * parts.amplitude**2), 0.0)


@pytest.mark.parametrize("orientation", [None, "vertical"])
def test_axis_and_noise_measured_on_first_use_as_before(orientation: str | None) -> None:
    """prepare_roi leaves the axis and the noise to their first use (the histogram method
    with a frequency needs neither); measured then, they are what it used to measure."""
    roi = render(BarCase(shape=(40, 50), px_per_period=8.0, angle_deg=70.0, noise_sigma=2.0),
                 np.random.default_rng(6))
    prep = prepare_roi(roi, freq_cycles_per_px=0.125, orientation=orientation)
    assert prep.known_noise is None
    assert prep.known_axis == (None if orientation is None else 0)
    axis = detect_axis(prep.pixels)
    assert axis == 0
    assert prep.noise_sigma == robust_noise_sigma(prep.pixels, axis)
    assert (prep.known_axis, prep.known_noise) == (axis, prep.noise_sigma)
    # The code-step floor applies to the lazily measured noise too.
    flat = prepare_roi(np.full((10, 10), 9, np.uint8))
    assert flat.noise_sigma == pytest.approx(1 / np.sqrt(12.0))
    # Given or from frames: known at once.
    assert prepare_roi(roi, noise_sigma=1.25).known_noise == 1.25
    frames = np.stack([roi, roi + 1, roi])
    assert prepare_roi(frames).known_noise is not None

