"""The chart reading (``knownbars``) through PSFs that are not Gaussian: defocus read within its
interval, contrast reversal read with its sign, a misfit widening the interval, Gaussian readings
unchanged; the synthetic renderer's bad input and the disc spectrum."""

from __future__ import annotations

import math

import numpy as np
import pytest

import benchlab.analysis.bars.knownbars as kb
from benchlab.synthetic.threebar import PsfSpec, render_three_bars


def _read(s: object, bar_width_px: float | None = None) -> kb.ModulationResult:
    return kb.read_three_bars(s.roi, centre_rc=s.centre_rc,  # type: ignore[attr-defined]
                              bar_width_px=bar_width_px or s.bar_width_px,  # type: ignore[attr-defined]
                              theta_deg=s.theta_deg)  # type: ignore[attr-defined]


@pytest.mark.parametrize("theta", [0.0, 17.0])
def test_defocus_disc_on_wide_bars_is_read_within_001_and_covered(theta: float) -> None:
    """A uniform disc of radius 1 px on 2.5 px bars: a Gaussian family read 0.564 against 0.581
    with +-0.007; the disc family reads it within 0.01, its interval holding the truth."""
    s = render_three_bars(2.5, theta, PsfSpec("disc", radius_px=1.0), bits=16)
    r = _read(s)
    assert r.resolved
    assert abs(r.modulation - s.truth_modulation) <= 0.01
    assert r.interval[0] <= s.truth_modulation <= r.interval[1]


@pytest.mark.parametrize(("w", "theta"), [(1.25, 0.0), (1.25, 33.0)])
def test_contrast_reversal_is_read_negative_with_the_warning(w: float, theta: float) -> None:
    """A disc of radius 1.6 px on 1.25 px bars reverses the contrast (truth < 0): the
    reading is negative, within 0.015, and says so instead of claiming a resolved reading."""
    s = render_three_bars(w, theta, PsfSpec("disc", radius_px=1.6), bits=16)
    assert s.truth_modulation < -0.015
    r = _read(s)
    assert r.modulation < 0
    assert abs(r.modulation - s.truth_modulation) <= 0.015
    assert any("contrast reversed (spurious resolution)" in x for x in r.warnings)
    assert r.interval[0] < r.modulation < r.interval[1] and r.interval[0] < 0


@pytest.mark.parametrize(("w", "theta"), [(1.1, 17.0), (1.15, 25.0)])
def test_the_known_polarity_keeps_a_reversal_from_passing_for_a_negative_target(
    w: float, theta: float
) -> None:
    """On the smallest sets a reversed dark-bar set fits about as well as a blurred negative
    target; told the bars are dark, the reading is the reversal, within 0.01."""
    s = render_three_bars(w, theta, PsfSpec("disc", radius_px=1.6), bits=16)
    assert s.truth_modulation < -0.04
    r = kb.read_three_bars(s.roi, centre_rc=s.centre_rc, bar_width_px=w, theta_deg=theta,
                           dark_bars=True)
    assert abs(r.modulation - s.truth_modulation) <= 0.01
    assert any("contrast reversed" in x for x in r.warnings)
    assert r.dark is not None and r.bright is not None and r.dark > r.bright


def test_a_defocus_size_floor_keeps_the_interval_honest(monkeypatch: pytest.MonkeyPatch) -> None:
    """A disc of 1.6 px on 1.25 px bars on a pixel axis: the separable model's best disc size
    is biased (read 0.010 off); the size floor widens the interval over the truth, without it
    the interval (+-0.004) misses."""
    s = render_three_bars(1.25, 0.0, PsfSpec("disc", radius_px=1.6), bits=12)

    def read() -> kb.ModulationResult:
        return kb.read_three_bars(s.roi, centre_rc=s.centre_rc, bar_width_px=1.25,
                                  theta_deg=0.0, dark_bars=True)

    assert read().interval[0] <= s.truth_modulation <= read().interval[1]
    monkeypatch.setattr(kb, "DISC_SIGMA_FLOOR_PX", 0.0)
    assert not read().interval[0] <= s.truth_modulation <= read().interval[1]


def test_a_misfit_widens_the_interval(monkeypatch: pytest.MonkeyPatch) -> None:
    """Bars 4 % narrower in the model than in the image leave structure in the residuals: the
    interval widens (by a term that does not shrink with pixel count) and says why."""
    s = render_three_bars(2.5, 0.0, PsfSpec("gauss", sigma_px=0.6), bits=12)
    with_rule = _read(s, bar_width_px=2.4)
    assert any("structure beyond the noise" in x for x in with_rule.warnings)
    assert with_rule.interval[0] <= s.truth_modulation <= with_rule.interval[1]
    monkeypatch.setattr(kb, "MISFIT_Z", math.inf)
    without = _read(s, bar_width_px=2.4)
    assert without.modulation == pytest.approx(with_rule.modulation, abs=1e-12)
    assert with_rule.uncertainty > 2.0 * without.uncertainty


# (sigma, w, theta, noise seed or None) and the reading before the defocus family was added
GAUSS_BEFORE = [
    ((0.8, 1.6, 17.0, None), 0.18833),
    ((0.6, 2.5, 33.0, None), 0.52874),
    ((0.7, 1.4, 8.0, 3), 0.17825),
    ((0.5, 2.0, 0.0, 4), 0.50197),
    ((0.9, 3.0, 25.0, 5), 0.46568),
]


@pytest.mark.parametrize(("case", "before"), GAUSS_BEFORE)
def test_gaussian_readings_are_unchanged(
    case: tuple[float, float, float, int | None], before: float
) -> None:
    """Gaussian PSFs read as before the defocus shapes (within 0.002) and near their truth: a
    shape pays a price in chi-square before it is chosen."""
    sigma, w, theta, seed = case
    rng = np.random.default_rng(seed) if seed is not None else None
    s = render_three_bars(w, theta, PsfSpec("gauss", sigma_px=sigma), rng=rng,
                          full_well_e=20000.0 if seed else None, read_noise_e=10.0, bits=12)
    r = _read(s)
    assert r.modulation == pytest.approx(before, abs=0.002)
    assert r.modulation == pytest.approx(s.truth_modulation, abs=0.005)


def test_disc_gain_is_the_line_spread_spectrum() -> None:
    """``2 J1(x) / x`` against the Fourier integral of the disc's line spread."""
    radius, du = 1.3, 1e-4
    u = np.arange(-radius, radius, du) + 0.5 * du
    lsf = 2.0 * np.sqrt(radius**2 - u**2) / (math.pi * radius**2)
    freqs = np.array([0.0, 0.1, 0.3, 0.5, 0.9])
    numeric = (lsf[None, :] * np.cos(2 * math.pi * freqs[:, None] * u[None, :])).sum(1) * du
    np.testing.assert_allclose(kb.disc_gain([radius], freqs)[0], numeric, atol=2e-6)
    assert kb.disc_gain([radius], [0.5])[0, 0] < 0  # past the first zero: reversal


@pytest.mark.parametrize("kwargs", [
    {"psf": PsfSpec("gauss", sigma_px=0.5), "bar_width_px": 0.2},
    {"psf": PsfSpec("gauss", sigma_px=0.5), "bar_width_px": 2.0, "bits": 4},
    {"psf": PsfSpec("gauss", sigma_px=0.5), "bar_width_px": 2.0, "full_well_e": 1000.0},
])
def test_renderer_bad_input_is_a_value_error(kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError):
        render_three_bars(theta_deg=0.0, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="PSF kind"):
        PsfSpec("airy")
