"""Shading (illumination non-uniformity) under a slanted edge, and hot pixels: the SFR reads
the lens, not the lighting nor a few bad pixels."""

from __future__ import annotations

import math

import numpy as np
import pytest

import benchlab.analysis.sfr.measure as sfr
import benchlab.analysis.sfr.shading as shading
from benchlab.analysis.sfr.measure import SfrRefused, measure_sfr
from benchlab.synthetic.edges import edge_truth_mtf, synthetic_edge

F = np.linspace(0.0, 0.5, 51)


def _shaded(angle_deg: float, sigma_px: float, gradient_per_px: float, *, additive: bool = False,
            snr: float = 100.0, seed: int = 0, along_rows: bool = False) -> np.ndarray:
    """A 12-bit 100 x 100 edge (levels 0.2 / 0.7 FS) under a linear illumination gradient
    along the columns (or rows): multiplied (vignetting) or added (stray light)."""
    rng = np.random.default_rng(seed)
    clean = synthetic_edge((100, 100), angle_deg, sigma_px, dark=0.2, bright=0.7)
    ramp = np.arange(100, dtype=np.float64) - 49.5
    ramp2d = ramp[:, None] if along_rows else ramp[None, :]
    lit = clean + gradient_per_px * ramp2d if additive else clean * (1 + gradient_per_px * ramp2d)
    noisy = lit + (rng.normal(0.0, 0.5 / snr, lit.shape) if math.isfinite(snr) else 0.0)
    return np.clip(np.floor(noisy * 4095 + 0.5), 0, 4095).astype(np.uint16)


def _max_err(res: sfr.SfrResult, sigma_px: float, angle_deg: float) -> float:
    truth = edge_truth_mtf(F, sigma_px, math.radians(angle_deg))
    return float(np.max(np.abs(res.mtf_at(F) - truth)))


@pytest.mark.parametrize(("angle", "sigma", "gradient", "additive"), [
    (6.0, 2.0, 0.0015, False),  # +-7.5 % vignetting across the ROI
    (21.0, 0.6, 0.001, False),
    (37.0, 1.0, 0.002, False),  # +-10 %, steep edge (its core read as other structure before)
    (9.0, 2.0, 0.002, True),    # stray light: +-0.1 of full scale, +-20 % of the step
])
def test_a_shaded_edge_reads_the_lens_not_the_lighting(
    monkeypatch: pytest.MonkeyPatch, angle: float, sigma: float, gradient: float, additive: bool
) -> None:
    img = _shaded(angle, sigma, gradient, additive=additive)
    res = measure_sfr(img, method="free")
    after = _max_err(res, sigma, angle)
    assert after < 0.015
    assert any(w.startswith("illumination not uniform") and "flattened" in w
               for w in res.warnings)
    # The dark level is the one at the edge centre, where the planes are anchored.
    assert res.dark == pytest.approx(0.2 * 4095, rel=0.01)
    # Without the flattening the same ROI reads the shading as MTF (or is refused).
    monkeypatch.setattr(sfr, "SHADING_PASSES", 0)
    try:
        before = _max_err(measure_sfr(img, method="free"), sigma, angle)
    except SfrRefused:
        before = math.inf
    assert before > max(0.02, 2.0 * after)


def test_a_uniform_roi_is_left_exactly_as_it_was(monkeypatch: pytest.MonkeyPatch) -> None:
    for seed, (angle, sigma, snr) in enumerate([(5.0, 1.0, 100.0), (28.0, 0.3, 20.0),
                                                 (12.0, 3.0, math.inf)]):
        img = _shaded(angle, sigma, 0.0, snr=snr, seed=seed)
        got = measure_sfr(img)
        assert not any("illumination" in w for w in got.warnings)
        monkeypatch.setattr(sfr, "SHADING_PASSES", 0)
        ref = measure_sfr(img)
        monkeypatch.undo()
        assert np.array_equal(got.mtf, ref.mtf)
        assert got.mtf50_cycles_per_px == ref.mtf50_cycles_per_px


def test_shading_along_the_edge_alone_is_found_and_removed() -> None:
    # A near-vertical edge lit unevenly from top to bottom: the plateaus change along the
    # edge only (each row's step differs); the ESF averages it out but the pixels disagree.
    img = _shaded(4.0, 1.0, 0.002, along_rows=True, snr=200.0)
    res = measure_sfr(img, method="free")
    assert any("illumination not uniform" in w for w in res.warnings)
    assert _max_err(res, 1.0, 4.0) < 0.01


def test_shading_too_strong_to_flatten_is_said() -> None:
    # The step falls to almost nothing at one side of the ROI (a plane cannot be the light).
    img = _shaded(8.0, 1.0, 0.0185, snr=300.0)
    try:
        res = measure_sfr(img, method="free")
    except SfrRefused as exc:  # or refused outright: never read silently
        assert "pixels" in str(exc) or "edge" in str(exc)
        return
    assert any("too strong to flatten" in w for w in res.warnings)


def test_plane_fit_ignores_hot_pixels_and_measures_a_known_slope() -> None:
    rng = np.random.default_rng(4)
    drow = rng.uniform(-50, 50, 3000)
    dcol = rng.uniform(-50, 50, 3000)
    z = 800.0 + 0.3 * drow - 1.2 * dcol + rng.normal(0.0, 5.0, 3000)
    z[:60] = 4000.0  # 2 % hot pixels
    plane = shading._plane(drow, dcol, z, 25.0)
    assert plane.c0 == pytest.approx(800.0, abs=0.5)
    assert (plane.c_row, plane.c_col) == pytest.approx((0.3, -1.2), abs=0.01)
    assert plane.chi2_drop > 1e5
    flat = shading._plane(drow, dcol, 800.0 + rng.normal(0.0, 5.0, 3000), 25.0)
    assert flat.chi2_drop < shading.SHADING_CHI2


@pytest.mark.parametrize(("noise", "n_hot"), [(0.0, 5), (0.0, 20), (0.0, 100), (0.005, 100)])
def test_hot_pixels_are_clipped_alone_and_leave_the_reading(noise: float, n_hot: int) -> None:
    img = synthetic_edge((100, 100), 5.0, 1.0, noise_sigma=noise, bits=12,
                         rng=np.random.default_rng(2)).astype(np.uint16)
    clean = measure_sfr(img)
    idx = np.random.default_rng(n_hot).choice(img.size, n_hot, replace=False)
    img.ravel()[idx] = 3900
    res = measure_sfr(img)
    # Exactly the hot pixels (noise-free: before, their neighbours in the same bins too).
    assert any(w.startswith(f"{n_hot} pixel(s) more than") for w in res.warnings)
    assert not any("illumination" in w or "truncated" in w for w in res.warnings)
    assert res.dark == pytest.approx(clean.dark, abs=2.5)
    assert res.lsf_windows[0].flat_half_px == pytest.approx(clean.lsf_windows[0].flat_half_px,
                                                             abs=0.5)
    assert _max_err(res, 1.0, 5.0) < 0.008
