"""Image centre, ROI geometry, sagittal/tangential, Coltman and radiometry helpers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchlab.analysis import (
    coltman_coefficient,
    ctf_to_mtf,
    fov_centre,
    image_height_mm,
    led_mask,
    mean_in_mask,
    mtf_from_fundamental,
    mtf_to_ctf,
    normalise_to_max,
    roi_centroid,
    roi_orientation_relative_to_centre,
)
from benchlab.analysis.mtf.compare import compare_with_simulated, load_simulated_curves


def disc(shape: tuple[int, int], centre: tuple[float, float], radius: float) -> np.ndarray:
    rr, cc = np.mgrid[: shape[0], : shape[1]]
    return (rr - centre[0]) ** 2 + (cc - centre[1]) ** 2 <= radius**2


def test_fov_centre_whole_circle_is_the_centroid() -> None:
    c = fov_centre(disc((1024, 1280), (511.5, 640.0), 300))
    assert not c.clipped and c.method == "centroid"
    assert c.centre_rc == pytest.approx((511.5, 640.0), abs=0.05)
    assert c.radius_px == pytest.approx(300, rel=0.01)


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(r0=st.floats(500, 900), c0=st.floats(300, 900), radius=st.floats(300, 500))
def test_fov_centre_of_a_clipped_circle(r0: float, c0: float, radius: float) -> None:
    """The prototype's circle is cut by the bottom edge (thesis fig. 4.14)."""
    mask = disc((1024, 1280), (r0, c0), radius)
    clipped = fov_centre(mask)
    if clipped.clipped:
        assert clipped.method == "circle-fit"
        assert clipped.centre_rc == pytest.approx((r0, c0), abs=1.0)
        naive_r = float(np.nonzero(mask)[0].mean())
        if r0 + radius > 1030:
            assert abs(clipped.centre_rc[0] - r0) < abs(naive_r - r0)


def test_fov_centre_errors() -> None:
    with pytest.raises(ValueError, match="empty"):
        fov_centre(np.zeros((10, 10), bool))
    with pytest.raises(ValueError, match="free boundary"):
        fov_centre(np.ones((10, 10), bool))  # all edge, no circle to fit
    with pytest.raises(ValueError, match="2-D"):
        fov_centre(np.ones(10, bool))


def test_roi_centroid_and_height() -> None:
    # The thesis's radial ROI, rows 250-290 and cols 1000-1050 inclusive (1-based) ...
    assert roi_centroid((250, 1000, 291, 1051)) == (270.0, 1025.0)
    # ... and the image height is a difference, so either convention gives 2.48 mm.
    assert round(image_height_mm((561.5, 647.0), (270.5, 1025.5)), 2) == 2.48
    with pytest.raises(ValueError, match="empty"):
        roi_centroid((5, 5, 5, 9))


def test_sagittal_and_tangential_relative_to_centre() -> None:
    centre = (512.0, 640.0)
    right = (500, 1000, 525, 1050)  # to the right of the centre: radius is horizontal
    assert roi_orientation_relative_to_centre(right, centre, "horizontal")[0] == "tangential"
    assert roi_orientation_relative_to_centre(right, centre, "vertical")[0] == "sagittal"
    above = (100, 630, 120, 651)
    name, angle = roi_orientation_relative_to_centre(above, centre, "vertical")
    assert name == "tangential" and angle == pytest.approx(0.0, abs=1.0)
    with pytest.raises(ValueError, match="optical axis"):
        roi_orientation_relative_to_centre((511, 639, 514, 642), centre, "horizontal")


def test_coltman_coefficients() -> None:
    got = [coltman_coefficient(k) for k in range(1, 22, 2)]
    assert got == [1, 1, -1, 1, 0, 1, -1, -1, -1, 1, 1]
    with pytest.raises(ValueError):
        coltman_coefficient(4)


def test_coltman_round_trip_gaussian_mtf() -> None:
    def mtf(f: np.ndarray) -> np.ndarray:
        return np.exp(-((f / 60.0) ** 2))

    freqs = np.linspace(2.0, 400.0, 200)
    ctf = mtf_to_ctf(mtf, freqs)
    out = ctf_to_mtf(freqs, ctf)
    # Up to 19 lp/mm every harmonic through 21 f was measured: MTF recovered to 4 decimals.
    low = freqs < 400.0 / 21
    assert np.allclose(out.mtf[low], mtf(freqs[low]), atol=1e-4)
    assert set(np.array(out.method)[(freqs > 4.0) & low]) == {"coltman"}
    # 2 lp/mm: the series (k <= 99) stops while CTF(202 lp/mm) was measured - labelled.
    assert out.method[0] == "truncated"
    # Above 400/3 lp/mm no harmonic was measured and no cutoff was given: the one-term series
    # is a truncation (MTF beyond 400 lp/mm assumed 0), never labelled as the exact pi/4 case.
    assert set(np.array(out.method)[freqs > 400.0 / 3]) == {"truncated"}
    with_cutoff = ctf_to_mtf(freqs, ctf, cutoff_lp_per_mm=400.0)
    assert set(np.array(with_cutoff.method)[freqs > 400.0 / 3]) == {"pi/4"}
    short = ctf_to_mtf(freqs, ctf, max_harmonic=21)
    assert short.method[0] == "truncated" and abs(short.mtf[0] - mtf(2.0)) > 1e-3


