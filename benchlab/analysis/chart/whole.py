"""Find whatever part of the whole USAF 1951 chart a frame shows, at any scale and rotation.

:func:`benchlab.analysis.chart.finder.find_chart` finds the forward view's chart near its
configured magnification (0.5-2x). A microscope or a lab camera sees another part of the
chart - groups 4-7 under a 10x objective, groups -2 to 1 from across the room - at a scale no
one configured. :func:`find_whole_chart` searches the whole chart
(:mod:`benchlab.analysis.chart.whole_layout`: groups -2 to 7) over every scale:

1. **Candidates at every scale.** Three-bar sets are found as the finder finds them (a closing
   as the local ground, bars as 5:1 components, three parallel bars two widths apart), on a
   pyramid of the frame - block means over 1, 2, 4, ... px - so the closing stays small
   (bars up to :data:`LEVEL_MAX_BAR_PX` wide at each level) while the bars found span every
   size. A set seen at two levels is kept once (the finer level's).
2. **Pose.** Each candidate paired with each set of the whole chart proposes an offset, scale
   and rotation, scored and refined as in the finder (:func:`~.finder._fit_pose`). With a
   magnification hint the scales within a factor :data:`HINT_FACTOR` of it are tried first;
   when they give no chart every scale is.
3. **Which groups.** Each layer of the chart is the next one at 4x, so a view of some layers
   fits equally at scale ``s`` as two groups coarser at ``s / 4`` (or finer at ``4 s``).
   Every such alternative that explains as many sets is refined, and the one whose implied
   magnification is nearest the hint names the groups; the others are said in a warning.
4. **Placement and check** of every set, as the finder does (found or rejected with the
   reason: off the frame, above Nyquist, too small, ambiguous).

Returns the finder's :class:`~.finder.ChartFit` (its ``layout`` is the whole chart at the
hint's magnification, its ``groups_found`` the groups named), so the chart reading and the
reports read it as they read the forward view's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.chart.finder import (
    LIT_FRACTION,
    MAGNIFICATION_TOLERANCE,
    MIN_MATCHED_SETS,
    ChartFit,
    ChartNotFoundError,
    Polarity,
    _as_frame,
    _Candidates,
    _candidates,
    _check,
    _darkness,
    _high_level,
    _Lit,
    _model,
    _refine,
    refined_hypotheses,
)
from benchlab.analysis.chart.pose import ChartPose, posed_bar_set
from benchlab.analysis.chart.whole_layout import WHOLE_CHART_GROUPS, whole_chart_layout
from benchlab.analysis.mtf.frequency import FORWARD_MAGNIFICATION
from benchlab.drivers.mightex.profile import PIXEL_PITCH_UM

#: Widest bar (px, at its pyramid level) the closing of one level restores the ground over.
LEVEL_MAX_BAR_PX = 6.0
#: Narrowest bar (px, at its level) taken from a level above the finest: narrower ones are
#: found better one level finer.
LEVEL_MIN_BAR_PX = 1.5
#: The coarsest pyramid level keeps at least this many px on its shorter side.
LEVEL_MIN_SIDE_PX = 24
#: With a hint, scales within this factor of it are searched first.
HINT_FACTOR = 2.0
#: Every scale: from sets of 1 px bars in a 20 000 px frame to one set filling 8 px.
ALL_SCALES = (1e-4, 1e4)
#: Two candidates of different levels are one set when their centres are within this many
#: bar widths, their widths within this log ratio and their angles within 10 deg.
SAME_SET_WIDTHS = 0.5
SAME_SET_LOG_WIDTH = 0.3
#: Each layer of the chart is the next one at this scale.
LAYER_SCALE = 4.0
#: Best-scored pose hypotheses refined (a view of two elements fits a few element shifts
#: equally well: the hint chooses among them).
HYPOTHESES = 48
#: Sets with bars this wide (px) are plain to see: one the pose puts in the lit frame with no
#: candidate on it counts against that pose.
PLAIN_BAR_PX = (2.5, 200.0)
#: One layer assignment is chosen on the evidence when it leads the others by this many sets.
EVIDENCE_MARGIN = 4
#: An alternative layer assignment counts when it matches at least this share of the best
#: one's sets.
ALTERNATIVE_SHARE = 0.9


def find_whole_chart(
    pixels: npt.ArrayLike,
    magnification: float | None = None,
    *,
    pixel_pitch_um: float = PIXEL_PITCH_UM,
    polarity: Polarity | None = None,
    magnification_tolerance: float = MAGNIFICATION_TOLERANCE,
) -> ChartFit:
    """Locate the part of the whole USAF 1951 chart (groups -2 to 7) a frame shows.

    Parameters
    ----------
    pixels : array_like
        2-D frame (8/12/16-bit codes or floats), or a stack of frames (averaged).
    magnification : float, optional
        A hint: the Eq. 4.1 object-to-image frequency factor (image lp/mm = object lp/mm x
        magnification; 16.3 for the forward view, about 1 / M for a microscope objective of
        magnification M at unit tube lens). Scales within a factor 2 of it are searched
        first, every scale after that; it names the groups where the chart's self-similarity
        leaves them open. None: the forward view's 16.3, with a warning.
    pixel_pitch_um : float
        Sensor pixel pitch (image lp/mm and Nyquist follow from it).
    polarity : {"positive", "negative"}, optional
        Dark bars on a bright ground or the reverse; None tries both.
    magnification_tolerance : float
        Relative disagreement of implied and hinted magnification that gives a warning.

    Returns
    -------
    ChartFit
        The pose (about the frame's centre), polarity and every set of the whole chart, found
        or rejected with a reason; ``groups_found`` names the groups in view.

    Raises
    ------
    ChartNotFoundError
        When no pose is supported by at least three bar sets.
    ValueError
        A frame that is not 2-D (or a stack), empty or not finite; a magnification <= 0.
    """
    hinted = magnification is not None
    hint = float(magnification) if magnification is not None else FORWARD_MAGNIFICATION
    if not (hint > 0 and math.isfinite(hint)):
        raise ValueError(f"magnification must be a positive number, got {magnification}")
    if polarity not in (None, "positive", "negative"):
        raise ValueError(f"polarity must be 'positive' or 'negative', got {polarity!r}")
    img = _as_frame(pixels)
    h, w = img.shape
    lay = whole_chart_layout(hint, origin_rc=((h - 1) / 2.0, (w - 1) / 2.0),
                             pixel_pitch_um=pixel_pitch_um)
    model = _model(lay)
    best: tuple[tuple[int, float], Polarity, ChartPose, int, float, _Lit, int] | None = None
    ranges = [(1.0 / HINT_FACTOR, HINT_FACTOR), ALL_SCALES] if hinted else [ALL_SCALES]
    for scale_range in ranges:
        for pol in (("positive", "negative") if polarity is None else (polarity,)):
            cands, lit = _pyramid_candidates(img, pol)
            found = _nearest_hint(cands, model, lay, scale_range, hint, lit, img.shape)
            if found is None:
                continue
            pose, matched, resid = found
            key = (matched, -resid)
            if best is None or key > best[0]:
                best = (key, pol, pose, matched, resid, lit, cands.n)
        if best is not None:
            break
    if best is None:
        raise ChartNotFoundError(
            "no chart found: no three-bar sets matching the USAF 1951 chart (groups -2 to 7) "
            f"at any scale (needs at least {MIN_MATCHED_SETS} bar sets in a consistent "
            "arrangement)")
    _, pol, pose, matched, resid, lit, n_cands = best
    placed = [posed_bar_set(lay, pose, g, e, o)
              for g, e in lay.elements for o in ("sagittal", "tangential")]
    elements = tuple(_check(img, lit, pol, posed, placed) for posed in placed)
    fit_out = ChartFit(layout=lay, pose=pose, polarity=pol, elements=elements,
                       candidates=n_cands, matched_sets=matched, residual_px=resid,
                       magnification_tolerance=magnification_tolerance)
    return _with_warnings(fit_out, hint, hinted, magnification_tolerance)


def _with_warnings(fit: ChartFit, hint: float, hinted: bool, tolerance: float) -> ChartFit:
    """The fit with what the user should know: the groups' self-similar alternatives, and
    an implied magnification far from the hint (or no hint at all)."""
    import dataclasses

    warnings: list[str] = []
    implied = fit.implied_magnification
    groups = fit.groups_found
    if groups:
        lo, hi = groups[0], groups[-1]
        # two groups finer (object frequencies x 4) at the same image size: magnification / 4
        others = [f"groups {lo + 2 * j} to {hi + 2 * j} at {implied / LAYER_SCALE ** j:.4g}"
                  for j in (-4, -3, -2, -1, 1, 2, 3, 4)
                  if lo + 2 * j >= WHOLE_CHART_GROUPS[0] and hi + 2 * j <= WHOLE_CHART_GROUPS[-1]]
        if others:
            warnings.append(
                f"the chart repeats itself every two groups at 4x the size: groups {lo} to {hi} "
                f"are named for the magnification nearest "
                f"{'the hint' if hinted else 'the default'} {hint:.4g} (implied {implied:.4g}); "
                f"the same view fits {'; '.join(others)}")
    if not hinted:
        warnings.append("no magnification given: pass --magnification (a hint within 2x) to "
                        "name the groups with certainty")
    elif abs(implied / hint - 1.0) > tolerance:
        warnings.append(f"implied magnification {implied:.4g} differs from the hint "
                        f"{hint:.4g} by {100 * (implied / hint - 1):+.1f} %")
    return dataclasses.replace(fit, warnings=tuple(warnings))


def _nearest_hint(
    cands: _Candidates, model: dict[str, Any], lay: Any, scale_range: tuple[float, float],
    hint: float, lit: _Lit, shape: tuple[int, ...],
) -> tuple[ChartPose, int, float] | None:
    """The best-scored poses (:func:`~.finder.refined_hypotheses`) and their self-similar
    alternatives (scale x 4^j, same offset and rotation: the layers two groups apart), each
    refined. Among those matching at least :data:`ALTERNATIVE_SHARE` of the most sets, the
    evidence decides first - sets matched less sets that should be plain to see but are not
    there (:func:`_missing`): the finest layer has no smaller copy inside it, the coarsest no
    larger one around it - where one alternative leads by :data:`EVIDENCE_MARGIN`; else the
    implied magnification nearest the hint. None when no pose matches
    :data:`~.finder.MIN_MATCHED_SETS` sets."""
    options = refined_hypotheses(cands, model, lay, scale_range, HYPOTHESES, any_rotation=True)
    if not options:
        return None
    best = max(options, key=lambda o: (o[1], -o[2]))
    for j in (-4, -3, -2, -1, 1, 2, 3, 4):
        alt = ChartPose(best[0].offset_rc, best[0].scale * LAYER_SCALE**j,
                        best[0].rotation_deg)
        refined = _refine(cands, model, lay.origin_rc, alt)
        if refined is not None:
            options.append(refined)
    top = max(o[1] for o in options)
    if top < MIN_MATCHED_SETS:
        return None
    good = [o for o in options if o[1] >= ALTERNATIVE_SHARE * top]
    evidence = [o[1] - _missing(cands, lay, o[0], lit, shape) for o in good]
    lead = max(evidence)
    if sum(1 for e in evidence if e > lead - EVIDENCE_MARGIN) == 1:
        return good[evidence.index(lead)]
    return min(good, key=lambda o: (abs(math.log(lay.magnification / o[0].scale / hint)),
                                    -o[1], o[2]))


def _missing(cands: _Candidates, lay: Any, pose: ChartPose, lit: _Lit,
             shape: tuple[int, ...]) -> int:
    """Sets the pose puts wholly inside the lit frame with bars wide enough to be found
    (:data:`PLAIN_BAR_PX`) that no candidate of their width and angle sits on."""
    n = 0
    for g, e in lay.elements:
        for o in ("sagittal", "tangential"):
            p = posed_bar_set(lay, pose, g, e, o)  # type: ignore[arg-type]
            if not PLAIN_BAR_PX[0] <= p.bar_width_px <= PLAIN_BAR_PX[1]:
                continue
            corners = p.corners()
            if not all(0 <= r <= shape[0] - 1 and 0 <= c <= shape[1] - 1 for r, c in corners):
                continue
            if lit.at([*corners, p.centre_rc]) < LIT_FRACTION:
                continue
            d = np.hypot(cands.centre_rc[:, 0] - p.centre_rc[0],
                         cands.centre_rc[:, 1] - p.centre_rc[1])
            near = (d < 0.6 * p.bar_width_px + 0.75) & (
                np.abs(np.log(cands.width_px / p.bar_width_px)) < 0.3)
            n += not bool(near.any())
    return n


def _pyramid_candidates(img: npt.NDArray[np.float32], pol: Polarity
                        ) -> tuple[_Candidates, _Lit]:
    """Three-bar sets at every scale (see the module docstring) and the lit field (the
    coarsest level's ground, which every bar fits under)."""
    top = 0.0 if pol == "positive" else float(np.percentile(img[::2, ::2], 99.9))
    work_full = img if pol == "positive" else top - img
    kernel = 2 * math.ceil(LEVEL_MAX_BAR_PX) + 3
    h, w = img.shape
    centres: list[FloatArray] = []
    widths: list[FloatArray] = []
    angles: list[FloatArray] = []
    ground_full: npt.NDArray[np.float32] | None = None
    f = 1
    while min(h, w) // f >= LEVEL_MIN_SIDE_PX:
        level = _block_mean(work_full, f)
        darkness, ground = _darkness(level, kernel)
        c = _candidates(darkness)
        keep = c.width_px >= (0.0 if f == 1 else LEVEL_MIN_BAR_PX)
        keep &= c.width_px <= LEVEL_MAX_BAR_PX
        centres.append((c.centre_rc[keep] + 0.5) * f - 0.5)
        widths.append(c.width_px[keep] * f)
        angles.append(c.angle_deg[keep])
        up = np.repeat(np.repeat(ground, f, axis=0), f, axis=1)
        full = np.full((h, w), float(up[-1, -1]) if up.size else 0.0, dtype=np.float32)
        full[: up.shape[0], : up.shape[1]] = up[:h, :w]
        ground_full = full
        f *= 2
    cands = _dedupe(np.concatenate(centres) if centres else np.zeros((0, 2)),
                    np.concatenate(widths) if widths else np.zeros(0),
                    np.concatenate(angles) if angles else np.zeros(0))
    if ground_full is None:
        ground_full = np.asarray(work_full, dtype=np.float32)
    lit_ground = ground_full if pol == "positive" else np.asarray(top - ground_full,
                                                                  dtype=np.float32)
    return cands, _Lit(lit_ground, (0, 0), _high_level(lit_ground))


def _block_mean(img: npt.NDArray[np.float32], f: int) -> npt.NDArray[np.float32]:
    """Means of whole ``f x f`` blocks (the frame itself for f = 1)."""
    if f == 1:
        return img
    hb, wb = img.shape[0] // f, img.shape[1] // f
    out = img[: hb * f, : wb * f].reshape(hb, f, wb, f).mean(axis=(1, 3))
    return np.asarray(out, dtype=np.float32)


def _dedupe(centre: FloatArray, width: FloatArray, angle: FloatArray) -> _Candidates:
    """One candidate per set: later (coarser-level) duplicates of a kept one dropped."""
    kept: list[int] = []
    for i in range(width.size):
        dup = False
        for j in kept:
            if (math.hypot(centre[i, 0] - centre[j, 0], centre[i, 1] - centre[j, 1])
                    < SAME_SET_WIDTHS * max(width[i], width[j])
                    and abs(math.log(width[i] / width[j])) < SAME_SET_LOG_WIDTH
                    and abs((angle[i] - angle[j] + 90.0) % 180.0 - 90.0) < 10.0):
                dup = True
                break
        if not dup:
            kept.append(i)
    idx = np.array(kept, dtype=np.intp)
    return _Candidates(centre[idx].reshape(-1, 2), width[idx], angle[idx])
