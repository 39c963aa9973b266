"""Forward view: the USAF 1951 scene and its truth values."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

from benchlab.analysis.chart.layout import ChartLayout, RadialLayout
from benchlab.drivers.sensor import DN12_PER_E, AcquisitionState, rate_for_dn8
from benchlab.scenes.optics import BlurProfile
from benchlab.scenes.usaf import UsafScene

H, W = 1024, 1280
THESIS_ELEMENTS = [(1, 5), (1, 6), (2, 1), (2, 2), (2, 3), (2, 4), (2, 5), (2, 6), (3, 1)]


def _state(**bench: object) -> AcquisitionState:
    return AcquisitionState(300.0, 1.0, 8, W, H, 0.0, 0, dict(bench))


def _dn8(rate: np.ndarray | float, exposure_ms: float = 300.0) -> np.ndarray:
    return np.asarray(rate) * exposure_ms * DN12_PER_E / 16.0


@pytest.fixture(scope="module")
def default_render() -> np.ndarray:
    return UsafScene().render(H, W)


def test_levels_disc_and_contract(default_render: np.ndarray) -> None:
    scene = UsafScene()
    img = scene(_state())
    assert img.shape == (H, W) and img.dtype == np.float64
    img[0, 0] = 1.0  # the caller gets its own copy; the cache is read-only
    assert not default_render.flags.writeable and default_render[0, 0] == 0.0
    cr, cc = RadialLayout().centre_rc
    # clear glass ~190 DN, outside the disc dark; the thesis's levels at 300 ms, unity gain
    assert _dn8(default_render[int(cr) - 150, int(cc)]) == pytest.approx(190.0, abs=1e-6)
    assert default_render[int(cr) - 300, int(cc)] < 1e-12
    assert default_render[20, 20] == 0.0
    assert scene.bright_rate == pytest.approx(float(rate_for_dn8(190.0, 300.0)))


@pytest.mark.parametrize("orientation", ["sagittal", "tangential"])
@pytest.mark.parametrize("group,element", [(1, 5), (2, 2)])
@pytest.mark.parametrize("smooth", [False, True])
def test_darkness_moments_give_bar_geometry_and_blur(
    smooth: bool, group: int, element: int, orientation: str
) -> None:
    """Across the bars, the darkness profile's area is 3 bars x bar length, its centre the set
    centre, and its variance that of three bars 2 widths apart plus the bar width, the blur and
    the pixel aperture: an exact check of scale, position and blur together."""
    scene = UsafScene()
    if smooth:  # bars ~6 px wide, 0.7-0.9 px blur: sampled moments equal continuous ones
        mag = 16.3 * scene.bar_group(group, element, "sagittal").bar_width_px / 6.0
        layout = ChartLayout(magnification=mag, element_centres_mm={(group, element): (0.0, 0.0)})
        scene = UsafScene(layout=layout, blur=BlurProfile.uniform(0.9, 0.7))
    render = scene.render(H, W)
    bars = scene.bar_group(group, element, orientation)  # type: ignore[arg-type]
    sig_r, sig_c = scene.sigmas_px(bars)
    w = bars.bar_width_px
    cr, cc = bars.centre_rc
    reach = 6 if smooth else 3  # the blur's reach, short of the element's other set
    along = int(2.5 * w) + reach + 1
    across = int(2.5 * w) + reach
    half_r, half_c = (along, across) if orientation == "sagittal" else (across, along)
    rows = slice(int(cr) - half_r, int(cr) + half_r + 1)
    cols = slice(int(cc) - half_c, int(cc) + half_c + 1)
    patch = render[rows, cols]
    darkness = (scene.bright_rate - patch) / (scene.bright_rate - scene.dark_rate)
    axis = 0 if orientation == "sagittal" else 1  # sum along the bars
    profile = darkness.sum(axis=axis)
    start = cols.start if orientation == "sagittal" else rows.start
    x = start + np.arange(profile.size)
    area = profile.sum()
    assert area == pytest.approx(3 * w * 5 * w, rel=1e-6)
    mean = (profile * x).sum() / area
    # Pixel sampling makes the discrete moments exact only for smooth profiles: a sharp
    # (default) blur leaves ~1e-3 px errors, a 0.7-0.9 px blur ~1e-9.
    tol = 1e-6 if smooth else 5e-3
    assert mean == pytest.approx(cc if orientation == "sagittal" else cr, abs=tol)
    var = (profile * (x - mean) ** 2).sum() / area
    sigma = sig_c if orientation == "sagittal" else sig_r
    expected_var = 8 * w**2 / 3 + w**2 / 12 + sigma**2 + 1 / 12
    assert var == pytest.approx(expected_var, abs=5 * tol * expected_var)


def test_truth_matches_pixels_where_bars_land_on_pixel_centres() -> None:
    """A layout whose G2E4 bars are exactly 2 px wide and centred on pixel centres: the noise-free
    render's pixels at the bar and space centres are the truth levels."""
    f = 2 ** (2 + 3 / 6)
    mag = 0.5 / (f * 2.0 * 0.0052)  # bar width = 2 px
    layout = ChartLayout(
        origin_rc=(500.0, 600.0), magnification=mag, element_centres_mm={(2, 4): (0, 0)}
    )
    scene = UsafScene(layout=layout, circles=RadialLayout(centre_rc=(500.0, 600.0)))
    img = scene.render(H, W)
    for orientation in ("sagittal", "tangential"):
        bars = scene.bar_group(2, 4, orientation)  # type: ignore[arg-type]
        r, c = (round(v) for v in bars.centre_rc)
        assert bars.centre_rc == (r, c)
        dark, bright = scene.truth_levels(2, 4, orientation)  # type: ignore[arg-type]
        if orientation == "sagittal":
            spaces = (img[r, c - 2], img[r, c + 2])
        else:
            spaces = (img[r - 2, c], img[r + 2, c])
        assert img[r, c] == pytest.approx(dark, rel=1e-9)
        assert np.mean(spaces) == pytest.approx(bright, rel=1e-9)
        measured = (np.mean(spaces) - img[r, c]) / (np.mean(spaces) + img[r, c])
        assert scene.truth_modulation(2, 4, orientation) == pytest.approx(measured, rel=1e-9)  # type: ignore[arg-type]


