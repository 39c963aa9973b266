"""What a USAF three-bar set should read if the optics were exactly what a slanted edge says.

Coltman's series converts a bar contrast to sine-wave MTF on the assumption of an endless square
wave; a USAF element has three bars, so on a sharp lens the converted bars read high where the
edges are right (the README's "Slanted-edge MTF" section). Instead of converting the bars, this
module images the set itself through the edge's measured transfer and reads the image with the
estimator that read the bars:

1. **Optics across a direction** (:func:`optics_from_edge`): the edge's MTF (ISO 12233 e-SFR,
   :class:`~benchlab.analysis.sfr.measure.SfrResult`
   , 0-1 cycle/px) is the optics' MTF times the pixel
   footprint on the edge normal, ``sinc(f cos t) sinc(f sin t)`` at the edge's angle ``t``.
   Divided by that footprint it gives the optics alone, used where the footprint's gain is at
   least :data:`FOOTPRINT_FLOOR` (to ~0.8 cycle/px); beyond, where the division would amplify
   the noise and the SFR has no data at all (above 1 cycle/px), a Gaussian fitted to the optics
   MTF carries it on (crossfaded over :data:`BLEND_CYCLES`). The MTF is taken as a real, even
   transfer (zero phase): what the edge measures is its magnitude. Above 1 cycle/px the optics
   x pixel transfer is not 0 (``sinc`` has a negative lobe to 2 cycles/px), and the pixel
   values of a fine set depend on it: so the footprint is applied exactly at the bars' own angle
   (step 2) and only the optics is extrapolated.
2. **The set imaged** (``_render``): three bars ``w`` wide at ``u = -2w, 0, 2w`` and
   ``5 w`` long, each edge integrated over the pixel footprint at the bars' angle in closed form
   (:func:`benchlab.analysis.bars.model.edge_response`), tabulated every :data:`GRID_STEP_PX`,
   blurred through its spectrum by the optics across the bars (and, for the bar ends, by the
   optics along them: the edges of the other orientation), sampled at the pixel centres of the
   ROI that was read, with the bar and ground levels giving the chart's own contrast.
3. **Read** (:func:`predict_reading`) by :func:`benchlab.analysis.bars.knownbars.fit_three_bars` at
   the setup the real set was read with (:class:`ReadingSetup`: ROI, centre, bar width and
   angle, polarity; the same pixels, so the patterns that reading tabulated serve again where
   still kept: ``reuse_tabulation``), then, where the chart reading gave the real set a blur
   prior from the
   chart's other sets (:func:`benchlab.analysis.chart.reading.read_chart_details`), concluded
   under that prior (:meth:`benchlab.analysis.bars.knownbars.ThreeBarReading.with_blur_prior`): the
   chart reading's own path for that set. The image is noise-free, but read with the real
   reading's pixel noise as its noise floor (``noise_floor``) and on its level scale: the
   estimator weighs the image's blurs against the prior as it weighed the real pixels'. Read
   as noise-free instead, its chi-square rests on the model's numerical misfit alone and, on
   sets that sample two phases of the pattern (2.1 px per period on the pixel axis), its blur
   - and with it the reading, ~1.3-1.5 per px of blur there - wanders: +0.047 off the image's own
   Eq. 2.9 contrast on one such set.

:func:`eq29_of_image` gives, for comparison, the estimator-free Eq. 2.9 contrast of the same
image (a pixel-sized box on the middle bar and on the spaces beside it).

Pure numpy, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars.knownbars import ThreeBarReading, fit_three_bars
from benchlab.analysis.bars.model import edge_response
from benchlab.analysis.bars.projection import across_coordinate
from benchlab.analysis.bars.result import eq29_modulation
from benchlab.analysis.sfr.measure import SfrResult

#: An optics transfer: real gain at frequencies (cycles/px, any sign; even).
Transfer = Callable[[FloatArray], FloatArray]

#: The edge's measured optics MTF is used where the pixel footprint's gain on the edge normal is
#: at least this (to ~0.8 cycle/px at the target's 5-10 deg): below it the division by the
#: footprint amplifies the MTF's noise more than 4 times.
FOOTPRINT_FLOOR = 0.25
#: Band (cycles/px) below that limit over which the measured optics hands over to its Gaussian.
BLEND_CYCLES = 0.15
#: The Gaussian is fitted where the measured optics MTF is in this range (below, it is mostly
#: noise; above, it says little about the width).
TAIL_FIT_RANGE = (0.05, 0.995)
#: Tabulation step of the imaged pattern (px; read between steps by cubic interpolation) and
#: the margin (px) beyond the bars and pixels (the optics' line spread must die out within it:
#: the grid is periodic).
GRID_STEP_PX = 0.01
GRID_MARGIN_PX = 16.0


def footprint_gain(freqs_cycles_per_px: npt.ArrayLike, theta_rad: float) -> FloatArray:
    """Transfer of the unit pixel's footprint on a direction at ``theta_rad`` from a pixel axis:
    ``sinc(f cos t) sinc(f sin t)`` (signed; :mod:`benchlab.analysis.bars.model`'s trapezoid)."""
    f = np.asarray(freqs_cycles_per_px, dtype=np.float64)
    return np.asarray(np.sinc(f * math.cos(theta_rad)) * np.sinc(f * math.sin(theta_rad)),
                      dtype=np.float64)


@dataclass(frozen=True)
class OpticsTransfer:
    """The optics' transfer across one direction as an edge measured it (:func:`optics_from_edge`):
    ``gain`` on ``freqs`` (cycles/px, the measured part), a Gaussian of ``tail_sigma_px`` beyond
    ``measured_to`` (crossfaded over :data:`BLEND_CYCLES` below it)."""

    freqs: FloatArray
    gain: FloatArray
    measured_to: float
    tail_sigma_px: float

    def __call__(self, freqs_cycles_per_px: FloatArray) -> FloatArray:
        f = np.abs(np.asarray(freqs_cycles_per_px, dtype=np.float64))
        tail = np.exp(-2.0 * math.pi**2 * self.tail_sigma_px**2 * f * f)
        measured = np.interp(f, self.freqs, self.gain)
        lo = max(self.measured_to - BLEND_CYCLES, 0.0)
        t = np.clip((f - lo) / max(self.measured_to - lo, 1e-12), 0.0, 1.0)
        t = 0.5 - 0.5 * np.cos(math.pi * t)  # smooth handover
        return np.asarray((1.0 - t) * measured + t * tail, dtype=np.float64)


def optics_from_edge(res: SfrResult) -> OpticsTransfer:
    """The optics across the edge's normal: its MTF over the pixel footprint at its angle where
    that footprint passes at least :data:`FOOTPRINT_FLOOR`, a fitted Gaussian beyond (see the
    module docstring)."""
    f = np.asarray(res.freqs_cycles_per_px, dtype=np.float64)
    theta = math.radians(res.edge_angle_deg)
    foot = footprint_gain(f, theta)
    keep = foot >= FOOTPRINT_FLOOR
    keep[0] = True
    # the footprint falls monotonically to its first zero: the kept part is a prefix
    stop = int(np.argmin(keep)) if not keep.all() else f.size
    f_m, h = f[:stop], np.asarray(res.mtf, dtype=np.float64)[:stop] / foot[:stop]
    return OpticsTransfer(f_m, h, float(f_m[-1]), _gaussian_sigma(f_m, h))


def _gaussian_sigma(f: FloatArray, h: FloatArray) -> float:
    """Sigma (px) of the Gaussian ``exp(-2 pi^2 s^2 f^2)`` nearest the optics MTF ``h``: least
    squares on ``-ln h`` against ``2 pi^2 f^2`` through the origin, weighted by ``(h f)^2`` (the
    log's error scales as 1/h; the width shows at the higher frequencies)."""
    lo, hi = TAIL_FIT_RANGE
    use = (f > 0) & (h >= lo) & (h <= hi)
    if not use.any():
        # sharper than the fit can see (h ~ 1 throughout): no optics blur beyond; else nothing
        # above the noise: no optics transfer beyond (a 10 px Gaussian passes nothing there)
        if np.all(h[f > 0] > hi):
            return 0.0
        return 10.0
    x = 2.0 * math.pi**2 * f[use] ** 2
    y = -np.log(h[use])
    w = (h[use] * f[use]) ** 2
    s2 = float(np.sum(w * x * y) / np.sum(w * x * x))
    return math.sqrt(max(s2, 0.0))


def mixed(parts: Sequence[tuple[Transfer, float]]) -> Transfer:
    """The weighted sum of transfers (weights summing to 1): the optics at an image height
    between two edges, interpolated linearly as their MTFs are."""
    if not parts:
        raise ValueError("no transfer to mix")

    def transfer(freqs: FloatArray) -> FloatArray:
        return np.asarray(sum(w * t(freqs) for t, w in parts), dtype=np.float64)

    return transfer


@dataclass(frozen=True)
class ReadingSetup:
    """Where and how a bar set was read: the ROI (``r0, c0, r1, c1`` in the frame, end
    exclusive), the set's centre (row, col, frame), the bar width (px), the direction across the
    bars (``theta_deg``, :mod:`benchlab.analysis.bars.projection`'s angle), the chart's polarity
    (``dark_bars``; None: the fit chose), the blur prior the chart reading gave it (mean, sd;
    px; None: none), and the reading's pixel noise and ground level (ROI units: the codes; the
    level of the spaces, or of the dark ground of a negative target; None: the synthetic image
    is on a scale of its own and read as noise-free)."""

    roi: tuple[int, int, int, int]
    centre_rc: tuple[float, float]
    bar_width_px: float
    theta_deg: float
    dark_bars: bool | None = True
    blur_prior_px: tuple[float, float] | None = None
    noise_sigma: float = 0.0
    ground_level: float | None = None

    @property
    def shape(self) -> tuple[int, int]:
        r0, c0, r1, c1 = self.roi
        return (r1 - r0, c1 - c0)

    @property
    def centre_in_roi(self) -> tuple[float, float]:
        return (self.centre_rc[0] - self.roi[0], self.centre_rc[1] - self.roi[1])

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> ReadingSetup:
        """From :meth:`to_dict`'s form (lists for the tuples)."""
        roi = tuple(int(v) for v in d["roi"])  # type: ignore[attr-defined]
        centre = tuple(float(v) for v in d["centre_rc"])  # type: ignore[attr-defined]
        prior = d.get("blur_prior_px")
        dark = d.get("dark_bars")
        ground = d.get("ground_level")
        return cls(roi=(roi[0], roi[1], roi[2], roi[3]), centre_rc=(centre[0], centre[1]),
                   bar_width_px=float(d["bar_width_px"]),  # type: ignore[arg-type]
                   theta_deg=float(d["theta_deg"]),  # type: ignore[arg-type]
                   dark_bars=None if dark is None else bool(dark),
                   blur_prior_px=None if prior is None else
                   (float(prior[0]), float(prior[1])),  # type: ignore[index]
                   noise_sigma=float(d.get("noise_sigma") or 0.0),  # type: ignore[arg-type]
                   ground_level=None if ground is None else float(ground))  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (tuples as lists)."""
        return {"roi": list(self.roi), "centre_rc": [self.centre_rc[0], self.centre_rc[1]],
                "bar_width_px": self.bar_width_px, "theta_deg": self.theta_deg,
                "dark_bars": self.dark_bars,
                "blur_prior_px": None if self.blur_prior_px is None else
                [self.blur_prior_px[0], self.blur_prior_px[1]],
                "noise_sigma": self.noise_sigma, "ground_level": self.ground_level}


def _imaged(pos: FloatArray, intervals: Sequence[tuple[float, float]], theta_rad: float,
            optics: Transfer) -> FloatArray:
    """Fraction (0-1) of the ``intervals`` (positions along one direction, px) seen at ``pos``
    through the pixel footprint at ``theta_rad`` (closed form) and ``optics`` (through the
    tabulated pattern's spectrum)."""
    lo = min(float(pos.min()), min(a for a, _ in intervals)) - GRID_MARGIN_PX
    hi = max(float(pos.max()), max(b for _, b in intervals)) + GRID_MARGIN_PX
    n = 1 << math.ceil(math.log2((hi - lo) / GRID_STEP_PX))
    step = (hi - lo) / n
    grid = lo + step * np.arange(n)
    sharp = np.zeros(n)
    for a, b in intervals:
        sharp += edge_response(grid - a, 0.0, theta_rad) - edge_response(grid - b, 0.0, theta_rad)
    spec = np.fft.rfft(sharp) * optics(np.asarray(np.fft.rfftfreq(n, step), dtype=np.float64))
    return _cubic(np.fft.irfft(spec, n), (pos - lo) / step)


def _cubic(table: FloatArray, x: FloatArray) -> FloatArray:
    """``table`` at fractional indices ``x`` (Catmull-Rom: exact for cubics, its error
    ~1e-8 on the tabulated patterns where linear interpolation's was ~1e-5)."""
    i = np.clip(np.floor(x).astype(np.intp), 1, table.size - 3)
    t = x - i
    p0, p1, p2, p3 = table[i - 1], table[i], table[i + 1], table[i + 2]
    return np.asarray(p1 + 0.5 * t * (p2 - p0 + t * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3
                                                     + t * (3.0 * (p1 - p2) + p3 - p0))),
                      dtype=np.float64)


def bar_profile(u_px: npt.ArrayLike, bar_width_px: float, theta_deg: float,
                optics: Transfer) -> FloatArray:
    """The three bars' fraction (0-1) across them at ``u_px`` (px from the middle bar's centre):
    pixel footprint at ``theta_deg`` and ``optics`` (as the set is imaged)."""
    w = float(bar_width_px)
    u = np.asarray(u_px, dtype=np.float64)
    bars = [(c - 0.5 * w, c + 0.5 * w) for c in (-2.0 * w, 0.0, 2.0 * w)]
    return _imaged(u.ravel(), bars, math.radians(theta_deg), optics).reshape(u.shape)


def _render(setup: ReadingSetup, across: Transfer, along: Transfer, *, ground: float,
            bars: float) -> tuple[FloatArray, float]:
    """The noise-free ROI of a three-bar set (float levels, ``setup.shape``; ``across`` /
    ``along``: the optics across the bars and along them, without the pixel footprint;
    ``ground`` / ``bars``: the levels of the ground and of a sharp bar) and the image's Eq. 2.9
    contrast (:func:`eq29_of_image`, signed for dark bars) from the same tabulation."""
    theta = math.radians(setup.theta_deg)
    centre = setup.centre_in_roi
    u = across_coordinate(setup.shape, theta, centre)
    v = across_coordinate(setup.shape, theta + 0.5 * math.pi, centre)
    w = float(setup.bar_width_px)
    probes = np.array([0.0, -w, w])
    p_all = bar_profile(np.concatenate([u.ravel(), probes]), w, setup.theta_deg, across)
    p_u, p_probe = p_all[:u.size].reshape(u.shape), p_all[u.size:]
    p_v = _imaged(v.ravel(), [(-2.5 * w, 2.5 * w)], theta, along).reshape(v.shape)
    image = np.asarray(ground - (ground - bars) * p_u * p_v, dtype=np.float64)
    return image, _eq29(p_probe, ground, bars)


def _eq29(p: FloatArray, ground: float, bars: float) -> float:
    """Eq. 2.9 contrast from the pattern at the middle bar's centre and the spaces beside it
    (``p``: fractions at ``u = 0, -w, +w``), negative where the bar images brighter than the
    spaces (dark bars) or darker (bright bars)."""
    bar, space = ground - (ground - bars) * p[0], ground - (ground - bars) * 0.5 * (p[1] + p[2])
    m = eq29_modulation(min(bar, space), max(bar, space))
    dark_bars = bars < ground
    return m if (bar <= space) == dark_bars else -m


def eq29_of_image(bar_width_px: float, theta_deg: float, across: Transfer, *,
                  ground: float, bars: float) -> float:
    """Eq. 2.9 contrast of the imaged set (no estimator): the image through ``across`` and the
    pixel footprint at the middle bar's centre and the mean of the spaces beside it (``u = 0``,
    ``+-w``; at the bars' middle, beyond the reach of their ends). Negative where the contrast
    is reversed."""
    w = float(bar_width_px)
    return _eq29(bar_profile(np.array([0.0, -w, w]), w, theta_deg, across), ground, bars)


@dataclass(frozen=True)
class Prediction:
    """:func:`predict_reading`'s answer: the estimator's reading of the imaged set, the image
    itself and its estimator-free Eq. 2.9 contrast."""

    reading: ThreeBarReading
    image: FloatArray
    eq29: float

    @property
    def modulation(self) -> float | None:
        """The predicted reading (None when the estimator does not resolve the image)."""
        res = self.reading.result
        return float(res.modulation) if res.measurable and res.resolved else None


def predict_reading(setup: ReadingSetup, across: Transfer, along: Transfer, *,
                    contrast: float) -> Prediction:
    """What the three-bar estimator reads on the set imaged through ``across`` / ``along``
    (see the module docstring). The sharp levels are the setup's ground level (else ``1 +
    contrast``) and the level ``contrast`` gives the bars against it.

    Parameters
    ----------
    setup : ReadingSetup
        How the real set was read (ROI, centre, bar width, angle, polarity, blur prior, noise
        and ground level).
    across, along : Transfer
        Optics across and along the bars, without the pixel footprint.
    contrast : float
        The chart's own Eq. 2.9 contrast (0-1), e.g. a slanted edge's plateaus on the same
        target: the sharp bar and ground levels.
    """
    if not 0.0 < contrast < 1.0:
        raise ValueError(f"contrast must be in (0, 1), got {contrast}")
    negative = setup.dark_bars is False
    ratio = (1.0 + contrast) / (1.0 - contrast)  # bright over dark level
    if negative:
        ground = 1.0 - contrast if setup.ground_level is None else setup.ground_level
        bars = ground * ratio
    else:
        ground = 1.0 + contrast if setup.ground_level is None else setup.ground_level
        bars = ground / ratio
    image, eq29 = _render(setup, across, along, ground=ground, bars=bars)
    # at the chart reading's geometry: its tabulated patterns serve again where still kept
    reading = fit_three_bars(image, centre_rc=setup.centre_in_roi,
                             bar_width_px=setup.bar_width_px, theta_deg=setup.theta_deg,
                             dark_bars=setup.dark_bars, noise_floor=setup.noise_sigma,
                             reuse_tabulation=True)
    if setup.blur_prior_px is not None:
        reading = reading.with_blur_prior(setup.blur_prior_px)
    return Prediction(reading, image, eq29)
