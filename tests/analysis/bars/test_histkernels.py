"""The histogram method's compiled kernels (``benchlab/analysis/_histkernels.c``, issue 9: 100 us
per 2,000-px ROI) read what the numpy reference reads: kernel by kernel, end to end on random
ROIs of any shape, dtype and extreme, and on the pinned readings; the numpy path runs when the
module is absent; bad buffers are refused, not read out of bounds.

Tests that call the compiled module need it built (``pip install -e .`` does; CI sets
``BENCHLAB_REQUIRE_KERNELS=1`` so a build that silently failed is an error there)."""

from __future__ import annotations

import importlib
import math
import os
import sys
import types
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from test_hist_speed_pinned import _CASES, _DATA, _same, extreme_rois, reading

from benchlab.analysis.bars import geometry as bargeometry
from benchlab.analysis.bars import histogram, kernels
from benchlab.analysis.bars.estimators import estimate_modulation
from benchlab.analysis.bars.roi import prepare_roi
from benchlab.benchmarks.bars import format_speed
from benchlab.synthetic.bars import BarCase, render

COMPILED = kernels.compiled
needs_compiled = pytest.mark.skipif(
    COMPILED is None and os.environ.get("BENCHLAB_REQUIRE_KERNELS", "") in ("", "0"),
    reason="compiled kernels not built (pip install -e . builds them)",
)
#: The paths agree to this (bit for bit on the machine the kernels were checked on; the
#: tolerance only absorbs a libm or numpy loop that rounds differently elsewhere).
REL_TOL = 1e-12


@pytest.fixture
def numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(kernels, "compiled", None)


def _close(a: object, b: object) -> bool:
    if isinstance(a, complex) and isinstance(b, complex):
        return _close(a.real, b.real) and _close(a.imag, b.imag)
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=1e-300)
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b, strict=True))
    return a == b


def _both_paths(fn, monkeypatch: pytest.MonkeyPatch):  # type: ignore[no-untyped-def]
    """``fn()`` on the compiled path, then on the numpy path."""
    assert COMPILED is not None, "compiled kernels not built"
    monkeypatch.setattr(kernels, "compiled", COMPILED)
    compiled = fn()
    monkeypatch.setattr(kernels, "compiled", None)
    reference = fn()
    monkeypatch.setattr(kernels, "compiled", COMPILED)
    return compiled, reference


def _result_tuple(roi: np.ndarray, freq: float | None, orientation: str | None = None):  # type: ignore[no-untyped-def]
    r = estimate_modulation(roi, estimator="histogram", freq_cycles_per_px=freq,
                            orientation=orientation)
    return (r.modulation, r.resolved, r.interval, r.dark, r.bright, r.warnings,
            r.diagnostics.noise_sigma)


@st.composite
def rois(draw: st.DrawFn) -> tuple[np.ndarray, float]:
    """A bar pattern (any angle, period, phase, duty, shading) or an extreme (flat, all-zero,
    saturated, noise only), 1x1 to 200x200, as float64, uint8 or uint16, and a frequency."""
    rows = draw(st.integers(1, 200))
    cols = draw(st.integers(1, 200))
    seed = draw(st.integers(0, 2**32 - 1))
    kind = draw(st.sampled_from(["bars", "bars", "bars", "flat", "zero", "saturated", "noise"]))
    dtype = draw(st.sampled_from([np.float64, np.uint8, np.uint16]))
    period = draw(st.floats(2.2, 40.0))
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:rows, 0:cols].astype(np.float64)
    if kind == "bars":
        theta = draw(st.floats(0.0, math.pi))
        u = x * math.cos(theta) + y * math.sin(theta)
        wave = np.cos(2 * math.pi * u / period + draw(st.floats(0.0, 6.3)))
        wave = np.where(wave > draw(st.floats(-0.3, 0.3)), 1.0, 0.0)
        img = 40 + 150 * wave * (1 + draw(st.floats(0.0, 0.3)) * x / max(cols, 1))
        img += rng.normal(0, draw(st.floats(0.0, 20.0)), img.shape)
    elif kind == "flat":
        img = np.full((rows, cols), 77.0)
    elif kind == "zero":
        img = np.zeros((rows, cols))
    elif kind == "saturated":
        img = np.full((rows, cols), 255.0 if dtype != np.uint16 else 65535.0)
    else:
        img = rng.normal(100, 5, (rows, cols))
    if dtype == np.uint8:
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    elif dtype == np.uint16:
        img = np.clip(np.rint(img * 16), 0, 65535).astype(np.uint16)
    return img, 1.0 / period


