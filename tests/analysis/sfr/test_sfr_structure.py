"""An ROI over a bar, a line, bars or a corner is refused as such (not as "no edge" or "tilt
the edge"), a bar or corner that was read as an edge is refused, and no clean edge is taken
for one (:mod:`benchlab.analysis.sfr.structure`)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from benchlab.analysis.sfr.measure import SfrRefused, measure_sfr
from benchlab.analysis.sfr.structure import find_two_edges
from benchlab.synthetic.edges import synthetic_edge

BAR = "the ROI holds a bar or a line (two parallel edges of opposite sign, "
BARS = "the ROI holds bars ("
ONE_EDGE = "not one edge: put the ROI over one edge only, with a plain plateau on each side of it"
CORNER = re.compile(r"the ROI holds a corner \(two edges at (\d+) deg to each other, \d+ and "
                    r"\d+ px long\), not one edge: put the ROI along one side only, clear of the "
                    r"corner")
SHAPE = (100, 100)
DARK, BRIGHT = 0.2, 0.8


def _step(angle_deg: float, sigma: float, offset_px: float, shape: tuple[int, int] = SHAPE
          ) -> np.ndarray:
    """0 -> 1 across an edge (the closed-form, pixel-integrated one)."""
    return synthetic_edge(shape, angle_deg, sigma, dark=0.0, bright=1.0, offset_px=offset_px)


def _codes(fraction: np.ndarray, bits: int, noise: float, seed: int = 0) -> np.ndarray:
    """Fractions of full scale to integer codes, with Gaussian noise (fraction of full scale)."""
    top = 2**bits - 1
    if noise > 0:
        fraction = fraction + np.random.default_rng(seed).normal(0.0, noise, fraction.shape)
    codes = np.clip(np.floor(fraction * top + 0.5), 0, top)
    return codes.astype(np.uint8 if bits == 8 else np.uint16)


def _bar(angle_deg: float, sigma: float, width_px: float, offset_px: float = 0.0,
         dark_bar: bool = True, shape: tuple[int, int] = SHAPE) -> np.ndarray:
    """A bar between two parallel edges: edge(-w/2) - edge(+w/2)."""
    inside = (_step(angle_deg, sigma, offset_px - width_px / 2, shape)
              - _step(angle_deg, sigma, offset_px + width_px / 2, shape))
    return BRIGHT - (BRIGHT - DARK) * inside if dark_bar else DARK + (BRIGHT - DARK) * inside


def _corner(angle_deg: float, sigma: float, at_rc: tuple[float, float] = (0.0, 0.0),
            combine: str = "product") -> np.ndarray:
    """A dark square's corner at ``at_rc`` (row, col from the ROI centre): the square lies
    where both perpendicular edges are dark, its sides ``angle_deg`` off the pixel axes."""
    t = math.radians(angle_deg)
    r, c = at_rc
    out1 = _step(angle_deg, sigma, c * math.cos(t) + r * math.sin(t))
    out2 = _step(angle_deg + 90.0, sigma, -c * math.sin(t) + r * math.cos(t))
    if combine == "product":
        inside = (1.0 - out1) * (1.0 - out2)
    else:
        inside = np.minimum(1.0 - out1, 1.0 - out2)
    return BRIGHT - (BRIGHT - DARK) * inside


def _refusal(img: np.ndarray) -> str:
    with pytest.raises(SfrRefused) as exc:
        measure_sfr(img)
    return "; ".join(exc.value.reasons)


@pytest.mark.parametrize("bits", [8, 12])
@pytest.mark.parametrize("noise", [0.0, 0.01])
@pytest.mark.parametrize(("width", "dark_bar", "angle"), [
    (8.0, True, 5.0),    # was "no edge: ESF step ... is lost in the noise ..."
    (3.0, False, 12.0),  # a bright bar: the same
    (1.0, True, 5.0),    # a thin line (1 px under a 1 px blur)
    (20.0, True, 0.0),   # on the pixel axis: the bar, not the axis, is the reason
])
def test_a_bar_or_line_is_refused_as_such(bits: int, noise: float, width: float,
                                          dark_bar: bool, angle: float) -> None:
    reason = _refusal(_codes(_bar(angle, 1.0, width, dark_bar=dark_bar), bits, noise))
    assert reason.startswith(BAR) and reason.endswith(ONE_EDGE)
    assert "lost in the noise" not in reason and "tilt the edge" not in reason


@pytest.mark.parametrize("bits", [8, 12])
@pytest.mark.parametrize("noise", [0.0, 0.01])
@pytest.mark.parametrize(("angle", "at_rc", "combine"), [
    (0.0, (0.0, 0.0), "product"),   # was "edge 0.95 deg from the pixel axis ... tilt the edge"
    (5.0, (0.0, 0.0), "min"),       # was "edge fit RMS 8.7 px ... other structure"
    (10.0, (20.0, 20.0), "product"),
    (30.0, (0.0, 30.0), "min"),
])
def test_a_corner_is_refused_as_such(bits: int, noise: float, angle: float,
                                     at_rc: tuple[float, float], combine: str) -> None:
    reason = _refusal(_codes(_corner(angle, 1.0, at_rc, combine), bits, noise))
    found = CORNER.fullmatch(reason)
    assert found is not None, reason
    assert abs(int(found.group(1)) - 90) <= 3
    assert "tilt the edge" not in reason and "try fit_order 2" not in reason


def test_bars_are_refused_as_bars() -> None:
    # Three dark bars (a USAF element's): was "no edge: ESF step ... lost in the noise".
    inside = sum(_step(5.0, 1.0, k * 16.0 - 4.0) - _step(5.0, 1.0, k * 16.0 + 4.0)
                 for k in (-1, 0, 1))
    reason = _refusal(_codes(BRIGHT - (BRIGHT - DARK) * inside, 12, 0.01))
    assert reason.startswith(BARS + "6 parallel edges alternating in sign)") and reason.endswith(
        ONE_EDGE)


def test_a_corner_with_a_short_side_is_refused_not_read_as_an_edge() -> None:
    # The corner 5 px from the ROI's side: a 110 px side and a 10 px one. The short side's
    # pixels were clipped as outliers ("68 pixel(s) ... hot or dead pixels, dust?") and the
    # rest read as one edge.
    for bits in (8, 12):
        reason = _refusal(_codes(_corner(30.0, 1.0, (10.0, 45.0)), bits, 0.0))
        assert CORNER.fullmatch(reason), reason


def test_a_bar_whose_far_edge_is_in_the_roi_is_refused_not_read() -> None:
    # A 40 px bar, its far edge 8 px from the ROI's side: the net step is small but not lost
    # in the noise, and it was read as an edge of contrast 0.08 with an MTF of ~90 at low
    # frequency (a truncated ESF and low-contrast warning, nothing else).
    img = _codes(_bar(5.0, 1.0, 40.0, offset_px=22.0), 12, 0.01, seed=3)
    reason = _refusal(img)
    assert reason.startswith(BAR) and reason.endswith(ONE_EDGE)


def _clean_edges() -> list[tuple[str, np.ndarray, float]]:
    """Clean edges as the benchmark draws them and beyond (0-45 deg, ROIs 20-300 rows,
    transposed, sharpened, with hot pixels, a halo, vignetting), with their pixel noise."""
    rng = np.random.default_rng(12)
    out = []
    for k in range(160):
        angle = float(rng.uniform(0.0, 45.0))
        sigma = float(rng.choice([0.3, 0.6, 1.0, 2.0, 3.0]))
        snr = float(rng.choice([10.0, 20.0, 100.0, math.inf]))
        noise = 0.0 if math.isinf(snr) else 0.6 / snr
        shape = (int(rng.choice([20, 60, 100, 300])), int(rng.choice([30, 60, 100])))
        base = synthetic_edge(shape, angle, sigma, offset_px=float(rng.uniform(-8, 8)))
        kind = k % 4
        if kind == 1:  # unsharp-masked: overshoot on both sides
            amount = float(rng.choice([1.0, 3.0]))
            base = base + amount * (base - gaussian_filter(base, 1.5, mode="nearest"))
        elif kind == 2:  # a halo
            base = 0.9 * base + 0.1 * gaussian_filter(base, 4.0, mode="nearest")
        elif kind == 3:  # vignetting
            y, x = np.indices(shape) - (np.array(shape)[:, None, None] - 1) / 2.0
            base = base * (1.0 - 0.3 * (x * x + y * y) / 70.0**2)
        img = _codes(np.clip(base, 0.0, 1.0), 12, noise, seed=k).astype(np.float64)
        if kind == 0:  # hot and dead pixels
            spots = rng.integers(0, min(shape), (int(rng.choice([1, 5, 30])), 2))
            img[spots[:, 0], spots[:, 1]] = rng.choice([0.0, 3900.0], spots.shape[0])
        if rng.random() < 0.5:
            img = img.T
        out.append((f"{kind=} {angle=:.1f} {sigma=} {snr=} {shape=}", img, noise * 4095))
    return out


def test_no_clean_edge_is_taken_for_a_bar_or_a_corner() -> None:
    alarms = [(name, found) for name, img, noise in _clean_edges()
              if (found := find_two_edges(img, noise)) is not None]
    assert alarms == []


def test_an_edge_crossed_by_a_bar_is_not_named_a_corner() -> None:
    # Three edge directions (the edge and the bar's two sides): not named, the generic
    # "other structure" reason stands.
    img = synthetic_edge((60, 40), 5.0, 0.8, noise_sigma=0.004, bits=8,
                         rng=np.random.default_rng(3))
    img[20:28, :] = 20.0
    assert find_two_edges(img, 0.004 * 255) is None
    assert "other structure in the ROI" in _refusal(img.astype(np.uint8))