def test_truth_modulation_matches_brute_force_profile() -> None:
    """Independent check: 3 bars on a fine grid, Gaussian blur, 1-px aperture, Eq. 2.9."""
    sigma = 0.5
    scene = UsafScene(blur=BlurProfile.uniform(sigma, sigma))
    bars = scene.bar_group(2, 2, "sagittal")
    w = bars.bar_width_px
    fine = 400
    x = (np.arange(-30 * fine, 30 * fine) + 0.5) / fine  # px, relative to the set centre
    dark_frac = sum(
        ((x >= k * 2 * w - w / 2) & (x < k * 2 * w + w / 2)).astype(float) for k in (-1, 0, 1)
    )
    blurred = gaussian_filter1d(dark_frac, sigma * fine, mode="constant", truncate=8)
    aperture = np.convolve(blurred, np.ones(fine) / fine, mode="same")

    def level(at_px: float) -> float:
        d = np.interp(at_px, x, aperture)
        return scene.bright_rate - (scene.bright_rate - scene.dark_rate) * d

    dark, bright = level(0.0), level(w)
    expected = (bright - dark) / (bright + dark)
    # along the bars (5 w long) the blur leaves the middle untouched to within ~1e-6
    assert scene.truth_modulation(2, 2, "sagittal") == pytest.approx(expected, abs=2e-3)