@needs_compiled
@settings(max_examples=150, deadline=None)
@given(case=rois(), orientation=st.sampled_from([None, None, "horizontal", "vertical"]))
def test_compiled_and_numpy_paths_read_the_same(
    case: tuple[np.ndarray, float], orientation: str | None
) -> None:
    roi, freq = case
    with pytest.MonkeyPatch.context() as mp:
        compiled, reference = _both_paths(lambda: _result_tuple(roi, freq, orientation), mp)
    assert _close(compiled, reference), (compiled, reference)


@needs_compiled
@settings(max_examples=80, deadline=None)
@given(case=rois())
def test_quick_fundamental_kernel_matches_numpy(case: tuple[np.ndarray, float]) -> None:
    """Every field of the bars' fundamental (or the same refusal) on both paths."""
    roi, freq = case
    img = roi.astype(np.float64)
    with pytest.MonkeyPatch.context() as mp:
        compiled, reference = _both_paths(
            lambda: bargeometry.quick_fundamental(img, None, freq, None, None), mp)
    assert (compiled is None) == (reference is None)
    if compiled is not None:
        assert reference is not None
        assert _close(tuple(compiled), tuple(reference)), (compiled, reference)


@needs_compiled
@settings(max_examples=80, deadline=None)
@given(case=rois(), theta=st.floats(-1.6, 1.6), phase=st.floats(-0.5, 0.5))
def test_phase_selection_kernel_matches_numpy(
    case: tuple[np.ndarray, float], theta: float, phase: float
) -> None:
    """Noise, significance and the selected bar-centre pixels (in order) of an arbitrary
    geometry: the compiled pass and the numpy phase bins, scatter and windows."""
    roi, freq = case
    prep = prepare_roi(roi, freq_cycles_per_px=freq)
    with pytest.MonkeyPatch.context() as mp:
        compiled, reference = _both_paths(
            lambda: histogram._phases_at(prep, theta, freq, phase, 3.0), mp)
    assert _close(compiled.noise, reference.noise)
    assert _close(compiled.z, reference.z)
    if prep.n_pixels < 8 * histogram.NOISE_BINS:
        assert compiled.chosen is None  # numpy on small ROIs: both paths are the same code
        return
    assert compiled.chosen is not None and reference.bins is not None
    values, vmin, vmax = compiled.chosen
    img = prep.pixels
    want = img[reference.centres("near")]
    if want.size < histogram.MIN_CENTRE_PIXELS:
        want = img[reference.centres("wide")]
        if want.size < histogram.MIN_CENTRE_PIXELS:
            want = img[reference.centres("all")]
    assert np.array_equal(values, want)
    if want.size:
        assert (vmin, vmax) == (float(want.min()), float(want.max()))


@needs_compiled
@settings(max_examples=400, deadline=None)
@given(
    y=arrays(np.float64, st.integers(0, 120), elements=st.sampled_from(
        [0.0, 0.0, 1.0, 2.0, 3.0, 5.0, 8.0, 40.0])) | arrays(
        np.float64, st.integers(0, 120), elements=st.floats(0.0, 50.0)),
    smooth_it=st.booleans(),
)
def test_modes_kernel_matches_find_peaks_and_massive_modes(
    y: np.ndarray, smooth_it: bool
) -> None:
    """Peaks (flat tops and plateaus at the ends included), the merge of light basins and
    the short path's valley: as ``_find_peaks`` then ``_massive_modes``."""
    assert COMPILED is not None
    smooth = np.convolve(y, [0.25, 0.5, 0.25]) if smooth_it and y.size else y
    peaks, _ = histogram._find_peaks(smooth, 0.0) if smooth.size >= 2 else ([], [])
    want = (*histogram._massive_modes(smooth, peaks), len(peaks) >= 2)
    assert COMPILED.modes(smooth, histogram.MIN_MODE_FRACTION) == want


