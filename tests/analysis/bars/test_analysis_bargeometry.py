"""Bar geometry from the ROI: the quick path (structure tensor + phase drift), the spectral path
and their shared pieces."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from benchlab.analysis.bars import geometry as bargeometry
from benchlab.analysis.bars.geometry import (
    _cell_gradient_direction,
    _centred_crop,
    _drift_refine,
    _fast_len,
    detrend,
    dft_at,
    measure_geometry,
    quick_geometry,
    structure_tensor_direction,
)
from benchlab.synthetic.bars import BarCase, render


def _bars(angle_deg: float, period: float, shape: tuple[int, int] = (40, 50),
          noise: float = 1.0, seed: int = 0, phase: float = 0.3) -> tuple[np.ndarray, BarCase]:
    case = BarCase(shape=shape, px_per_period=period, angle_deg=angle_deg, noise_sigma=noise,
                   phase=phase, psf_sigma_px=0.8)
    return render(case, np.random.default_rng(seed)).astype(np.float64), case


def _angle_error(a: float, b: float) -> float:
    """Difference of two directions modulo pi (radians)."""
    return abs((a - b + math.pi / 2) % math.pi - math.pi / 2)


@pytest.mark.parametrize("angle", [0.0, 17.0, 45.0, 71.0, 90.0])
@pytest.mark.parametrize("period", [2.6, 8.0, 15.0])
def test_quick_geometry_matches_truth_and_the_spectral_path(angle: float, period: float) -> None:
    img, case = _bars(angle, period, seed=int(angle + 10 * period))
    f = case.freq_cycles_per_px
    quick = quick_geometry(img, 1.0, f)
    full = measure_geometry(img, 1.0, f, curvature=False)
    assert full is not None
    across = f * (abs(math.cos(case.theta_rad)) * 50 + abs(math.sin(case.theta_rad)) * 40)
    if across < bargeometry.QUICK_MIN_PERIODS:  # 15 px bars over 40 rows: 2.7 periods
        assert quick is None
        return
    assert quick is not None
    # Phase errors at the ROI's edge (cycles) from the direction and frequency errors: small
    # against the truth (non-whole periods bias both paths' frequency alike on axis-aligned
    # bars) and against the spectral path.
    edge = 0.5 * math.hypot(*img.shape)
    assert _angle_error(quick.theta_rad, case.theta_rad) * f * edge < 0.01
    assert abs(quick.freq_cycles_per_px - f) * edge < 0.04
    assert _angle_error(quick.theta_rad, full.theta_rad) * f * edge < 0.002
    assert abs(quick.freq_cycles_per_px - full.freq_cycles_per_px) * edge < 0.002
    # Same bright-bar phase (modulo one period) and amplitude as the whole-ROI DFT.
    assert abs((quick.phase_cycles - full.phase_cycles + 0.5) % 1.0 - 0.5) < 0.01
    assert quick.amplitude == pytest.approx(full.amplitude, rel=0.02)
    assert quick.hessian == (0.0, 0.0, 0.0)


def test_quick_geometry_declines_what_it_cannot_measure() -> None:
    img, case = _bars(30.0, 8.0)
    f = case.freq_cycles_per_px
    assert quick_geometry(img, 1.0, 0.0) is None  # no prior
    assert quick_geometry(img[:12, :12], 1.0, f) is None  # under QUICK_MIN_PIXELS
    assert quick_geometry(img[:, :6], 1.0, f) is None  # narrower than 8 px
    wide, case40 = _bars(3.0, 40.0, shape=(20, 100))
    # 100 px along the bars but < 1 period across them.
    assert quick_geometry(wide.T.copy(), 1.0, case40.freq_cycles_per_px) is None
    noise = np.random.default_rng(1).normal(100.0, 5.0, (40, 50))
    assert quick_geometry(noise, 5.0, f) is None  # no significant fundamental
    # A prior off by more than its band (the bars are at 2.5x it): the caller searches.
    assert quick_geometry(img, 1.0, f / 2.5) is None


def test_structure_tensor_direction_and_coherence() -> None:
    img, case = _bars(33.0, 12.0, noise=0.3)
    theta, coherence = structure_tensor_direction(detrend(img))
    assert _angle_error(theta, case.theta_rad) < math.radians(1.5)
    assert coherence > 0.9
    _, incoherent = structure_tensor_direction(np.random.default_rng(2).normal(0, 1, (40, 50)))
    assert incoherent < 0.2
    # Directions are reported in (-pi/2, pi/2], like BarGeometry.
    steep, _ = structure_tensor_direction(detrend(_bars(-80.0, 12.0)[0]))
    assert -math.pi / 2 < steep <= math.pi / 2 and _angle_error(steep, math.radians(-80)) < 0.03


def test_cell_gradient_anisotropy_is_corrected() -> None:
    """Fine oblique bars: the 2 x 2-cell gradients pull the direction towards the diagonal;
    quick_geometry inverts that before refining (without it the first estimate is off by
    more than the refinement's settling threshold)."""
    f, theta = 0.35, math.radians(25.0)
    reported = _cell_gradient_direction(theta, f)
    assert abs(reported - theta) > math.radians(1.0)  # the bias is real ...
    corrected = reported
    for _ in range(3):
        corrected += reported - _cell_gradient_direction(corrected, f)
    assert abs(corrected - theta) < 1e-4  # ... and the inversion removes it
    # The tensor of a noiseless pattern reports the biased direction.
    img, case = _bars(25.0, 1 / f, noise=0.0)
    measured, _ = structure_tensor_direction(detrend(img))
    assert abs(measured - theta) > abs(reported - theta) / 2


def test_drift_refine_converges_from_an_offset_start() -> None:
    img, case = _bars(40.0, 6.0, shape=(64, 64), noise=0.5)
    kx0, ky0 = case.freq_cycles_per_px * math.cos(case.theta_rad), case.freq_cycles_per_px * (
        math.sin(case.theta_rad))
    resid = detrend(img)
    start = (kx0 + 0.004, ky0 - 0.003)  # ~0.2 cycles off at the ROI's edge
    out = _drift_refine(resid, start[0], start[1], 0.01, 5)
    assert out is not None
    assert math.hypot(out[0] - kx0, out[1] - ky0) < 4e-4
    assert _drift_refine(resid, start[0], start[1], 1e-9, 1) is None  # not settled in 1 pass


def test_measure_geometry_with_a_wrong_prior_still_finds_the_bars() -> None:
    """The spectrum is computed once for the prior's band and the wide search: a fundamental
    far stronger than anything in the band wins."""
    img, case = _bars(20.0, 10.0, shape=(64, 64), noise=0.5)
    geom = measure_geometry(img, 0.5, freq_prior=case.freq_cycles_per_px * 3.0)
    assert geom is not None
    assert geom.freq_cycles_per_px == pytest.approx(case.freq_cycles_per_px, rel=0.01)


def test_detrend_removes_mean_and_plane_exactly() -> None:
    rng = np.random.default_rng(5)
    rows, cols = 17, 23
    y, x = np.mgrid[:rows, :cols].astype(np.float64)
    noise = rng.normal(0, 1, (rows, cols))
    img = 7.0 + 0.3 * x - 1.1 * y + noise
    out = detrend(img)
    design = np.column_stack([np.ones(img.size), x.ravel(), y.ravel()])
    coef, *_ = np.linalg.lstsq(design, img.ravel(), rcond=None)
    assert np.allclose(out.ravel(), img.ravel() - design @ coef, atol=1e-10)
    assert np.allclose(detrend(np.full((1, 5), 3.0)), 0.0)  # one row: no y slope to fit


def test_fast_len_is_the_next_11_smooth_number() -> None:
    def smooth(m: int) -> bool:
        for p in (2, 3, 5, 7, 11):
            while m % p == 0:
                m //= p
        return m == 1

    for n in range(1, 600):
        got = _fast_len(n)
        assert got >= n and smooth(got)
        assert all(not smooth(m) for m in range(n, got))


def test_geometry_modules_import_no_scipy_at_module_level() -> None:
    """``import scipy.fft`` cost ~0.15 s of the CLI start-up (issue 11)."""
    root = Path(bargeometry.__file__).parent
    for name in ("geometry.py", "projection.py", "histogram.py"):
        tree = ast.parse((root / name).read_text())
        for node in tree.body:  # module level only
            if isinstance(node, ast.Import):
                assert not any(a.name.split(".")[0] == "scipy" for a in node.names), name
            if isinstance(node, ast.ImportFrom):
                assert (node.module or "").split(".")[0] != "scipy", name


@pytest.mark.parametrize("shape", [(300, 520), (301, 257), (40, 700)])
def test_large_rois_are_measured_on_a_centred_crop(shape: tuple[int, int]) -> None:
    """Fixed cost on large ROIs, and the crop's centre is the ROI's: the phase is the whole
    ROI's."""
    crop = _centred_crop(np.zeros(shape), 256)
    assert crop.shape[0] <= 256 and crop.shape[1] <= 256
    assert (shape[0] - crop.shape[0]) % 2 == 0 and (shape[1] - crop.shape[1]) % 2 == 0
    img, case = _bars(28.0, 9.0, shape=shape, noise=2.0, seed=shape[1])
    for geom in (quick_geometry(img, 2.0, case.freq_cycles_per_px),
                 measure_geometry(img, 2.0, case.freq_cycles_per_px)):
        assert geom is not None
        value = dft_at(detrend(img), *geom.k_xy)
        whole = math.atan2(value.imag, value.real) / (2 * math.pi)
        assert abs((geom.phase_cycles - whole + 0.5) % 1.0 - 0.5) < 0.01
        edge = 0.5 * math.hypot(*shape)
        assert abs(geom.freq_cycles_per_px - case.freq_cycles_per_px) * edge < 0.03


def test_quick_geometry_with_a_prior_a_few_percent_off() -> None:
    """A nominal magnification 3-5 % off wraps the phase over half a large ROI: one step
    between quarters first, then the halves."""
    img, case = _bars(31.0, 8.0, shape=(200, 200), noise=1.0, seed=1)
    f = case.freq_cycles_per_px
    for ratio in (0.95, 1.05):
        assert _drift_refine(detrend(img), *(_k(f * ratio, case.theta_rad)), 0.05, 3) is None
        geom = quick_geometry(img, 1.0, f * ratio)
        assert geom is not None and geom.freq_cycles_per_px == pytest.approx(f, rel=1e-3)


def test_quick_geometry_rejects_a_side_lobe() -> None:
    """Strong 4 px bars and a prior at 0.7 of their frequency: the refinement can settle on a
    side lobe (75 % of the frequency); it carries a small share of the bars' power, so the
    quick path declines and the caller searches the spectrum."""
    img, case = _bars(31.0, 4.0, shape=(40, 50), noise=1.0, seed=1)
    f = case.freq_cycles_per_px
    assert quick_geometry(img, 1.0, 0.7 * f) is None
    geom = measure_geometry(img, 1.0, 0.7 * f)
    assert geom is not None and geom.freq_cycles_per_px == pytest.approx(f, rel=0.01)


def _k(f: float, theta: float) -> tuple[float, float]:
    return f * math.cos(theta), f * math.sin(theta)


def test_no_blas_products_on_the_pixels() -> None:
    """A BLAS dot or matrix product over a large ROI wakes OpenBLAS's threads, which then spin
    against the analysis on a loaded machine (a 200 x 200 histogram reading went from ~1 to
    ~10 ms): the geometry, projection, histogram and ROI preparation use numpy reductions."""
    root = Path(bargeometry.__file__).parent
    for name in ("geometry.py", "projection.py", "histogram.py", "roi.py"):
        tree = ast.parse((root / name).read_text())
        products = [node.lineno for node in ast.walk(tree)
                    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult)]
        dots = [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Attribute)
                and node.attr in ("dot", "matmul", "vdot", "inner", "tensordot")]
        assert not products and not dots, (name, products, dots)