def test_coltman_pi_over_four_above_a_third_of_cutoff() -> None:
    freqs = np.array([40.0, 60.0, 80.0])
    ctf = np.array([0.5, 0.4, 0.3])
    out = ctf_to_mtf(freqs, ctf, cutoff_lp_per_mm=96.15)
    assert out.method == ("pi/4", "pi/4", "pi/4")
    assert np.allclose(out.mtf, math.pi / 4 * ctf)
    lowf = ctf_to_mtf(np.array([10.0, 30.0]), np.array([0.8, 0.5]), cutoff_lp_per_mm=96.15)
    # 10 lp/mm needs CTF at 50, 70, 90 lp/mm: unmeasured below cutoff -> truncated, labelled.
    assert lowf.method[0] == "truncated"
    assert lowf.mtf[0] == pytest.approx(math.pi / 4 * (0.8 + 0.5 / 3))
    assert mtf_from_fundamental(4 / math.pi * 0.5, 1.0) == pytest.approx(0.5)


def test_coltman_errors() -> None:
    with pytest.raises(ValueError):
        ctf_to_mtf([], [])
    with pytest.raises(ValueError):
        ctf_to_mtf([1.0, 1.0], [0.5, 0.4])
    with pytest.raises(ValueError):
        ctf_to_mtf([0.0], [0.5])


def test_led_mask_and_mean() -> None:
    frame = np.full((100, 120), 10.0)
    frame[40:50, 60:75] = 250.0
    frame[5, 5] = 255.0  # hot pixel
    mask = led_mask(frame)
    assert mask.sum() == 150 and not mask[5, 5]
    measure = np.full((100, 120), 12.0)
    measure[40:50, 60:75] = 88.0
    assert mean_in_mask(measure, mask) == pytest.approx(88.0)
    assert mean_in_mask(measure, mask, dark=np.full((100, 120), 8.0)) == pytest.approx(80.0)


def test_radiometry_errors() -> None:
    with pytest.raises(ValueError, match="uniform"):
        led_mask(np.zeros((10, 10)))
    with pytest.raises(ValueError, match="no LED"):
        led_mask(np.zeros((10, 10)), threshold=5.0)
    with pytest.raises(ValueError, match="empty"):
        mean_in_mask(np.ones((4, 4)), np.zeros((4, 4), bool))
    with pytest.raises(ValueError, match="shape"):
        mean_in_mask(np.ones((4, 4)), np.ones((3, 3), bool))
    with pytest.raises(ValueError, match="positive"):
        normalise_to_max([0.0, 0.0])
    edge = np.zeros((20, 20))
    edge[:4, :4] = 200.0  # LED clipped by the frame corner: still found
    assert led_mask(edge).sum() == 16


def test_simulated_curves(tmp_path) -> None:
    path = tmp_path / "curves.csv"
    path.write_text(
        "# simulated\nview,field_angle_deg,direction,freq_lp_per_mm,mtf\n"
        "radial,-30,S,0,1\nradial,-30,S,100,0.2\nradial,-30,T,0,1\nradial,-30,T,100,0.1\n"
    )
    curves = load_simulated_curves(path)
    assert len(curves) == 2
    out = compare_with_simulated(curves, "radial", -30.0, "sagittal", 50.0, 0.5)
    assert out["simulated"] == pytest.approx(0.6) and out["difference"] == pytest.approx(-0.1)
    with pytest.raises(ValueError, match="outside"):
        compare_with_simulated(curves, "radial", -30.0, "T", 150.0, 0.5)
    bad = tmp_path / "bad.csv"
    bad.write_text("view,field_angle_deg,direction,freq_lp_per_mm,mtf\nradial,x,S,1,1\n")
    with pytest.raises(ValueError, match="row 1"):
        load_simulated_curves(bad)


def test_coltman_with_measured_harmonics_is_exact_where_nyquist_as_cutoff_is_not() -> None:
    # The simulated bench's optics x pixel MTF does not vanish above Nyquist (at 3f it is
    # ~0.2 for a sharp lens): taking Nyquist as the cutoff misconverts a long square wave's
    # CTF by > 0.03; the harmonics taken from the (edge-measured) MTF recover it exactly.
    import numpy as np

    from benchlab.analysis.mtf.coltman import ctf_to_mtf, ctf_to_mtf_with_harmonics, mtf_to_ctf

    sigma_px, pitch_mm = 0.12, 5.2e-3

    def mtf(f_lp: np.ndarray) -> np.ndarray:
        nu = np.asarray(f_lp) * pitch_mm
        return np.exp(-2 * math.pi**2 * sigma_px**2 * nu**2) * np.abs(np.sinc(nu))

    freqs = np.array([51.75, 58.09, 65.2, 73.18, 82.15, 92.21])
    ctf = mtf_to_ctf(mtf, freqs, max_harmonic=999)
    exact = ctf_to_mtf_with_harmonics(freqs, ctf, mtf, max_harmonic=999)
    np.testing.assert_allclose(exact, mtf(freqs), atol=1e-9)
    nyquist = ctf_to_mtf(freqs, ctf, cutoff_lp_per_mm=1 / (2 * pitch_mm)).mtf
    assert np.max(np.abs(nyquist - mtf(freqs))) > 0.03
    with pytest.raises(ValueError, match="equally many"):
        ctf_to_mtf_with_harmonics([50.0], [0.5, 0.4], mtf)