@needs_compiled
def test_modes_kernel_refuses_bad_buffers() -> None:
    assert COMPILED is not None
    with pytest.raises(TypeError):
        COMPILED.modes(np.ones(10, np.float32), 0.04)
    with pytest.raises(TypeError):
        COMPILED.modes(np.ones((2, 10)), 0.04)
    with pytest.raises(ValueError):
        COMPILED.modes(np.ones(20)[::2], 0.04)  # not contiguous: numpy would copy first


@needs_compiled
@pytest.mark.parametrize("layout", ["crop", "transposed", "reversed", "every-other"])
def test_kernels_read_strided_views_as_copies(layout: str) -> None:
    """Any strides: a view gives what its contiguous copy gives."""
    assert COMPILED is not None
    bar = BarCase(shape=(90, 110), px_per_period=7.0, angle_deg=31.0, noise_sigma=2.0)
    base = render(bar, np.random.default_rng(3)).astype(np.float64)
    view = {"crop": base[5:75, 7:101], "transposed": base.T, "reversed": base[::-1, ::-1],
            "every-other": base[::2, ::1]}[layout]
    copy = np.ascontiguousarray(view)
    args = (1 / 7.0, 3.0, 0.05, 3, 32, kernels.FUSED_COMPLEX)
    got = COMPILED.quick_core(view, *args)
    assert got is not None and got == COMPILED.quick_core(copy, *args)
    select = (4.0, 1.5, 300.0, 200.0, histogram._NEAR_BYTES, histogram._WIDE_BYTES, 48)
    out_view, out_copy = np.empty(view.size), np.empty(view.size)
    got_sel = COMPILED.phase_select(view, *select, out_view)
    assert got_sel == COMPILED.phase_select(copy, *select, out_copy)
    assert 0 < got_sel[1] < view.size
    assert np.array_equal(out_view[: got_sel[1]], out_copy[: got_sel[1]])


@needs_compiled
def test_kernels_refuse_bad_buffers() -> None:
    """Wrong dtype, dimensions, size or output: an exception, never a read out of bounds."""
    assert COMPILED is not None
    img = np.ones((20, 20))
    args = (0.1, 3.0, 0.05, 3, 32, True)
    with pytest.raises(TypeError):
        COMPILED.quick_core(img.astype(np.float32), *args)
    with pytest.raises(TypeError):
        COMPILED.quick_core(np.ones(400), *args)
    with pytest.raises(TypeError):
        COMPILED.quick_core(np.ones((2, 20, 20)), *args)
    with pytest.raises(ValueError):
        COMPILED.quick_core(np.ones((7, 50)), *args)
    with pytest.raises(ValueError):
        COMPILED.quick_core(np.ones((0, 50)), *args)
    near, wide = histogram._NEAR_BYTES, histogram._WIDE_BYTES
    with pytest.raises(ValueError):
        COMPILED.phase_select(img, 1.0, 1.0, 100.0, -1.0, near, wide, 48, np.empty(399))
    with pytest.raises(ValueError):
        COMPILED.phase_select(img, 1.0, 1.0, 100.0, -1.0, near[:31], wide, 48, np.empty(400))
    with pytest.raises(ValueError):  # read-only output
        out = np.empty(400)
        out.setflags(write=False)
        COMPILED.phase_select(img, 1.0, 1.0, 100.0, -1.0, near, wide, 48, out)
    with pytest.raises(ValueError):
        COMPILED.phase_select(img, 1.0, 1.0, 100.0, -1.0, near, wide, 48, np.empty(400, np.int32))