@pytest.mark.parametrize(("angle", "period", "shape"), [
    (0.0, 8.0, (40, 50)), (23.0, 8.0, (40, 50)), (58.0, 3.1, (64, 64)), (90.0, 15.0, (100, 100)),
    (37.0, 5.0, (300, 400)),
])
def test_quick_start_reads_like_the_spectral_start(
    angle: float, period: float, shape: tuple[int, int], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``quick_start`` replaces only the 2-D spectrum's peak as the refinement's start: the
    same direction, frequency, phase and amplitude, and no spectrum computed at all."""
    img, case = _bars(angle, period, shape=shape, seed=3)
    f = case.freq_cycles_per_px
    spectral = measure_geometry(img, 1.0, f, curvature=False)
    calls: list[int] = []
    real_spectrum = bargeometry._spectrum

    def counted(resid: np.ndarray) -> bargeometry._Spectrum:
        calls.append(1)
        return real_spectrum(resid)

    monkeypatch.setattr(bargeometry, "_spectrum", counted)
    quick = measure_geometry(img, 1.0, f, curvature=False, quick_start=True)
    assert calls == []  # the quick path accepted these bars: no spectrum
    assert spectral is not None and quick is not None
    edge = 0.5 * math.hypot(*shape)
    assert _angle_error(quick.theta_rad, spectral.theta_rad) * f * edge < 0.005
    assert abs(quick.freq_cycles_per_px - spectral.freq_cycles_per_px) * edge < 0.005
    assert abs((quick.phase_cycles - spectral.phase_cycles + 0.5) % 1.0 - 0.5) < 0.005
    assert quick.amplitude == pytest.approx(spectral.amplitude, rel=1e-3)


def test_quick_start_falls_back_to_the_spectrum() -> None:
    """Where the quick path declines (a side lobe near a prior far off, too few pixels) the
    spectral search starts the refinement as without ``quick_start``."""
    img, case = _bars(31.0, 4.0, shape=(40, 50), noise=1.0, seed=1)
    f = case.freq_cycles_per_px
    geom = measure_geometry(img, 1.0, 0.7 * f, quick_start=True)
    assert geom is not None and geom.freq_cycles_per_px == pytest.approx(f, rel=0.01)
    small, small_case = _bars(20.0, 5.0, shape=(12, 12), seed=2)
    assert measure_geometry(small, 1.0, small_case.freq_cycles_per_px, quick_start=True) == (
        measure_geometry(small, 1.0, small_case.freq_cycles_per_px))
