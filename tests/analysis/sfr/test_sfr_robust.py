"""The robust edge acceptance: compression and sensor structure are read, a bent edge and a
second edge are refused by name (:mod:`benchlab.analysis.sfr.robust`)."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from PIL import Image

from benchlab.analysis.sfr.measure import SfrRefused, measure_sfr
from benchlab.analysis.sfr.robust import edge_bow, is_bent
from benchlab.synthetic.edges import pixel_integrated_step, synthetic_edge


def _jpeg(img: np.ndarray, quality: int) -> np.ndarray:
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="JPEG", quality=quality)
    buf.seek(0)
    return np.asarray(Image.open(buf))


@pytest.mark.parametrize(("angle_deg", "sigma_px"), [(5.0, 0.6), (8.0, 0.6), (12.0, 1.0),
                                                     (12.0, 1.5)])
def test_a_jpeg_compressed_clean_edge_is_read_with_a_warning(angle_deg: float, sigma_px: float
                                                             ) -> None:
    """Quality 75 put 1-3 % of these pixels more than 5 noise sigmas off the ESF: refused as
    "other structure in the ROI, or a bent edge" before."""
    img = synthetic_edge((120, 120), angle_deg, sigma_px, dark=0.2, bright=0.75,
                         offset_px=0.3, bits=8).astype(np.uint8)
    lossless = measure_sfr(img)
    res = measure_sfr(_jpeg(img, 75))
    assert res.mtf50_cycles_per_px == pytest.approx(lossless.mtf50_cycles_per_px, rel=0.04)
    assert any("compression or sensor structure" in w for w in res.warnings)


def _bent_or_stepped(bow_px: float = 0.0, second_gap_px: float | None = None) -> np.ndarray:
    rows, cols, sigma = 100, 80, 0.8
    y = np.arange(rows, dtype=np.float64)[:, None] - (rows - 1) / 2
    x = np.arange(cols, dtype=np.float64)[None, :] - (cols - 1) / 2
    slope = math.tan(math.radians(5.0))
    bend = bow_px * (y / ((rows - 1) / 2)) ** 2
    norm = math.hypot(1.0, slope)
    if second_gap_px is None:
        img = 0.15 + 0.6 * pixel_integrated_step((x - slope * y - bend) / norm, sigma, 1, slope)
    else:
        img = 0.1 + sum(0.35 * pixel_integrated_step((x - slope * y + k * second_gap_px / 2)
                                                     / norm, sigma, 1, slope) for k in (-1, 1))
    rng = np.random.default_rng(7)
    return np.round((img + rng.normal(0.0, 0.004, img.shape)) * 4095).astype(np.uint16)


def test_a_bent_edge_is_refused_as_bent_and_read_with_a_curved_fit() -> None:
    img = _bent_or_stepped(bow_px=2.0)
    with pytest.raises(SfrRefused, match=r"bent edge: the edge bows 1\.[89]\d px .*fit_order 2"):
        measure_sfr(img)
    assert measure_sfr(img, fit_order=2).mtf50_cycles_per_px is not None


@pytest.mark.parametrize("gap_px", [8.0, 14.0, 25.0])
def test_a_second_edge_of_the_same_sign_is_refused_by_name(gap_px: float) -> None:
    """Two equal steps 8 and 14 px apart read silently as one wide edge (MTF50 0.04 and 0.02
    cycles/px) before; 25 px apart were refused as "1.17 deg from the pixel axis"."""
    with pytest.raises(SfrRefused, match=r"the ROI holds a second edge \(two parallel edges of "
                                         r"the same sign, 9\d and 9\d px long\)"):
        measure_sfr(_bent_or_stepped(second_gap_px=gap_px))


def test_edge_bow_measures_the_sagitta_and_its_error() -> None:
    rows = np.arange(101, dtype=np.float64)
    t = (rows - 50) / 50
    rng = np.random.default_rng(0)
    straight = 3.0 + 0.1 * rows + rng.normal(0, 0.05, rows.size)
    bow, sigma = edge_bow(rows, straight)
    assert bow < 0.05 and sigma == pytest.approx(0.05 * math.sqrt(45 / 4 / 101), rel=0.3)
    assert not is_bent(bow, sigma)
    curved = straight + 0.8 * t * t
    bow, sigma = edge_bow(rows, curved)
    assert bow == pytest.approx(0.8, abs=0.05) and is_bent(bow, sigma)
    assert edge_bow(rows[:5], curved[:5]) == (0.0, math.inf)