@needs_compiled
def test_flat_and_constant_rois_on_the_kernels(monkeypatch: pytest.MonkeyPatch) -> None:
    """Flat, all-zero and saturated pixels: a zero fundamental and power (refused as bars by
    the noise test after it, on both paths alike), a zero scatter - no division by zero."""
    assert COMPILED is not None
    for value in (0.0, 77.0, 65535.0):
        img = np.full((40, 50), value)
        core = COMPILED.quick_core(img, 0.125, 3.0, 0.05, 3, 32, kernels.FUSED_COMPLEX)
        assert core is not None and core[2:] == (0.0, 0.0, 0.0)
        compiled, reference = _both_paths(
            lambda img=img: bargeometry.quick_fundamental(img, 1.0, 0.125, None, None),
            monkeypatch)
        assert compiled is None and reference is None  # not clear of the noise
        out = np.empty(img.size)
        scatter, m, vmin, vmax = COMPILED.phase_select(
            img, 4.0, 0.0, 300.0, 80.0, histogram._NEAR_BYTES, histogram._WIDE_BYTES, 48, out)
        assert scatter == 0.0 and m > 0 and vmin == vmax == value


@needs_compiled
def test_compiled_path_is_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    """With the module present the numpy passes it replaces do not run."""
    def forbidden(*_: object, **__: object) -> None:
        raise AssertionError("numpy pass ran on the compiled path")

    monkeypatch.setattr(bargeometry, "detrend", forbidden)
    monkeypatch.setattr(histogram, "_phase_bins", forbidden)
    monkeypatch.setattr(histogram, "_find_peaks", forbidden)
    for angle, orientation in ((20.0, None), (0.0, "horizontal")):
        bar = BarCase(shape=(40, 50), px_per_period=8.0, angle_deg=angle, noise_sigma=2.0)
        result = estimate_modulation(render(bar, np.random.default_rng(1)),
                                     estimator="histogram", freq_cycles_per_px=0.125,
                                     orientation=orientation)
        assert result.resolved


