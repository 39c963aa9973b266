"""Coltman's forward series evaluated in blocks of harmonics keeps the plain loop's bits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.mtf.coltman import mtf_to_ctf
from benchlab.analysis.mtf.simulated_ctf import _extended, _harmonics_needed
from benchlab.protocols.mtf.curves import load_curves


def _plain(mtf_at, freqs, max_harmonic):  # type: ignore[no-untyped-def]
    """The series one harmonic at a time, as it was written before (issue 39)."""
    f = np.asarray(freqs, dtype=np.float64)
    total = np.zeros_like(f)
    for k in range(1, max_harmonic + 1, 2):
        total += (-1) ** ((k - 1) // 2) * np.asarray(mtf_at(k * f)) / k
    return 4 / math.pi * total


def test_simulated_curves_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    curves = load_curves(None)
    assert len(curves) >= 8
    for curve in curves:
        mtf_at, _, support = _extended(curve)
        for grid in (np.array([rng.uniform(1.0, 300.0)]),
                     np.sort(rng.uniform(1.0, 400.0, 37))):
            k = _harmonics_needed(support, grid)
            assert mtf_to_ctf(mtf_at, grid, k).tobytes() == _plain(mtf_at, grid, k).tobytes()


@pytest.mark.parametrize("max_harmonic", [1, 3, 101, 20001])
def test_many_blocks_and_shapes(max_harmonic: int) -> None:
    def gauss(x: np.ndarray) -> np.ndarray:
        return np.exp(-(np.asarray(x) / 60.0) ** 2)

    grid = np.linspace(0.5, 300.0, 257)  # 257 x 10,001 terms: several blocks
    assert mtf_to_ctf(gauss, grid, max_harmonic).tobytes() == _plain(
        gauss, grid, max_harmonic).tobytes()
    scalar = mtf_to_ctf(gauss, 7.0, max_harmonic)
    assert scalar.shape == ()
    assert float(scalar) == float(_plain(gauss, 7.0, max_harmonic))


def test_square_wave_of_a_perfect_lens_is_one() -> None:
    # MTF = 1 up to 1,000 lp/mm: 4/pi (1 - 1/3 + 1/5 - ...) -> 1 as the series lengthens
    ctf = mtf_to_ctf(lambda x: np.where(np.asarray(x) <= 1000.0, 1.0, 0.0), [1.0], 999)
    assert ctf[0] == pytest.approx(1.0, abs=2e-3)
