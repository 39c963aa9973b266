"""The known-bar fit's Gaussian gains skip the exponentials that underflow, bit for bit: the
re-analysis of a session must give byte-identical CSVs whatever the speed-up."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.bars import knownbars
from benchlab.analysis.bars.knownbars import gaussian_gain


@pytest.mark.parametrize("seed", range(6))
def test_gaussian_gain_is_the_whole_exponential_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.choice([256, 1024, 2048, 16384]))
    freqs2 = np.fft.rfftfreq(n, rng.uniform(0.005, 0.03)) ** 2
    sigmas = np.concatenate([[0.0], rng.uniform(0.0, 4.0, 60)])
    share = rng.choice([0.0, 0.5, 1.0], sigmas.size)
    rates = (-2.0 * math.pi**2) * (sigmas * sigmas * (1.0 - share))
    whole = np.exp(np.outer(rates, freqs2))
    assert gaussian_gain(rates, freqs2).tobytes() == whole.tobytes()
    # and it skipped work: wide blurs vanish long before the last column
    assert (whole == 0.0).mean() > 0.1
    # rows stopped early (a defocus row's cutoff): the same values before, 0 from there on
    stop = rng.integers(0, freqs2.size + 1, sigmas.size)
    cut = gaussian_gain(rates, freqs2, stop)
    before = np.arange(freqs2.size)[None, :] < stop[:, None]
    assert cut[before].tobytes() == whole[before].tobytes()
    assert not cut[~before].any()


def test_the_tabulated_patterns_are_those_of_the_whole_exponential(
        monkeypatch: pytest.MonkeyPatch) -> None:
    w, theta = 1.7, 0.3
    u = np.random.default_rng(3).uniform(-3.5 * w, 3.5 * w, 400)
    blurred = knownbars._Blurred(u, [(c - 0.5 * w, c + 0.5 * w) for c in (-2 * w, 0, 2 * w)],
                                 theta, 1.7)
    sigmas = 1.7 * np.linspace(0.0, 1.0, 32) ** 2
    shares = np.r_[np.zeros(26), np.full(6, 0.5)]
    fast = blurred.tables(sigmas, shares)
    def whole(rates: np.ndarray, freqs2: np.ndarray, stop: np.ndarray | None = None
              ) -> np.ndarray:
        gain = np.exp(np.outer(rates, freqs2))
        if stop is not None:  # the columns the caller needs no value of: 0
            gain[np.arange(freqs2.size)[None, :] >= stop[:, None]] = 0.0
        return gain

    monkeypatch.setattr(knownbars, "gaussian_gain", whole)
    assert blurred.tables(sigmas, shares).tobytes() == fast.tobytes()