def test_numpy_path_runs_without_the_module(
    numpy_path: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without the module the numpy passes run (and read the bars)."""
    calls: list[str] = []
    detrend, phase_bins = bargeometry.detrend, histogram._phase_bins
    monkeypatch.setattr(bargeometry, "detrend",
                        lambda *a, **k: calls.append("detrend") or detrend(*a, **k))
    monkeypatch.setattr(histogram, "_phase_bins",
                        lambda *a, **k: calls.append("bins") or phase_bins(*a, **k))
    bar = BarCase(shape=(40, 50), px_per_period=8.0, angle_deg=20.0, noise_sigma=2.0)
    result = estimate_modulation(render(bar, np.random.default_rng(1)), estimator="histogram",
                                 freq_cycles_per_px=0.125)
    assert result.resolved and calls == ["detrend", "bins"]
    assert kernels.describe() == "numpy fallback"
    assert "histogram path: numpy fallback" in format_speed(("histogram",), ((20, 20),))


def test_loader_falls_back_when_the_module_is_absent_or_disabled(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An absent module (no compiler at install) or ``BENCHLAB_NUMPY_KERNELS=1``: no error,
    the numpy path; otherwise the module when it is built."""
    import benchlab.analysis as package

    try:
        # Absent: neither imported nor importable.
        monkeypatch.delattr(package, "_histkernels", raising=False)
        monkeypatch.setitem(sys.modules, "benchlab.analysis.bars._histkernels", None)
        assert importlib.reload(kernels).compiled is None
        monkeypatch.delitem(sys.modules, "benchlab.analysis.bars._histkernels")
        monkeypatch.setenv(kernels.DISABLE_ENV, "1")
        assert importlib.reload(kernels).compiled is None
        assert kernels.describe() == "numpy fallback"
        monkeypatch.setenv(kernels.DISABLE_ENV, "0")
        assert (importlib.reload(kernels).compiled is None) == (COMPILED is None)
        # A stale build (another version of the C source): a warning, the numpy path.
        stale = types.ModuleType("benchlab.analysis.bars._histkernels")
        stale.VERSION = kernels.VERSION + 1  # type: ignore[attr-defined]
        stale.__file__ = "/old/_histkernels.so"
        monkeypatch.delattr(package, "_histkernels", raising=False)
        monkeypatch.setitem(sys.modules, "benchlab.analysis.bars._histkernels", stale)
        with pytest.warns(RuntimeWarning, match="stale compiled kernels.*rebuild"):
            assert importlib.reload(kernels).compiled is None
    finally:
        monkeypatch.undo()
        importlib.reload(kernels)
        kernels.compiled = COMPILED


def test_fused_flag_says_how_numpy_multiplies_complexes() -> None:
    """The kernels round complex products as numpy does on this CPU."""
    a, b = complex(1 + 2**-27, 1 + 2**-26), complex(1 + 2**-28, 1 - 2**-27)
    exact = Fraction  # a fused multiply-add rounds the exact a*b + c once
    fused = complex(float(exact(a.real) * exact(b.real) - exact(a.imag * b.imag)),
                    float(exact(a.real) * exact(b.imag) + exact(a.imag * b.real)))
    assert fused != a * b  # the probe tells the two apart
    numpy_product = complex((np.array([a]) * np.array([b]))[0])
    assert numpy_product == (fused if kernels.FUSED_COMPLEX else a * b)


@pytest.mark.parametrize("path", ["compiled", "numpy"])
def test_pinned_readings_on_both_paths(path: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """tests/test_hist_speed_pinned.py's histogram readings on each path."""
    if path == "compiled":
        if COMPILED is None and os.environ.get("BENCHLAB_REQUIRE_KERNELS", "") in ("", "0"):
            pytest.skip("compiled kernels not built (pip install -e . builds them)")
        assert COMPILED is not None, "compiled kernels not built"
    monkeypatch.setattr(kernels, "compiled", COMPILED if path == "compiled" else None)
    for row in _DATA["benchmark"]:
        index = int(row["case"])
        case = _CASES[index]
        roi = render(case.bar, np.random.default_rng(10_000 + index))
        got = reading(roi, "histogram", case.bar.freq_cycles_per_px, row["orientation"])
        assert _same(got, row["histogram"]), (index, got, row["histogram"])
    for key, (roi, freq, orientation) in extreme_rois().items():
        got = reading(roi, "histogram", freq, orientation)
        assert _same(got, _DATA["extremes"][key]["histogram"]), (key, got)


@needs_compiled
def test_kernels_refuse_non_finite_histograms_unaligned_and_oversized_images() -> None:
    """Review: -inf beside NaN walked modes() before its arrays (heap write); unaligned doubles
    are undefined behaviour; the plane fit's integer denominators overflow past ~2^20 px."""
    assert COMPILED is not None
    with pytest.raises(ValueError, match="finite"):
        COMPILED.modes(np.array([0, 1, 0, -np.inf, 0, 5, 0, np.nan, 0, 5, 0.0]), 0.04)
    img = np.random.default_rng(1).normal(100, 5, (20, 30))
    raw = np.frombuffer(b"\0" + img.tobytes(), np.float64, offset=1).reshape(img.shape)
    assert not raw.flags.aligned
    with pytest.raises(ValueError, match="aligned"):
        COMPILED.quick_core(raw, 0.1, 2.0, 1e9, 1, 10**9, True)
    with pytest.raises(ValueError, match="4096"):
        COMPILED.quick_core(np.zeros((8, 5000)), 0.1, 2.0, 1e9, 1, 10**9, True)


def test_unaligned_roi_reads_as_its_aligned_copy() -> None:
    """An unaligned ROI takes the numpy path (not the kernels) and reads the same."""
    case = BarCase(px_per_period=7.0, angle_deg=30.0, noise_sigma=1.0)
    img = np.asarray(render(case, np.random.default_rng(3)), dtype=np.float64)
    raw = np.frombuffer(b"\0" + img.tobytes(), np.float64, offset=1).reshape(img.shape)
    a = estimate_modulation(raw, estimator="histogram", freq_cycles_per_px=1 / 7)
    b = estimate_modulation(img, estimator="histogram", freq_cycles_per_px=1 / 7)
    assert a.resolved and a.modulation == b.modulation and a.interval == b.interval
