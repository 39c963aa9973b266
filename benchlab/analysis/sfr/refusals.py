"""Why a slanted edge is refused once its ESF is read (:func:`~benchlab.analysis.sfr.measure.
measure_sfr`'s step 5): other structure in the ROI (a second edge, a bend, a fit far from
straight), a bright side clipped below full scale, pixels off the ESF that are not the edge's
own; and :class:`SfrRefused`, the refusal itself, with every reason.

The checks on the ROI alone (noise only, too short, clipped at full scale, too near a pixel
axis) stay with the steps that read those quantities in :mod:`benchlab.analysis.sfr.measure`;
the second edges themselves are found by :mod:`benchlab.analysis.sfr.structure`, a bend by
:mod:`benchlab.analysis.sfr.robust`.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.sfr.robust import bent_reason, edge_bow, is_bent
from benchlab.analysis.sfr.structure import find_other_edge, find_second_edge, find_two_edges

#: Pixels further than this many noise sigmas from the ESF are clipped to it (hot, dead, dust).
OUTLIER_SIGMAS = 5.0
#: Edge-fit RMS residual (px) above which the edge is reported as not straight / noisy.
FIT_RMS_WARN_PX = 1.0
#: Quality gate (refused above it): the edge-fit RMS residual, px (no clean edge in
#: ``benchlab benchmark sfr --quick`` exceeds 2.4 px, even at SNR 10; a bar or a corner
#: crossing the ROI reads 6-10 px). Above OUTLIER_REFUSE_FRACTION of the pixels more than
#: OUTLIER_SIGMAS off the ESF (benchmark at most 0.01 %; other structure in the ROI: 2-45 %;
#: JPEG at quality 75: 1-3 %) the ROI is looked at for a second edge or a bend, and refused
#: only for one of them (:func:`stray_pixels`).
FIT_RMS_REFUSE_PX = 3.0
OUTLIER_REFUSE_FRACTION = 0.01

#: Clipped below full scale: the bright plateau on one code for at least this fraction of its
#: pixels, with a noise sigma below CLIPPED_NOISE_RATIO x the dark plateau's (shot noise makes
#: an unclipped bright side the noisier one) and the dark side's noise at least 0.3 codes.
CLIPPED_AT_CODE_FRACTION = 0.9
CLIPPED_NOISE_RATIO = 0.25


class SfrRefused(ValueError):
    """The ROI holds no edge the SFR can be measured on; ``reasons`` says why (all of them)."""

    def __init__(self, reasons: list[str]) -> None:
        self.reasons = tuple(reasons)
        super().__init__("edge refused: " + "; ".join(reasons))


class PlateauLevels(Protocol):
    """The ESF's two plateau levels and their pixel noise variances (the noise model of
    :mod:`benchlab.analysis.sfr.measure`)."""

    @property
    def dark(self) -> float: ...

    @property
    def bright(self) -> float: ...

    @property
    def var_dark(self) -> float: ...

    @property
    def var_bright(self) -> float: ...


def quality_gate(
    work: FloatArray, u: FloatArray, core_half_px: float, noise: PlateauLevels, rms_px: float,
    code_step: float, codes: FloatArray | None = None,
) -> tuple[list[str], list[str]]:
    """Why the ROI holds no clean, unclipped straight edge (both empty when it does): its
    structure - the ESF's far side not brighter than its near side (other structure decided
    the polarity), an edge fit far worse than a straight edge gives - and its clipping: a
    bright plateau clipped on one code below full scale (read on ``codes``, the ROI before any
    flattening, default ``work``). Pixels off the ESF are judged by :func:`stray_pixels`."""
    reasons = []
    if not noise.bright > noise.dark:
        reasons.append(f"no single edge: the ESF's bright side ({noise.bright:.4g}) is not "
                       f"brighter than its dark side ({noise.dark:.4g}); other structure in "
                       "the ROI?")
    if rms_px > FIT_RMS_REFUSE_PX:
        reasons.append(f"edge fit RMS {rms_px:.2f} px (> {FIT_RMS_REFUSE_PX:g} px): not one "
                       "straight edge: other structure in the ROI (a second edge crossing it?)")
    clipping = []
    bright = (work if codes is None else codes)[u > core_half_px]
    if bright.size >= 30 and code_step > 0:
        top = float(bright.max())
        at_top = float(np.mean(bright == top))
        sd_dark, sd_bright = math.sqrt(noise.var_dark), math.sqrt(noise.var_bright)
        floor = math.sqrt(code_step * code_step / 12.0)  # the rounding floor of the variances
        if (at_top >= CLIPPED_AT_CODE_FRACTION and sd_dark >= 0.3 * code_step
                and sd_bright <= max(CLIPPED_NOISE_RATIO * sd_dark, floor)):
            clipping.append(f"bright side clipped at code {top:g} below full scale: "
                            f"{100 * at_top:.0f} % of its pixels on that code, noise "
                            f"{sd_bright:.2f} against {sd_dark:.2f} on the dark side (saturated "
                            "sensor: lower the exposure or gain)")
    return reasons, clipping


def stray_pixels(
    img: FloatArray, noise: float, n_outliers: int, n_pixels: int, cents: FloatArray,
    fit_order: int, rms_px: float = 0.0,
) -> tuple[str | None, str | None]:
    """More than :data:`OUTLIER_REFUSE_FRACTION` of the pixels off the ESF: the refusal when a
    second edge (:func:`find_two_edges`, :func:`find_second_edge`, :func:`find_other_edge`)
    or, on a straight fit, a
    bent edge (:func:`~benchlab.analysis.sfr.robust.edge_bow`) put them there, naming which;
    else the warning that they were taken for compression or sensor structure (clipped to
    the limit, the edge read; :mod:`benchlab.analysis.sfr.robust`). Returns (refusal,
    warning), one of them None. An edge fit scattering more than :data:`FIT_RMS_WARN_PX` (an
    edge crossing only a corner of the ROI, or no single edge) is refused too: the stray pixels
    are then not the edge's own structure."""
    found = (find_two_edges(img, noise) or find_second_edge(img, noise)
             or find_other_edge(img, noise))
    if found is not None:
        return found.reason(), None
    if rms_px > FIT_RMS_WARN_PX:
        return (f"not one clean edge across the ROI: the per-row edge positions scatter "
                f"{rms_px:.2f} px RMS about the fit (> {FIT_RMS_WARN_PX:g} px) and "
                f"{100 * n_outliers / n_pixels:.1f} % of the pixels lie off the edge profile; "
                "does the edge cross the ROI from one side to the opposite one?"), None
    if fit_order == 1:
        bow, bow_sigma = edge_bow(np.arange(cents.size, dtype=np.float64), cents)
        if is_bent(bow, bow_sigma):
            return bent_reason(bow, int(np.count_nonzero(np.isfinite(cents)))), None
    share = 100.0 * n_outliers / n_pixels
    return None, (f"{share:.1f} % of the pixels more than {OUTLIER_SIGMAS:g} noise sigmas off "
                  "the edge profile, with no second edge and no bend: taken for compression "
                  "or sensor structure (JPEG blocks, fixed pattern) and clipped to that limit; "
                  "the MTF's 1-sigma holds the pixel noise only")


def structure_refusal(reasons: list[str], img: FloatArray, noise: float,
                      also: list[str] | None = None) -> SfrRefused:
    """The refusal of an ROI whose structure may be the cause (no step, an edge near the
    pixel axis, no centroids, not one straight edge): where the ROI holds two edges - a bar
    or a line, a corner (:func:`~benchlab.analysis.sfr.structure.find_two_edges`) - that is
    the reason, said in place of ``reasons``, its symptoms; ``also`` (other causes) is kept."""
    found = find_two_edges(img, noise) or find_second_edge(img, noise)
    return SfrRefused(([found.reason()] if found is not None else reasons) + (also or []))
