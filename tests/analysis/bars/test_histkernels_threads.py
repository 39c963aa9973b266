"""The compiled histogram kernels beside other threads and other memory layouts: they release
the GIL on large inputs (a 2048 x 2048 ROI held it ~30 ms, stalling the TUI and the acquisition
thread) and keep it on small ones; calls in several threads at once read what one thread reads;
a Fortran-order, transposed or reversed ROI reads bit for bit what its C-order copy reads, on
both paths."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_histkernels import COMPILED, _both_paths, _result_tuple, needs_compiled, rois

from benchlab.analysis.bars import geometry as bargeometry
from benchlab.analysis.bars import histogram, kernels
from benchlab.analysis.bars.roi import prepare_roi

QUICK_ARGS = (1 / 7.0, 3.0, 0.05, 3, 32)
#: Iterations of the other thread that show it ran while a kernel did (it makes none while
#: the kernel holds the GIL).
MIN_PROGRESS = 3


@contextmanager
def _other_thread() -> Iterator[list[int]]:
    """A Python thread counting loop iterations (a sleep of 0.5 ms each, which lets this
    thread take the GIL back at once) while the body runs. The switch interval is made long:
    this thread then holds the GIL except where it releases it, so the count moves only
    while a kernel has released it - a deterministic 0 when it has not."""
    count = [0]
    stop, started = threading.Event(), threading.Event()

    def spin() -> None:
        started.set()
        while not stop.is_set():
            count[0] += 1
            time.sleep(0.0005)

    old = sys.getswitchinterval()
    sys.setswitchinterval(10.0)
    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    started.wait()
    try:
        yield count
    finally:
        stop.set()
        thread.join()
        sys.setswitchinterval(old)


def _progress_during(call: Callable[[], object], max_calls: int = 20) -> int:
    """The other thread's iterations while ``call()`` runs (repeated until it made
    ``MIN_PROGRESS``, at most ``max_calls`` times: a loaded machine may not run it at once)."""
    total = 0
    with _other_thread() as count:
        for _ in range(max_calls):
            before = count[0]
            call()
            total += count[0] - before
            if total >= MIN_PROGRESS:
                break
    return total


def _comb(n_bins: int) -> np.ndarray:
    """A histogram with a light peak every third bin beside two heavy ones: modes() merges
    thousands of basins (quadratic: tens of ms)."""
    y = np.tile([0.0, 1.0, 0.0], n_bins // 3)
    y[n_bins // 4] = y[3 * n_bins // 4] = float(n_bins)
    return y


@pytest.fixture(scope="module")
def large_roi() -> np.ndarray:
    rng = np.random.default_rng(5)
    x = np.arange(2048.0)
    bars = 60.0 * (np.cos(2 * np.pi * (x[None, :] + 0.3 * x[:, None]) / 7.0) > 0)
    return bars + rng.normal(100.0, 3.0, (2048, 2048))


def _phase_select(img: np.ndarray) -> tuple[float, int, float, float]:
    assert COMPILED is not None
    return COMPILED.phase_select(img, 4.0, 1.5, 300.0, 200.0, histogram._NEAR_BYTES,
                                 histogram._WIDE_BYTES, 48, np.empty(img.size))


@needs_compiled
@pytest.mark.parametrize("kernel", ["phase_select", "quick_core", "modes"])
def test_kernels_release_the_gil_on_large_inputs(kernel: str, large_roi: np.ndarray) -> None:
    """Another Python thread runs while a kernel reads a 2048 x 2048 ROI (or merges 4,000
    histogram basins); with the GIL held it makes no progress at all."""
    assert COMPILED is not None
    calls: dict[str, Callable[[], object]] = {
        "phase_select": lambda: _phase_select(large_roi),
        "quick_core": lambda: COMPILED.quick_core(large_roi, *QUICK_ARGS, kernels.FUSED_COMPLEX),
        "modes": lambda: COMPILED.modes(_comb(12_000), histogram.MIN_MODE_FRACTION),
    }
    assert _progress_during(calls[kernel]) >= MIN_PROGRESS


@needs_compiled
def test_kernels_keep_the_gil_on_small_inputs(large_roi: np.ndarray) -> None:
    """Below the thresholds (tens of microseconds) the GIL stays held: taking it back from a
    busy thread could cost a switch interval."""
    assert COMPILED is not None
    side = int(COMPILED.RELEASE_MIN_PIXELS**0.5) - 1
    small = np.ascontiguousarray(large_roi[:side, :side])
    assert _progress_during(lambda: _phase_select(small), max_calls=3) == 0
    assert _progress_during(
        lambda: COMPILED.quick_core(small, *QUICK_ARGS, kernels.FUSED_COMPLEX), 3) == 0
    hist = _comb(COMPILED.RELEASE_MIN_BINS - 3)
    assert _progress_during(lambda: COMPILED.modes(hist, 0.04), max_calls=3) == 0


@needs_compiled
def test_concurrent_calls_read_what_one_thread_reads(large_roi: np.ndarray) -> None:
    """Calls in two threads at once (the GIL released: they overlap) give the single-threaded
    results: no shared scratch memory (the residual's cache is taken, not shared)."""
    assert COMPILED is not None
    images = [np.ascontiguousarray(large_roi[:1024, :1536]), large_roi[512:, 300:1800:2]]
    fused = kernels.FUSED_COMPLEX

    def both(img: np.ndarray) -> tuple[object, ...]:
        assert COMPILED is not None
        return COMPILED.quick_core(img, *QUICK_ARGS, fused), _phase_select(img)

    alone = [both(img) for img in images]
    got: list[list[tuple[object, ...]]] = [[], []]

    def work(i: int) -> None:
        for _ in range(3):
            got[i].append(both(images[i]))

    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert got == [[alone[0]] * 3, [alone[1]] * 3]


@needs_compiled
def test_large_roi_reads_the_same_on_both_paths(monkeypatch: pytest.MonkeyPatch) -> None:
    """Above the threshold (the GIL released) the compiled path still reads what numpy reads,
    bit for bit."""
    rng = np.random.default_rng(11)
    x = np.arange(400.0)
    roi = 80.0 * (np.cos(2 * np.pi * (x[None, :] * 0.9 + 0.4 * x[:, None]) / 9.0) > 0)
    roi = np.rint(roi + rng.normal(60.0, 4.0, (400, 400))).astype(np.uint16)
    assert roi.size >= 2 * kernels.compiled.RELEASE_MIN_PIXELS  # type: ignore[union-attr]
    compiled, reference = _both_paths(lambda: _result_tuple(roi, 1 / 9.0 * 0.98), monkeypatch)
    assert compiled == reference and compiled[1]


def _layout(img: np.ndarray, layout: str) -> np.ndarray:
    """The same pixels in another memory layout."""
    views = {
        "fortran": lambda: np.asfortranarray(img),
        "transposed": lambda: np.ascontiguousarray(img.T).T,
        "reversed": lambda: np.ascontiguousarray(img[::-1, ::-1])[::-1, ::-1],
        "fortran-crop": lambda: np.asfortranarray(np.pad(img, 3))[3:-3, 3:-3],
    }
    out = views[layout]()
    assert np.array_equal(out, img)
    return out


@needs_compiled
@settings(max_examples=60, deadline=None)
@given(case=rois(), layout=st.sampled_from(["fortran", "transposed", "reversed",
                                            "fortran-crop"]))
def test_any_layout_reads_as_its_c_order_copy_on_both_paths(
    case: tuple[np.ndarray, float], layout: str
) -> None:
    """The bars' fundamental and the histogram reading of a Fortran-order (transposed,
    reversed) ROI: bit for bit those of the C-order ROI, on the compiled and the numpy path
    (numpy summed a Fortran-order ROI in its memory order: 1e-15 apart)."""
    roi, freq = case
    img = np.ascontiguousarray(roi, dtype=np.float64)
    other = _layout(img, layout)
    def read(data: np.ndarray, mp: pytest.MonkeyPatch) -> tuple[object, object]:
        """(compiled, numpy) of the fundamental and of the reading."""
        quick = _both_paths(
            lambda: bargeometry.quick_fundamental(data, None, freq, None, None), mp)
        return quick, _both_paths(lambda: _result_tuple(data, freq), mp)

    with pytest.MonkeyPatch.context() as mp:
        assert read(other, mp) == read(img, mp)  # each path bit for bit


def test_prepared_pixels_are_row_major_and_views_are_not_copied() -> None:
    """prepare_roi reads a Fortran-order ROI through its C-order copy; a crop of a C-order
    frame (already row by row) is not copied."""
    frame = np.arange(30 * 40, dtype=np.float64).reshape(30, 40)
    assert prepare_roi(np.asfortranarray(frame)).pixels.flags.c_contiguous
    for view in (frame[5:25, 3:33], frame[:, ::2], frame[::3, 1:2], frame[2:3, :]):
        assert kernels.row_major(view) is view
    for layout in ("fortran", "transposed", "reversed", "fortran-crop"):
        other = _layout(frame, layout)
        assert kernels.row_major(other).flags.c_contiguous
        assert np.array_equal(kernels.row_major(other), frame)
