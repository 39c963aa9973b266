"""The shared across-feature projection (bars at any angle, slanted-edge SFR)."""

import math

import numpy as np
import pytest

from benchlab.analysis.bars.projection import (
    across_coordinate,
    bin_profile,
    bin_profiles,
    project_roi,
)


def test_axis_aligned_projection_is_the_column_mean():
    rng = np.random.default_rng(1)
    img = rng.normal(100.0, 5.0, size=(7, 9))
    prof = project_roi(img, 0.0, bin_width_px=1.0)
    np.testing.assert_allclose(prof.u_px, np.arange(9) - 4.0)
    np.testing.assert_allclose(prof.mean, img.mean(axis=0))
    assert prof.count.tolist() == [7] * 9


def test_vertical_direction_is_the_row_mean():
    img = np.arange(12, dtype=float).reshape(4, 3)
    prof = project_roi(img, math.pi / 2, bin_width_px=1.0)
    np.testing.assert_allclose(prof.mean, img.mean(axis=1))
    np.testing.assert_allclose(prof.u_px, [-1.5, -0.5, 0.5, 1.5])


def test_oblique_projection_samples_below_one_pixel():
    # A linear ramp along a 30 deg normal: every bin mean equals the ramp at the bin centre.
    theta = math.radians(30.0)
    u = across_coordinate((60, 60), theta)
    img = 3.0 * u + 50.0
    prof = project_roi(img, theta, bin_width_px=0.25)
    ok = prof.filled
    assert ok.mean() > 0.95  # oblique: nearly every quarter-pixel bin holds pixels
    np.testing.assert_allclose(prof.mean[ok], 3.0 * prof.u_px[ok] + 50.0, atol=3.0 * 0.125)
    assert int(prof.count.sum()) == 3600


def test_empty_bins_are_nan_and_counted_zero():
    prof = bin_profile([0.0, 2.0], [1.0, 5.0], bin_width_px=1.0)
    assert prof.count.tolist() == [1, 0, 1]
    assert math.isnan(prof.mean[1])
    assert prof.mean[0] == 1.0 and prof.mean[2] == 5.0


def test_one_pixel_roi():
    prof = project_roi(np.array([[7]], dtype=np.uint16), 0.3)
    assert prof.count.tolist() == [1] and prof.mean.tolist() == [7.0]
    assert prof.u_px.tolist() == [0.0]


@pytest.mark.parametrize(
    "args, match",
    [
        (([0.0, 1.0], [1.0]), "differ in size"),
        (([], []), "no samples"),
        (([0.0], [1.0], 0.0), "positive"),
        (([float("nan")], [1.0]), "non-finite"),
        (([0.0, float("inf"), 1.0], [1.0, 2.0, 3.0]), "non-finite"),
        (([0.0, float("-inf")], [1.0, 2.0]), "non-finite"),
        (([float("nan"), 2.0, 1.0], [1.0, 2.0, 3.0]), "non-finite"),
    ],
)
def test_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        bin_profile(*args)


def test_bad_shape():
    with pytest.raises(ValueError, match="2-D"):
        project_roi(np.zeros(5), 0.0)
    with pytest.raises(ValueError, match="at least 1 x 1"):
        across_coordinate((0, 3), 0.0)


def _reference_bins(u, values, width):
    """The straightforward binning: index per sample, then a mean per bin."""
    u = np.asarray(u, dtype=np.float64).ravel()
    idx = np.floor((u - u.min()) / width + 0.5 + 1e-9).astype(np.int64)
    n_bins = int(idx.max()) + 1
    count = np.bincount(idx, minlength=n_bins)
    inv = 1.0 / np.maximum(count, 1)
    means = [np.where(count > 0, np.bincount(idx, np.ravel(v), n_bins) * inv, np.nan)
             for v in values]
    return u.min() + np.arange(n_bins) * width, count, means


@pytest.mark.parametrize("seed", range(6))
def test_bin_profiles_identical_to_the_straightforward_binning(seed):
    """In-place index arithmetic and the last bin from max(u): bit-identical bins and means,
    bin edges (half-pixel steps at 1 px bins) included."""
    rng = np.random.default_rng(seed)
    shape = (int(rng.integers(1, 60)), int(rng.integers(1, 60)))
    theta = float(rng.choice([0.0, math.pi / 2, rng.uniform(-math.pi, math.pi)]))
    u = across_coordinate(shape, theta)
    width = float(rng.choice([0.25, 0.5, 1.0, rng.uniform(0.05, 3.0)]))
    values = [rng.normal(size=shape), rng.integers(0, 4096, size=shape)]
    got = bin_profiles(u, values, width)
    centres, count, means = _reference_bins(u, values, width)
    for prof, mean in zip(got, means, strict=True):
        assert np.array_equal(prof.u_px, centres) and np.array_equal(prof.count, count)
        assert np.array_equal(prof.mean, mean, equal_nan=True)
