"""Find a USAF 1951 chart in a frame: every imaged element located, labelled and checked.

The chart's known layout (:class:`~.layout.ChartLayout`: element sizes per group,
the three-bar sets, where each element sits) is the model; the frame supplies evidence; the
pose (:class:`benchlab.analysis.chart.pose.ChartPose`: offset, scale, rotation) links them.

0. **Window.** Only the part of the frame with light in it is searched: 8 x 8 px blocks whose
   brightest pixel stands out from the dark floor (the forward view's lit disc is a fifth of
   the frame), padded by the closing's width.
1. **Candidates.** The local ground level is a morphological closing of the frame wider than the
   widest expected bar (it fills every bar with the spaces beside it and follows vignetting);
   the relative darkness ``(ground - frame) / ground`` above :data:`BAR_CONTRAST` marks bar
   pixels. Connected components whose second moments describe a 5:1 rectangle are bars; three
   parallel bars of equal length two bar widths apart are a three-bar set (centre, bar width,
   bar angle). A negative target (bright bars on a dark ground) is the same search on the
   inverted frame; both polarities are tried and the better fit wins. Dust and defects make
   components too, but rarely three equal parallel bars.
2. **Pose.** Each candidate paired with each bar set of the layout proposes a pose (scale from
   the bar widths, rotation from the bar angles, offset from the centres). Every proposal is
   scored by how many layout sets it places on a candidate of the predicted width and angle;
   the best few are refined by least squares (a similarity transform over all matched sets)
   and re-scored. A prior pose (default: the layout's own place, i.e. the parameter file's
   geometry) is refined first; when it explains most candidates the search is skipped.
3. **Placement and check.** Every set of the layout is placed by the fitted pose. Sets off the
   frame or outside the lit field are rejected as clipped by the FOV, sets with bar periods
   under 2 px as above Nyquist, sets whose measurement ROI is too thin as too small. The rest
   are checked against the frame: the ROI is projected across the predicted bars
   (:func:`benchlab.analysis.bars.projection.project_roi`) and correlated with the three-bar
   pattern at the predicted phase; the correlation is the confidence and the best-fitting
   period the measured pixels per period. A set whose pattern does not correlate
   (< :data:`MIN_CONFIDENCE`) is rejected as ambiguous. A found set gets its measurement ROI
   (three whole periods across, bar ends trimmed, no neighbouring set inside) and, where no
   reliable modulation can be read from it, the reason (:attr:`FoundElement.unmeasurable`).
4. **Reading.** :meth:`FoundElement.measure` reads a set's modulation with its geometry fixed
   by the pose (:mod:`benchlab.analysis.bars.knownbars`; every set of a chart at once, the blur
   shared between them: :func:`benchlab.analysis.chart.reading.read_chart`), down to Nyquist
   at any angle. :meth:`FoundElement.estimator_priors` hands the generic estimators the
   frequency (and the axis on axis-aligned bars) instead; they re-estimate the geometry and
   are kept off fine oblique sets (:attr:`FoundElement.generic_unreliable`).

Pure numpy/OpenCV: no files, no devices. Raises :class:`ChartNotFoundError` when no pose is
supported by at least :data:`MIN_MATCHED_SETS` sets.

Why one module of ~870 lines: steps 0-3 run in this order only and share the candidate and
placement types; the reading (step 4) and the pose maths already live in their own modules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.bars.knownbars import ThreeBarReading, fit_three_bars
from benchlab.analysis.bars.projection import project_roi
from benchlab.analysis.bars.result import ModulationResult
from benchlab.analysis.chart.layout import Box, ChartLayout, Orientation, usaf_bar_group
from benchlab.analysis.chart.morphology import box_close, label_components
from benchlab.analysis.chart.pose import (
    WHOLE_PERIODS_HALF_WIDTHS,
    ChartPose,
    PosedBarSet,
    posed_bar_set,
    posed_bar_set_roi,
)
from benchlab.analysis.mtf.frequency import nyquist_lp_per_mm

Polarity = Literal["positive", "negative"]

#: Relative darkness against the local ground above which a pixel belongs to a bar.
BAR_CONTRAST = 0.3
#: Bars: length / width of the moment-equivalent rectangle (5 for an ideal bar).
BAR_ASPECT = (2.8, 9.0)
#: Bars of one set: directions within this many degrees, lengths within this ratio.
SET_ANGLE_TOL_DEG = 10.0
SET_LENGTH_RATIO = 1.3
#: Pose matching: centre within this many predicted bar widths (+0.75 px), width within this
#: log ratio, bar angle within this many degrees.
MATCH_DIST_WIDTHS = 0.6
MATCH_LOG_WIDTH = 0.18
MATCH_ANGLE_DEG = 12.0
#: A pose needs at least this many layout sets matched to candidates.
MIN_MATCHED_SETS = 3
#: Pose hypotheses scored at once (memory: hypotheses x layout sets x candidates).
POSE_CHUNK = 512
#: Correlation with the three-bar pattern below which a placed set is "ambiguous".
MIN_CONFIDENCE = 0.5
#: The lit field: local ground above this fraction of the frame's lit level.
LIT_FRACTION = 0.3
#: The layout's own place: the default prior pose.
NOMINAL_POSE = ChartPose()
#: A pose fit is "confident" when it matches at least this many sets and this share of the
#: three-bar candidates (the rest are dust, defects and sets the layout does not hold).
CONFIDENT_MIN_SETS = 8
CONFIDENT_SHARE = 0.6
#: The search window: blocks of this many px, padded by the closing's kernel plus this.
WINDOW_BLOCK_PX = 8
WINDOW_PAD_PX = 8
#: Default warning threshold: implied vs configured magnification, relative.
MAGNIFICATION_TOLERANCE = 0.05
#: Fewest lines along the bars / pixels across them for a measurable ROI.
MIN_ROI_LINES = 3
MIN_ROI_ACROSS_PX = 4
#: Oblique sets (beyond :data:`~benchlab.analysis.chart.pose.AXIS_TOLERANCE_DEG`) with fewer
#: pixels per period give no reliable reading from a generic estimator
#: (:func:`benchlab.analysis.estimate_modulation` with :meth:`FoundElement.estimator_priors`):
#: it must find the direction and phase from a few dozen pixels first, and read only 32 %
#: (2-2.25 px) and 77 % (2.25-2.5 px) of them within 0.03 on ``benchlab benchmark chart``.
#: :meth:`FoundElement.measure` fixes the geometry from the pose
#: (:func:`benchlab.analysis.bars.knownbars.read_three_bars`), and every line of an oblique set
#: samples another phase, so it reads them down to Nyquist: all 78 sets at 2-2.25 px and all 67
#: at 2.25-2.5 px within 0.03 (40 + 8 frames). Sets above Nyquist (< 2 px) are rejected.
GENERIC_MIN_OBLIQUE_PX_PER_PERIOD = 2.5
#: The chart reading's ROI runs this far (px) past the bar ends (see :func:`_reading_roi`):
#: its model holds the ends' blur, and short bars get more lines along them. On ``benchlab
#: benchmark chart`` the sets at 2-2.25 px per period went from 3 to 1 of 94 read more than
#: 0.03 off with it (no set worse); 1.5 px read closer still but beside fewer neighbours.
READING_END_PX = 1.0
#: Fewest whole periods the measurement ROI must span across the bars.
MIN_ROI_PERIODS = 2.0
#: Blur reach (px) of a neighbouring set kept out of a measurement ROI.
NEIGHBOUR_MARGIN_PX = 1.0


class ChartNotFoundError(ValueError):
    """No USAF 1951 chart could be located in the frame."""


@dataclass(frozen=True)
class FoundElement:
    """One bar set of the chart, placed by the fitted pose and checked against the frame.

    ``status`` is ``"found"`` or ``"rejected"`` (then ``reason`` says why: clipped by the FOV,
    above Nyquist, too small, ambiguous). ``confidence`` is the correlation (0-1) of the ROI's
    across-bar profile with the three-bar pattern at the predicted place and period (0 when
    not checked). ``image_lp_per_mm`` is the object frequency (Eq. 4.1 / Table 4.9) times the
    implied magnification; ``px_per_period`` follows from it, ``measured_px_per_period`` is the
    period that fits the ROI best (None when not checked). ``roi`` is the bar-set ROI (bar ends
    trimmed, across the set only); ``measurement_roi`` the ROI a modulation is read from: three
    whole periods across (:attr:`PosedBarSet.whole_period_roi`), back to ``roi`` where a
    neighbouring set would reach into it. ``reading_roi`` is the ROI :meth:`measure` reads:
    the measurement ROI run :data:`READING_END_PX` past the bar ends (its model holds the ends'
    blur), where that stays on the frame and clear of every other set (None: the measurement
    ROI). ``unmeasurable`` says why a found set gives no reliable modulation (None when it
    does).
    """

    posed: PosedBarSet
    status: Literal["found", "rejected"]
    reason: str | None
    confidence: float
    measured_px_per_period: float | None
    roi: Box
    measurement_roi: Box
    unmeasurable: str | None = None
    reading_roi: Box | None = None

    def measure(
        self, pixels: npt.ArrayLike, max_code: float | None = None,
        blur_prior_px: tuple[float, float] | None = None, dark_bars: bool | None = None,
    ) -> ModulationResult:
        """The set's Eq. 2.9 modulation read at the geometry the pose gives it.

        :func:`benchlab.analysis.bars.knownbars.read_three_bars` on :attr:`measurement_roi` of the
        frame (``pixels``: the whole 2-D frame, or a stack of frames), with the set's centre,
        bar width and bar angle fixed by the fitted pose; only the levels, shading, blur and a
        small shift are fitted (``blur_prior_px``: a prior on the blur, see
        :func:`benchlab.analysis.chart.reading.read_chart`, which reads every set with the
        blur shared across the chart). Read whether or not :attr:`unmeasurable` is set
        (callers show that reason instead of a number). ``dark_bars``: the chart's polarity
        (``ChartFit.polarity == "positive"``), so that a contrast reversed by defocus cannot
        pass for bars of the other polarity; None lets the fit choose.
        """
        return self.fit_reading(pixels, max_code, blur_prior_px, dark_bars).result

    def fit_reading(
        self, pixels: npt.ArrayLike, max_code: float | None = None,
        blur_prior_px: tuple[float, float] | None = None, dark_bars: bool | None = None,
    ) -> ThreeBarReading:
        """:meth:`measure` with the blur it used and the blurs the pixels allow."""
        r0, c0, r1, c1 = self.reading_roi or self.measurement_roi
        p = self.posed
        roi = np.asarray(pixels)[..., r0:r1, c0:c1]
        return fit_three_bars(roi, centre_rc=(p.centre_rc[0] - r0, p.centre_rc[1] - c0),
                              bar_width_px=p.bar_width_px, theta_deg=p.theta_deg,
                              max_code=max_code, blur_prior_px=blur_prior_px,
                              dark_bars=dark_bars)

    @property
    def generic_unreliable(self) -> str | None:
        """Why a generic estimator (:meth:`estimator_priors`) gives no reliable reading here:
        :attr:`unmeasurable`, or oblique bars under
        :data:`GENERIC_MIN_OBLIQUE_PX_PER_PERIOD` px per period (None when it does)."""
        if self.unmeasurable is not None:
            return self.unmeasurable
        p = self.posed
        if not p.axis_aligned and p.px_per_period < GENERIC_MIN_OBLIQUE_PX_PER_PERIOD:
            off_axis = abs((p.theta_deg + 45.0) % 90.0 - 45.0)
            return (f"not measurable: {p.px_per_period:.2f} px per period < "
                    f"{GENERIC_MIN_OBLIQUE_PX_PER_PERIOD:g} on bars {off_axis:.1f} deg off the "
                    "pixel axes by a generic estimator (it must find the bar direction and phase "
                    "from the few pixels; the chart reading fixes them from the pose)")
        return None

    def estimator_priors(self) -> dict[str, Any]:
        """Keyword arguments for :func:`benchlab.analysis.estimate_modulation`: the set's
        frequency, and its orientation only where the bars lie on a pixel axis (the estimators
        take an axis, not an angle; oblique bars have their direction measured)."""
        p = self.posed
        return {"freq_cycles_per_px": 1.0 / p.px_per_period,
                "orientation": p.orientation if p.axis_aligned else None}

    @property
    def label(self) -> str:
        """Thesis label, e.g. ``G2E4S``."""
        return self.posed.label

    @property
    def found(self) -> bool:
        """True when the element was confirmed."""
        return self.status == "found"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description."""
        p = self.posed
        return {
            "label": p.label, "group": p.group, "element": p.element,
            "orientation": p.orientation, "status": self.status, "reason": self.reason,
            "confidence": round(self.confidence, 4),
            "centre_rc": [round(p.centre_rc[0], 3), round(p.centre_rc[1], 3)],
            "bar_width_px": round(p.bar_width_px, 4), "theta_deg": round(p.theta_deg, 3),
            "roi": list(self.roi), "measurement_roi": list(self.measurement_roi),
            "unmeasurable": self.unmeasurable, "object_lp_per_mm": p.object_lp_per_mm,
            "image_lp_per_mm": round(p.image_lp_per_mm, 4),
            "px_per_period": round(p.px_per_period, 4),
            "measured_px_per_period": None if self.measured_px_per_period is None
            else round(self.measured_px_per_period, 4),
            "image_height_mm": round(p.image_height_mm, 4),
        }