def test_default_truth_looks_like_table_4_11() -> None:
    scene = UsafScene()
    trend = [(1, 5), (2, 2), (2, 4), (2, 6), (3, 1)]
    for o in ("sagittal", "tangential"):
        mods = [scene.truth_modulation(g, e, o) for g, e in trend]  # type: ignore[arg-type]
        assert all(b < a for a, b in zip(mods, mods[1:], strict=False))  # falls with frequency
    for g, e in THESIS_ELEMENTS:
        s = scene.truth_modulation(g, e, "sagittal")
        t = scene.truth_modulation(g, e, "tangential")
        assert t < s
    assert scene.truth_modulation(1, 5, "sagittal") == pytest.approx(0.81, abs=0.05)  # thesis 0.82
    assert scene.truth_modulation(2, 4, "sagittal") == pytest.approx(0.62, abs=0.1)  # thesis 0.62
    dark, bright = scene.truth_levels_dn8(1, 5, "sagittal")
    assert dark == pytest.approx(20, abs=3) and bright == pytest.approx(190, abs=3)


def test_render_is_cached_per_geometry() -> None:
    a = UsafScene().render(H, W)
    assert UsafScene().render(H, W) is a  # equal parameters share the cache
    b = UsafScene(bright_dn8=150.0).render(H, W)
    assert b is not a and b.max() < a.max()


def test_truth_table_lists_every_bar_set() -> None:
    scene = UsafScene()
    rows = scene.truth_table()
    labels = [r["label"] for r in rows]
    assert labels[:2] == ["G0E1S", "G0E1T"] and len(rows) == 2 * len(scene.layout.elements)
    assert labels.index("G1E5S") == 2 * 10  # groups 0 and 1 E1-E4 before the thesis's
    for row in rows:
        args = (row["group"], row["element"], row["orientation"])
        assert row["modulation"] == pytest.approx(scene.truth_modulation(*args))  # type: ignore[arg-type]
        assert row["box"] == scene.bar_group(*args).box  # type: ignore[arg-type]


def test_defocus_from_the_bench_state_blurs_the_bars() -> None:
    scene = UsafScene()
    sharp = scene(_state())
    blurred = scene(_state(defocus_px=1.5))
    box = scene.bar_group(2, 2, "sagittal").box
    r0, c0, r1, c1 = box
    assert np.ptp(blurred[r0:r1, c0:c1]) < 0.5 * np.ptp(sharp[r0:r1, c0:c1])
    soft = UsafScene(defocus_px=1.5)
    assert soft.truth_modulation(2, 2, "sagittal") < 0.5 * scene.truth_modulation(2, 2, "sagittal")
    assert np.array_equal(blurred, soft.render(H, W))


def test_noise_free_bar_sets_read_their_truth_in_the_measurement_roi() -> None:
    """The measurement ROI of every non-aliased bar set, on the noise-free render, reads the
    truth (best-phase centre-bar Eq. 2.9) within 0.06 with the sine fit; the bar-set box with
    the pixels straddling the bar ends read up to 0.12 low."""
    from benchlab.analysis.bars.estimators import estimate_modulation
    from benchlab.analysis.chart.layout import THESIS_ELEMENT_CENTRES_MM

    scene = UsafScene()
    img = scene.render(H, W)
    # The thesis's elements (the coarse ones' 2.9-6 px sharp bars are over-read by the sine
    # fit's waveform, an estimator matter, not the scene's).
    for g, e in sorted(THESIS_ELEMENT_CENTRES_MM):
        for orient in ("sagittal", "tangential"):
            bars = scene.bar_group(g, e, orient)  # type: ignore[arg-type]
            f = 1.0 / bars.px_per_period
            if f > 0.5:
                continue
            r0, c0, r1, c1 = bars.roi
            res = estimate_modulation(
                img[r0:r1, c0:c1],
                estimator="sinefit",
                orientation=orient,
                freq_cycles_per_px=f,
                noise_sigma=1.0,
            )
            truth = scene.truth_modulation(g, e, orient)  # type: ignore[arg-type]
            assert res.modulation == pytest.approx(truth, abs=0.06), bars.label