@dataclass(frozen=True)
class ChartFit:
    """The chart as found: its pose, polarity and every element's placement and check."""

    layout: ChartLayout
    pose: ChartPose
    polarity: Polarity
    elements: tuple[FoundElement, ...]
    candidates: int
    matched_sets: int
    residual_px: float
    magnification_tolerance: float = MAGNIFICATION_TOLERANCE
    warnings: tuple[str, ...] = field(default=())

    @property
    def configured_magnification(self) -> float:
        """The layout's (configured) Eq. 4.1 magnification."""
        return self.layout.magnification

    @property
    def implied_magnification(self) -> float:
        """Magnification the found scale implies (configured / scale)."""
        return self.layout.magnification / self.pose.scale

    @property
    def found(self) -> list[FoundElement]:
        """The confirmed elements, coarse to fine."""
        return [e for e in self.elements if e.found]

    @property
    def groups_found(self) -> list[int]:
        """The USAF groups with at least one confirmed bar set, coarse to fine."""
        return sorted({e.posed.group for e in self.found})

    @property
    def rejected(self) -> list[FoundElement]:
        """The rejected elements with their reasons."""
        return [e for e in self.elements if not e.found]

    def element(self, group: int, element: int, orientation: Orientation) -> FoundElement:
        """The placed set of one element and orientation (found or not)."""
        for e in self.elements:
            p = e.posed
            if (p.group, p.element, p.orientation) == (group, element, orientation):
                return e
        raise KeyError(f"G{group}E{element} {orientation} is not on the chart layout")

    @property
    def offset_px(self) -> tuple[int, int]:
        """Offset of the chart origin in whole pixels (row, col)."""
        return (round(self.pose.offset_rc[0]), round(self.pose.offset_rc[1]))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (pose, magnification, every element)."""
        return {
            "pose": {"offset_rc": [round(v, 3) for v in self.pose.offset_rc],
                     "scale": round(self.pose.scale, 5),
                     "rotation_deg": round(self.pose.rotation_deg, 3)},
            "origin_rc": list(self.layout.origin_rc),
            "polarity": self.polarity,
            "configured_magnification": self.configured_magnification,
            "implied_magnification": round(self.implied_magnification, 4),
            "candidates": self.candidates, "matched_sets": self.matched_sets,
            "residual_px": round(self.residual_px, 3),
            "found": len(self.found), "rejected": len(self.rejected),
            "groups_found": self.groups_found,
            "warnings": list(self.warnings),
            "elements": [e.to_dict() for e in self.elements],
        }


@dataclass(frozen=True)
class _Candidates:
    """Three-bar sets found in the frame: centres (row, col), bar widths, bar angles (deg)."""

    centre_rc: FloatArray
    width_px: FloatArray
    angle_deg: FloatArray

    @property
    def n(self) -> int:
        return int(self.width_px.size)


# --------------------------------------------------------------------------- public entry


def find_chart(
    pixels: npt.ArrayLike,
    layout: ChartLayout | None = None,
    *,
    scale_range: tuple[float, float] = (0.5, 2.0),
    polarity: Polarity | None = None,
    magnification_tolerance: float = MAGNIFICATION_TOLERANCE,
    prior: ChartPose | None = NOMINAL_POSE,
) -> ChartFit:
    """Locate the USAF 1951 chart of ``layout`` in a frame and check every element.

    Parameters
    ----------
    pixels : array_like
        2-D frame (any integer or float dtype; 8-bit, 12-bit or 16-bit codes alike), or a 3-D
        stack (frames, rows, cols), which is averaged.
    layout : ChartLayout, optional
        The chart model and its configured place and magnification (the prior); default
        :class:`ChartLayout` (the forward view's chart).
    scale_range : (float, float)
        Image scales tried, relative to the layout's magnification.
    polarity : {"positive", "negative"}, optional
        Dark bars on a bright ground or the reverse; ``None`` tries both.
    magnification_tolerance : float
        Relative disagreement of implied and configured magnification that gives a warning.
    prior : ChartPose, optional
        Pose tried first (default: the layout's own place, unit scale, no rotation - the
        parameter file's geometry; or a previous frame's pose). When, refined, it explains
        most three-bar sets found (:data:`CONFIDENT_SHARE`, at least
        :data:`CONFIDENT_MIN_SETS`) it is taken without searching every pose, and a polarity
        fitted that well is not searched in the other; ``None`` always searches.

    Returns
    -------
    ChartFit
        Pose, polarity and every element of the layout, found or rejected with a reason.

    Raises
    ------
    ChartNotFoundError
        When no pose is supported by at least :data:`MIN_MATCHED_SETS` bar sets.
    ValueError
        For a frame that is not 2-D (or a 3-D stack), empty or not finite, or bad options.
    """
    lay = layout if layout is not None else ChartLayout()
    img = _as_frame(pixels)
    lo, hi = scale_range
    if not (0 < lo < hi and math.isfinite(hi)):
        raise ValueError(f"scale_range must be 0 < low < high, got {scale_range}")
    if polarity not in (None, "positive", "negative"):
        raise ValueError(f"polarity must be 'positive' or 'negative', got {polarity!r}")
    model = _model(lay)
    w_max = float(model["width"].max()) * hi
    kernel = 2 * math.ceil(w_max) + 3
    r0, c0, r1, c1 = _search_window(img, kernel + WINDOW_PAD_PX)
    sub = img[r0:r1, c0:c1]
    best: tuple[tuple[int, float], Polarity, ChartPose, int, float, _Lit, int] | None = None
    for pol in (("positive", "negative") if polarity is None else (polarity,)):
        top = 0.0 if pol == "positive" else float(np.percentile(sub[::2, ::2], 99.9))
        work = sub if pol == "positive" else top - sub
        darkness, ground = _darkness(work, kernel)
        cands = _candidates(darkness, (r0, c0))
        fit = _fit_pose(cands, model, lay, scale_range, prior)
        if fit is None:
            continue
        pose, matched, resid = fit
        key = (matched, -resid)
        if best is None or key > best[0]:
            # the ground of the frame itself: the closing for a positive target; for a
            # negative one the opening of the frame, which is top - the closing of the work
            lit_ground = ground if pol == "positive" else top - ground
            lit = _Lit(lit_ground, (r0, c0), _high_level(lit_ground))
            best = (key, pol, pose, matched, resid, lit, cands.n)
        if _confident(matched, cands.n):
            break  # the other polarity's bars are this one's spaces: two per set, no chart
    if best is None:
        raise ChartNotFoundError(
            "no chart found: no three-bar sets matching the USAF 1951 layout "
            f"(needs at least {MIN_MATCHED_SETS} bar sets in a consistent arrangement)"
        )
    _, pol, pose, matched, resid, lit, n_cands = best
    placed = [posed_bar_set(lay, pose, g, e, o)
              for g, e in lay.elements for o in ("sagittal", "tangential")]
    elements = tuple(_check(img, lit, pol, posed, placed) for posed in placed)
    warnings: list[str] = []
    implied = lay.magnification / pose.scale
    if abs(implied / lay.magnification - 1.0) > magnification_tolerance:
        warnings.append(
            f"implied magnification {implied:.3g} differs from the configured "
            f"{lay.magnification:.3g} by {100 * (implied / lay.magnification - 1):+.1f} % "
            f"(tolerance {100 * magnification_tolerance:.0f} %)"
        )
    return ChartFit(layout=lay, pose=pose, polarity=pol, elements=elements,
                    candidates=n_cands, matched_sets=matched, residual_px=resid,
                    magnification_tolerance=magnification_tolerance, warnings=tuple(warnings))


# --------------------------------------------------------------------------- candidates


def _as_frame(pixels: npt.ArrayLike) -> npt.NDArray[np.float32]:
    arr = np.asarray(pixels)
    if arr.ndim == 3:
        arr = arr.mean(axis=0)
    if arr.ndim != 2 or arr.size == 0:
        raise ValueError(f"a frame must be 2-D (or a 3-D stack), got shape {arr.shape}")
    out = np.asarray(arr, dtype=np.float32)
    if not np.all(np.isfinite(out)):
        raise ValueError("the frame holds non-finite values")
    return out


def _search_window(img: npt.NDArray[np.float32], pad_px: int) -> Box:
    """The part of the frame worth searching (r0, c0, r1, c1): blocks of 8 x 8 px whose
    brightest pixel is above :data:`LIT_FRACTION` of the way from the dark floor to the
    brightest blocks (the lit disc of a positive target, the bars of a negative one), padded
    by ``pad_px``. A frame lit all over is searched whole."""
    h, w = img.shape
    step = WINDOW_BLOCK_PX
    hb, wb = h // step, w // step
    if hb < 4 or wb < 4:
        return (0, 0, h, w)
    blocks = _block_max(img, step)
    floor, level = np.percentile(blocks, (5.0, 99.0))
    lit = blocks > floor + LIT_FRACTION * (level - floor)
    if not lit.any():
        return (0, 0, h, w)
    rows, cols = np.nonzero(lit.any(axis=1))[0], np.nonzero(lit.any(axis=0))[0]
    r0, c0 = int(rows[0]) * step - pad_px, int(cols[0]) * step - pad_px
    r1 = h if rows[-1] == hb - 1 else (int(rows[-1]) + 1) * step + pad_px
    c1 = w if cols[-1] == wb - 1 else (int(cols[-1]) + 1) * step + pad_px
    return (max(r0, 0), max(c0, 0), min(r1, h), min(c1, w))


def _block_max(img: npt.NDArray[np.float32], step: int) -> npt.NDArray[np.float32]:
    """Brightest pixel of each whole ``step`` x ``step`` block (what sampling a ``step``-box
    dilation at the block centres gives, without the dilation)."""
    hb, wb = img.shape[0] // step, img.shape[1] // step
    # rows first: a maximum of whole rows (contiguous, ~8x faster than both axes at once)
    rows = img[: hb * step].reshape(hb, step, img.shape[1]).max(axis=1)
    out: npt.NDArray[np.float32] = rows[:, : wb * step].reshape(hb, wb, step).max(axis=2)
    return out


def _darkness(
    work: npt.NDArray[np.float32], kernel: int
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """Relative darkness against the local ground (a closing; 0 outside the lit field), and
    that ground."""
    ground = np.asarray(box_close(work, kernel), dtype=np.float32)
    lit_level = _high_level(ground)
    if lit_level <= 0:
        return np.zeros_like(work), ground
    floor = LIT_FRACTION * lit_level
    darkness = np.asarray((ground - work) / np.maximum(ground, floor), dtype=np.float32)
    darkness[ground < floor] = 0.0
    return darkness, ground


def _high_level(ground: npt.NDArray[Any]) -> float:
    """The lit level: 99th percentile of the (smooth) ground, from every 4th pixel."""
    return float(np.percentile(ground[::4, ::4], 99.0))


@dataclass(frozen=True)
class _Lit:
    """Where the chart is lit: the ground level (closing of a positive target, opening of a
    negative one) over the search window at ``origin_rc``, as a fraction of its high
    percentile; 0 outside the window."""

    ground: npt.NDArray[np.float32]
    origin_rc: tuple[int, int]
    level: float

    def at(self, points_rc: list[tuple[float, float]]) -> float:
        """The least lit fraction over the pixels holding the points."""
        level = self.level
        if level <= 0:
            return 0.0
        h, w = self.ground.shape
        out = math.inf
        for r, c in points_rc:
            rr, cc = round(r) - self.origin_rc[0], round(c) - self.origin_rc[1]
            if not (0 <= rr < h and 0 <= cc < w):
                return 0.0
            out = min(out, float(self.ground[rr, cc]) / level)
        return out


def _candidates(
    darkness: npt.NDArray[np.float32], origin_rc: tuple[int, int] = (0, 0)
) -> _Candidates:
    """Three-bar sets among the dark components of the darkness map (``origin_rc``: where the
    map's first pixel sits in the frame)."""
    mask = darkness > BAR_CONTRAST
    n, labels, areas = label_components(mask)
    empty = _Candidates(np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    if n <= 1:
        return empty
    rr, cc = np.nonzero(mask)
    lab = labels[rr, cc]
    wgt = darkness[rr, cc].astype(np.float64)
    cnt = np.bincount(lab, minlength=n).astype(np.float64)
    m0 = np.bincount(lab, wgt, n)
    ok = (cnt >= 4) & (areas < 5000)
    ok[0] = False
    m0s = np.where(m0 > 0, m0, 1.0)
    my = np.bincount(lab, wgt * rr, n) / m0s
    mx = np.bincount(lab, wgt * cc, n) / m0s
    dy, dx = rr - my[lab], cc - mx[lab]
    vyy = np.bincount(lab, wgt * dy * dy, n) / m0s + 1 / 12
    vxx = np.bincount(lab, wgt * dx * dx, n) / m0s + 1 / 12
    vxy = np.bincount(lab, wgt * dx * dy, n) / m0s
    tr, det = vxx + vyy, vxx * vyy - vxy**2
    disc = np.sqrt(np.maximum(tr**2 / 4 - det, 0))
    l1, l2 = tr / 2 + disc, np.maximum(tr / 2 - disc, 1e-6)
    length, width = np.sqrt(12 * l1), np.sqrt(12 * l2)
    angle = np.degrees(0.5 * np.arctan2(2 * vxy, vxx - vyy)) % 180.0  # long axis, from x to y
    aspect = length / width
    ok &= (aspect > BAR_ASPECT[0]) & (aspect < BAR_ASPECT[1]) & (length >= 4.0)
    idx = np.nonzero(ok)[0]
    if idx.size < 3:
        return empty
    y, x, ln, ang = my[idx], mx[idx], length[idx], angle[idx]
    w_est = ln / 5.0
    # pairwise geometry: offset of j from i along i's normal (across) and along its axis
    t = np.radians(ang)
    nx, ny = -np.sin(t), np.cos(t)  # normal to the long axis
    ddx, ddy = x[None, :] - x[:, None], y[None, :] - y[:, None]
    across = ddx * nx[:, None] + ddy * ny[:, None]
    along = ddx * np.cos(t)[:, None] + ddy * np.sin(t)[:, None]
    dang = np.abs((ang[None, :] - ang[:, None] + 90.0) % 180.0 - 90.0)
    ratio = ln[None, :] / ln[:, None]
    similar = (
        (dang < SET_ANGLE_TOL_DEG) & (ratio < SET_LENGTH_RATIO) & (ratio > 1 / SET_LENGTH_RATIO)
    )
    spacing = 2.0 * w_est[:, None]
    near_line = np.abs(along) < 0.5 * w_est[:, None]
    plus = similar & near_line & (np.abs(across - spacing) < 0.6 * w_est[:, None])
    minus = similar & near_line & (np.abs(across + spacing) < 0.6 * w_est[:, None])
    centres, widths, angles = [], [], []
    for i in range(idx.size):
        jp, jm = np.nonzero(plus[i])[0], np.nonzero(minus[i])[0]
        if jp.size == 0 or jm.size == 0:
            continue
        j = jp[np.argmin(np.abs(across[i, jp] - spacing[i, 0]))]
        k = jm[np.argmin(np.abs(across[i, jm] + spacing[i, 0]))]
        centres.append(((y[i] + y[j] + y[k]) / 3.0, (x[i] + x[j] + x[k]) / 3.0))
        widths.append((across[i, j] - across[i, k]) / 4.0)
        a = np.radians(ang[[i, j, k]] * 2.0)  # mean of axial angles
        angles.append(math.degrees(0.5 * math.atan2(np.sin(a).sum(), np.cos(a).sum())) % 180.0)
    if not centres:
        return empty
    return _Candidates(np.array(centres) + np.array(origin_rc, dtype=np.float64),
                       np.array(widths), np.array(angles))


# --------------------------------------------------------------------------- pose


def _model(layout: ChartLayout) -> dict[str, Any]:
    """Layout sets as arrays: nominal centres relative to the origin, bar widths, bar angles."""
    keys, centres, widths, angles = [], [], [], []
    for g, e in layout.elements:
        for o in ("sagittal", "tangential"):
            b = usaf_bar_group(layout, g, e, o)  # type: ignore[arg-type]
            keys.append((g, e, o))
            centres.append(
                (b.centre_rc[0] - layout.origin_rc[0], b.centre_rc[1] - layout.origin_rc[1])
            )
            widths.append(b.bar_width_px)
            angles.append(90.0 if o == "sagittal" else 0.0)  # bar long axis
    return {"keys": keys, "centre": np.array(centres), "width": np.array(widths),
            "angle": np.array(angles)}


def _predict(
    model: dict[str, Any], origin: tuple[float, float], k: FloatArray, phi_deg: FloatArray,
    off: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Predicted set centres (H, S, 2), widths (H, S) and bar angles (H, S) for H poses."""
    phi = np.radians(phi_deg)
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    py, px = model["centre"][None, :, 0], model["centre"][None, :, 1]
    x = origin[1] + off[:, 1:2] + k[:, None] * (px * c - py * s)
    y = origin[0] + off[:, 0:1] + k[:, None] * (px * s + py * c)
    return (np.stack([y, x], axis=-1), k[:, None] * model["width"][None, :],
            (model["angle"][None, :] + phi_deg[:, None]) % 180.0)


def _match(
    cands: _Candidates, pos: FloatArray, wid: FloatArray, ang: FloatArray, dist_widths: float
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.int64], FloatArray]:
    """For each pose and layout set: matched?, which candidate, distance (px)."""
    d = np.hypot(pos[:, :, None, 0] - cands.centre_rc[None, None, :, 0],
                 pos[:, :, None, 1] - cands.centre_rc[None, None, :, 1])
    dw = np.abs(np.log(cands.width_px[None, None, :] / wid[:, :, None]))
    da = np.abs((cands.angle_deg[None, None, :] - ang[:, :, None] + 90.0) % 180.0 - 90.0)
    ok = (
        (d < dist_widths * wid[:, :, None] + 0.75)
        & (dw < MATCH_LOG_WIDTH)
        & (da < MATCH_ANGLE_DEG)
    )
    d_ok = np.where(ok, d, np.inf)
    which = np.argmin(d_ok, axis=2)
    best = np.take_along_axis(d_ok, which[:, :, None], axis=2)[:, :, 0]
    return np.isfinite(best), which, best


def _confident(matched: int, n_candidates: int) -> bool:
    """A fit that explains most candidates with many sets: no other pose or polarity can
    match more of them."""
    return matched >= CONFIDENT_MIN_SETS and matched >= CONFIDENT_SHARE * n_candidates


def _fit_pose(
    cands: _Candidates, model: dict[str, Any], layout: ChartLayout,
    scale_range: tuple[float, float], prior: ChartPose | None = None,
) -> tuple[ChartPose, int, float] | None:
    """Best pose from candidate / layout-set correspondences, refined; None when unsupported.

    A ``prior`` pose that, refined, explains most candidates (:func:`_confident`) is taken
    without the search over every candidate / set pairing."""
    if cands.n < 2:
        return None
    origin = layout.origin_rc
    if prior is not None and scale_range[0] <= prior.scale <= scale_range[1]:
        refined = _refine(cands, model, origin, prior)
        if refined is not None and _confident(refined[1], cands.n):
            return refined
    best: tuple[ChartPose, int, float] | None = None
    for refined in refined_hypotheses(cands, model, layout, scale_range, 8):
        if best is None or (refined[1], -refined[2]) > (best[1], -best[2]):
            best = refined
    if best is None or best[1] < MIN_MATCHED_SETS:
        return None
    return best


def refined_hypotheses(
    cands: _Candidates, model: dict[str, Any], layout: ChartLayout,
    scale_range: tuple[float, float], top: int, any_rotation: bool = False,
) -> list[tuple[ChartPose, int, float]]:
    """The ``top`` best-scored poses of every candidate / layout-set pairing (scale within
    ``scale_range``), each refined (:func:`_refine`): (pose, sets matched, residual px).
    A bar's angle gives the rotation modulo 180 deg: rotations within +-90 deg are tried, and
    with ``any_rotation`` those half a turn further too."""
    if cands.n < 2:
        return []
    origin = layout.origin_rc
    grid_c, grid_s = np.meshgrid(np.arange(cands.n), np.arange(len(model["keys"])), indexing="ij")
    ci, si = grid_c.ravel(), grid_s.ravel()
    k = cands.width_px[ci] / model["width"][si]
    keep = (k >= scale_range[0]) & (k <= scale_range[1])
    ci, si, k = ci[keep], si[keep], k[keep]
    if ci.size == 0:
        return []
    phi = (cands.angle_deg[ci] - model["angle"][si] + 90.0) % 180.0 - 90.0
    if any_rotation:
        ci, si, k = np.tile(ci, 2), np.tile(si, 2), np.tile(k, 2)
        phi = np.concatenate([phi, phi + 180.0])
    rad = np.radians(phi)
    py, px = model["centre"][si, 0], model["centre"][si, 1]
    off = np.stack([
        cands.centre_rc[ci, 0] - origin[0] - k * (px * np.sin(rad) + py * np.cos(rad)),
        cands.centre_rc[ci, 1] - origin[1] - k * (px * np.cos(rad) - py * np.sin(rad)),
    ], axis=1)
    # In chunks of hypotheses: the whole chart's 120 sets x ~100 candidates per hypothesis
    # would otherwise need gigabytes (the scores are the same either way).
    score = np.zeros(k.size, dtype=np.int64)
    for h0 in range(0, k.size, POSE_CHUNK):
        sl = slice(h0, h0 + POSE_CHUNK)
        pos, wid, ang = _predict(model, origin, k[sl], phi[sl], off[sl])
        matched, _, _ = _match(cands, pos, wid, ang, MATCH_DIST_WIDTHS)
        score[sl] = matched.sum(axis=1)
    out: list[tuple[ChartPose, int, float]] = []
    for h in np.argsort(-score, kind="stable")[:top]:
        if score[h] < 2:
            break
        pose = ChartPose((float(off[h, 0]), float(off[h, 1])), float(k[h]), float(phi[h]))
        refined = _refine(cands, model, origin, pose)
        if refined is not None:
            out.append(refined)
    return out


def _refine(
    cands: _Candidates, model: dict[str, Any], origin: tuple[float, float], pose: ChartPose
) -> tuple[ChartPose, int, float] | None:
    """Least-squares similarity over the matched sets, re-matching twice."""
    n, resid = 0, math.inf
    for dist in (MATCH_DIST_WIDTHS, 0.45, 0.35):
        pos, wid, ang = _predict(model, origin, np.array([pose.scale]),
                                 np.array([pose.rotation_deg]), np.array([pose.offset_rc]))
        ok, which, _ = _match(cands, pos, wid, ang, dist)
        s_idx = np.nonzero(ok[0])[0]
        c_idx = which[0, s_idx]
        # one candidate serves one set
        _, first = np.unique(c_idx, return_index=True)
        s_idx, c_idx = s_idx[first], c_idx[first]
        if s_idx.size < 2:
            return None
        p = model["centre"][s_idx]
        zp = p[:, 1] + 1j * p[:, 0]
        q = cands.centre_rc[c_idx]
        zq = (q[:, 1] - origin[1]) + 1j * (q[:, 0] - origin[0])
        a_mat = np.stack([zp, np.ones_like(zp)], axis=1)
        sol, *_ = np.linalg.lstsq(a_mat, zq, rcond=None)
        a, t = complex(sol[0]), complex(sol[1])
        if not 0.05 < abs(a) < 20:
            return None
        pose = ChartPose((t.imag, t.real), abs(a), math.degrees(math.atan2(a.imag, a.real)))
        res = np.abs(a_mat @ sol - zq)
        n, resid = int(s_idx.size), float(np.sqrt(np.mean(res**2)))
    return pose, n, resid


# --------------------------------------------------------------------------- check


def _check(
    img: npt.NDArray[np.float32], lit: _Lit, pol: Polarity, posed: PosedBarSet,
    placed: list[PosedBarSet],
) -> FoundElement:
    """Place one set, reject it with a reason or confirm it against the frame."""
    roi = posed.roi
    h, w = img.shape

    def rejected(reason: str) -> FoundElement:
        return FoundElement(posed, "rejected", reason, 0.0, None, roi, roi)

    corners = posed.corners()
    if any(not (-0.5 <= r <= h - 0.5 and -0.5 <= c <= w - 0.5) for r, c in corners):
        return rejected("clipped by the FOV (runs off the frame)")
    if lit.at([*corners, posed.centre_rc]) < LIT_FRACTION:
        return rejected("clipped by the FOV (outside the lit field)")
    if posed.image_lp_per_mm > nyquist_lp_per_mm():
        return rejected(f"above Nyquist ({posed.px_per_period:.2f} px per period < 2)")
    r0, c0, r1, c1 = roi
    along, across = (r1 - r0, c1 - c0) if posed.orientation == "sagittal" else (c1 - c0, r1 - r0)
    if abs(math.sin(math.radians(2 * posed.theta_deg))) > 0.5:  # near 45 deg: both count
        along = across = min(r1 - r0, c1 - c0)
    if along < MIN_ROI_LINES or across < MIN_ROI_ACROSS_PX:
        return rejected(f"too small (ROI {r1 - r0} x {c1 - c0} px)")
    conf, measured = _confirm(img[r0:r1, c0:c1], posed, (posed.centre_rc[0] - r0,
                                                         posed.centre_rc[1] - c0), pol)
    if conf < MIN_CONFIDENCE:
        return FoundElement(posed, "rejected",
                            f"ambiguous (three-bar pattern correlation {conf:.2f} < "
                            f"{MIN_CONFIDENCE})", conf, measured, roi, roi)
    box, note = _measurement_roi(posed, placed, (h, w))
    return FoundElement(posed, "found", None, conf, measured, roi, box, note,
                        _reading_roi(posed, placed, (h, w), box))


def _reading_roi(
    posed: PosedBarSet, placed: list[PosedBarSet], shape: tuple[int, int], box: Box
) -> Box | None:
    """The measurement ROI ``box`` (when it spans three whole periods) run
    :data:`READING_END_PX` past the bar ends, when that stays on the frame and clear of every
    other set; None otherwise (the reading then uses ``box``)."""
    if box != posed.whole_period_roi:
        return None
    longer = posed_bar_set_roi(posed.centre_rc, posed.bar_width_px, posed.theta_deg,
                               margin_px=-READING_END_PX,
                               half_across_widths=WHOLE_PERIODS_HALF_WIDTHS)
    return longer if _on_frame(longer, shape) and _clear_of_others(longer, posed, placed) else None


def _measurement_roi(
    posed: PosedBarSet, placed: list[PosedBarSet], shape: tuple[int, int]
) -> tuple[Box, str | None]:
    """The ROI a modulation is read from, and why it gives no reliable reading (or None).

    Three whole periods across the bars when that box stays on the frame and clear of every
    other set (with :data:`NEIGHBOUR_MARGIN_PX` for its blur), else the bar-set ROI.
    """
    box = posed.whole_period_roi
    if not (_on_frame(box, shape) and _clear_of_others(box, posed, placed)):
        box = posed.roi
        if not _clear_of_others(box, posed, placed):
            return box, "a neighbouring bar set reaches into the ROI"
    p = posed.px_per_period
    r0, c0, r1, c1 = box
    t = math.radians(posed.theta_deg)
    span = abs((c1 - c0 - 1) * math.cos(t)) + abs((r1 - r0 - 1) * math.sin(t)) + 1.0
    if span / p < MIN_ROI_PERIODS:
        return box, (f"not measurable: the ROI spans {span / p:.1f} periods across the bars "
                     f"(< {MIN_ROI_PERIODS:g})")
    return box, None


def _on_frame(box: Box, shape: tuple[int, int]) -> bool:
    """Whether ``box`` (r0, c0, r1, c1; ends exclusive) lies within a frame of ``shape``."""
    r0, c0, r1, c1 = box
    return 0 <= r0 and 0 <= c0 and r1 <= shape[0] and c1 <= shape[1]


def _clear_of_others(box: Box, posed: PosedBarSet, placed: list[PosedBarSet]) -> bool:
    """Whether ``box`` meets no set of ``placed`` but ``posed`` (:func:`_box_meets_set`)."""
    return not any(o is not posed and _box_meets_set(box, o) for o in placed)


def _box_meets_set(box: Box, other: PosedBarSet) -> bool:
    """True when the pixels of ``box`` overlap the square of ``other`` widened by
    :data:`NEIGHBOUR_MARGIN_PX` (separating-axis test of two rectangles)."""
    r0, c0, r1, c1 = box
    top, left, bottom, right = r0 - 0.5, c0 - 0.5, r1 - 0.5, c1 - 0.5
    half = other.half_size_px + NEIGHBOUR_MARGIN_PX
    oy, ox = other.centre_rc
    by, bx = 0.5 * (top + bottom), 0.5 * (left + right)
    hy, hx = 0.5 * (bottom - top), 0.5 * (right - left)
    if math.hypot(oy - by, ox - bx) > math.hypot(hy, hx) + half * math.sqrt(2.0):
        return False
    t = math.radians(other.theta_deg)
    ct, st = abs(math.cos(t)), abs(math.sin(t))
    # the box's axes (rotated square's extent along x and y is half * (|cos| + |sin|))
    if abs(ox - bx) > hx + half * (ct + st) or abs(oy - by) > hy + half * (ct + st):
        return False
    # the square's axes (the box's extent along u and v)
    ux, uy = math.cos(t), math.sin(t)
    du, dv = (bx - ox) * ux + (by - oy) * uy, -(bx - ox) * uy + (by - oy) * ux
    return not (abs(du) > half + hx * ct + hy * st or abs(dv) > half + hx * st + hy * ct)


def _confirm(
    region: npt.NDArray[np.float32], posed: PosedBarSet, origin_rc: tuple[float, float],
    pol: Polarity,
) -> tuple[float, float]:
    """Correlation of the across-bar profile with the three-bar pattern, and the best period.

    The profile (:func:`project_roi`, 0.5 px bins when the bars are oblique) is compared with
    ``-cos(pi u / w)`` (dark bars at ``u = 0, +-2w``; the sign flips for a negative target)
    over trial bar widths within +-15 % of the prediction; the correlation at the best width is
    the confidence, twice that width the measured pixels per period.
    """
    theta = math.radians(posed.theta_deg)
    oblique = abs(math.sin(2 * theta)) > 0.05
    prof = project_roi(region, theta, 0.5 if oblique else 1.0, origin_rc)
    filled = prof.count > 0
    u, v, n = prof.u_px[filled], prof.mean[filled], prof.count[filled].astype(np.float64)
    sign = -1.0 if pol == "positive" else 1.0
    trials = posed.bar_width_px * np.linspace(0.85, 1.15, 13)
    # every trial width at once: one row per trial, the bins outside its set weighted 0
    wgt = np.where(np.abs(u)[None, :] <= 2.5 * trials[:, None], n[None, :], 0.0)
    scores = _weighted_corr_rows(v, sign * np.cos(np.pi * u[None, :] / trials[:, None]), wgt)
    scores[(wgt > 0).sum(axis=1) < 4] = -1.0
    i = int(np.argmax(scores))
    best_w = float(trials[i])
    if 0 < i < trials.size - 1:  # parabola through the peak and its neighbours
        y0, y1, y2 = scores[i - 1], scores[i], scores[i + 1]
        curv = y0 - 2 * y1 + y2
        if curv < 0:
            best_w += 0.5 * (y0 - y2) / curv * float(trials[1] - trials[0])
    return max(0.0, float(scores[i])), 2.0 * best_w


def _weighted_corr_rows(a: FloatArray, b: FloatArray, wgt: FloatArray) -> FloatArray:
    """Weighted correlation of ``a`` (one profile) with each row of ``b`` under the weights
    of the same row of ``wgt`` (0 where a row has no weight or no spread)."""
    wsum = np.maximum(wgt.sum(axis=1, keepdims=True), 1e-300)
    da = a[None, :] - (wgt * a[None, :]).sum(axis=1, keepdims=True) / wsum
    db = b - (wgt * b).sum(axis=1, keepdims=True) / wsum
    den = np.sqrt((wgt * da * da).sum(axis=1) * (wgt * db * db).sum(axis=1))
    num = (wgt * da * db).sum(axis=1)
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
