"""Every found set of a USAF chart read at its known geometry, with the blur shared across sets.

:meth:`benchlab.analysis.chart.finder.FoundElement.measure` reads one set with its geometry fixed
by the pose and the PSF width fitted to the set alone. On coarse or oblique sets the pixels pin
that width down; on fine sets whose bars lie on a pixel axis they sample only a few phases of
the pattern (at 2.1 px per period, two), and a blur that is 0.1 px off moves the reading by
0.05-0.1. The blur of a lens is a smooth function of the field: the sets at the same image
height and orientation (sagittal: intensity varying along the chart's x) see the same PSF. So:

1. every found set is read on its own (:meth:`FoundElement.fit_reading`, with the chart's
   polarity: ``dark_bars`` of :func:`benchlab.analysis.bars.knownbars.read_three_bars`), which
   gives its blur and the range of blurs its pixels allow (``Delta chi^2 <= 1``);
2. for each set, the other sets of its orientation whose own blur range is at most
   :data:`WELL_DETERMINED_PX` wide give a prior: a local linear fit of their blurs against
   image height (Gaussian kernel :data:`KERNEL_MM`, weighted by their ranges), its mean at the
   set's height, its standard deviation the fit's scatter and error (at least
   :data:`PRIOR_FLOOR_PX`);
3. the set is read again with the prior (:meth:`ThreeBarReading.with_blur_prior`: its fits
   reused, only re-weighed; :func:`benchlab.analysis.bars.knownbars.read_three_bars`'s
   ``blur_prior_px``): the chi-square plus the prior's term picks the blur, and the interval
   holds the readings over the blurs both allow. Where the set's own pixels pin the blur down
   the prior changes little; where they sample few phases it decides (on ``benchlab benchmark
   chart`` the fine sets on the pixel axes, 2-2.25 px per period, went from 75 % to 88 % of
   readings within 0.03 with it, the sets at 3-4 px from 95 % to 100 %).

Pure numpy, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.knownbars import ThreeBarReading
from benchlab.analysis.bars.result import ModulationResult
from benchlab.analysis.chart.finder import ChartFit, FoundElement
from benchlab.analysis.threads import one_thread

#: A set's own blur counts as pinned down when its allowed range is at most this wide (px).
WELL_DETERMINED_PX = 0.1
#: Kernel width (mm of image height) of the local fit of blur against image height.
KERNEL_MM = 0.15
#: Smallest prior standard deviation (px): the blur also differs between neighbouring sets
#: for reasons the height does not capture (the pixel footprint, defocus across the chart).
PRIOR_FLOOR_PX = 0.03
#: Fewest well-determined sets (effective count under the kernel) for a prior.
MIN_SUPPORT = 3.0


class SetReading(NamedTuple):
    """One set's reading by :func:`read_chart_details`: the result and the blur prior (mean, sd;
    px) it was concluded under (None: its own pixels alone)."""

    result: ModulationResult
    blur_prior_px: tuple[float, float] | None


@dataclass(frozen=True)
class ChartReading:
    """A frame's chart read whole: the chart as found, and one reading per found bar set.

    Attributes
    ----------
    fit : ChartFit
        The chart as found: pose, polarity, implied magnification, warnings, and every bar set
        of the layout, found or rejected with the reason (:attr:`ChartFit.rejected`).
    readings : tuple of ModulationResult
        One per found set (:attr:`ChartFit.found`, coarse to fine), in that order
        (:func:`read_chart`). Where the finder marks a set
        :attr:`~benchlab.analysis.chart.finder.FoundElement.unmeasurable` its reading is no
        reliable number: :attr:`unmeasurable` says why.
    """

    fit: ChartFit
    readings: tuple[ModulationResult, ...]

    def __post_init__(self) -> None:
        if len(self.readings) != len(self.fit.found):
            raise ValueError(f"{len(self.readings)} readings for {len(self.fit.found)} found "
                             "sets: one per found set expected")

    @property
    def labels(self) -> list[str]:
        """The thesis label of each reading, in order (``G2E4S``: group 2, element 4,
        sagittal)."""
        return [el.label for el in self.fit.found]

    @property
    def unmeasurable(self) -> dict[str, str]:
        """Label -> why, for the found sets whose reading is no reliable number."""
        return {el.label: el.unmeasurable for el in self.fit.found
                if el.unmeasurable is not None}

    def reading(self, label: str) -> ModulationResult:
        """The reading of the set labelled ``label`` (see :attr:`labels`).

        Raises
        ------
        KeyError
            The set was not found in the frame, or is not on the chart; the message lists the
            labels read.
        """
        for el, result in zip(self.fit.found, self.readings, strict=True):
            if el.label == label:
                return result
        raise KeyError(f"no reading of bar set {label!r}; read: {', '.join(self.labels)}")


def read_chart(
    pixels: npt.ArrayLike, fit: ChartFit, max_code: float | None = None, workers: int = 1,
) -> list[ModulationResult]:
    """Read every found set of ``fit`` in ``pixels`` (see the module docstring).

    Parameters
    ----------
    pixels : array_like
        The frame the chart was found in (2-D), or a stack of frames (3-D), which each ROI
        averages.
    fit : ChartFit
        :func:`benchlab.analysis.chart.finder.find_chart`'s answer for that frame.
    max_code : float, optional
        Saturation code (inferred for integer data).
    workers : int
        Threads that read the sets (each set's reading is a pure function of its pixels, so
        the readings are those of one thread; numpy's transforms, products and gathers run
        without the GIL, so a second core shortens the wall time).

    Returns
    -------
    list of ModulationResult
        One per :attr:`ChartFit.found`, in that order; a set marked
        :attr:`FoundElement.unmeasurable` is read too (callers show the reason instead).
    """
    return [r.result for r in read_chart_details(pixels, fit, max_code, workers)]


def read_chart_details(
    pixels: npt.ArrayLike, fit: ChartFit, max_code: float | None = None, workers: int = 1,
) -> list[SetReading]:
    """:func:`read_chart` with the blur prior each set was concluded under (what a reading of
    the same set elsewhere - e.g. imaged through a slanted edge's transfer,
    :mod:`benchlab.analysis.chart.threebar` - needs to be read the same way)."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    found = fit.found
    dark_bars = fit.polarity == "positive"

    def own(el: FoundElement) -> ThreeBarReading:
        return el.fit_reading(pixels, max_code, dark_bars=dark_bars)

    def with_prior(k: int) -> SetReading:
        prior = blur_prior(found, first, k)
        return SetReading(first[k].result if prior is None
                          else first[k].with_blur_prior(prior).result, prior)

    if workers == 1 or len(found) < 2 or one_thread():
        first = [own(el) for el in found]
        return [with_prior(k) for k in range(len(found))]
    from concurrent.futures import ThreadPoolExecutor

    # the largest sets first, so that the threads finish together
    order = sorted(range(len(found)), key=lambda k: -_pixel_count(found[k]))
    with ThreadPoolExecutor(max_workers=workers) as pool:
        done = dict(zip(order, pool.map(lambda k: own(found[k]), order), strict=True))
        first = [done[k] for k in range(len(found))]
        return list(pool.map(with_prior, range(len(found))))


def _pixel_count(el: FoundElement) -> int:
    r0, c0, r1, c1 = el.reading_roi or el.measurement_roi
    return max(r1 - r0, 0) * max(c1 - c0, 0)


def _pinned(r: ThreeBarReading) -> bool:
    """The set's own pixels fix its blur (its allowed range is narrow)."""
    if r.blur_range_px is None or not r.result.resolved:
        return False
    lo, hi = r.blur_range_px
    return hi - lo <= WELL_DETERMINED_PX


def blur_prior(
    found: list[FoundElement], readings: list[ThreeBarReading], k: int
) -> tuple[float, float] | None:
    """Prior (mean, sd; px) on set ``k``'s blur from the other sets of its orientation whose
    blur is pinned down, or None when too few are near it in image height.

    Parameters
    ----------
    found : list of FoundElement
        The chart's found sets.
    readings : list of ThreeBarReading
        Their own readings (same order).
    k : int
        The set to give a prior.
    """
    me = found[k].posed
    h, s, sd = [], [], []
    for j, (el, r) in enumerate(zip(found, readings, strict=True)):
        if j == k or el.posed.orientation != me.orientation or not _pinned(r):
            continue
        assert r.blur_range_px is not None and r.blur_sigma_px is not None
        h.append(el.posed.image_height_mm)
        s.append(r.blur_sigma_px)
        sd.append(0.5 * (r.blur_range_px[1] - r.blur_range_px[0]))
    if not h:
        return None
    dh = np.array(h) - me.image_height_mm
    sig = np.array(s)
    kernel = np.exp(-0.5 * (dh / KERNEL_MM) ** 2)
    weight = kernel / (np.array(sd) ** 2 + PRIOR_FLOOR_PX**2)
    if kernel.sum() < MIN_SUPPORT:
        return None
    # local linear fit: sigma ~ a + b dh, weighted; a is the prior mean
    design = np.stack([np.ones_like(dh), dh], axis=1)
    gram = design.T @ (weight[:, None] * design)
    try:
        inv = np.linalg.inv(gram)
    except np.linalg.LinAlgError:
        return None
    coef = inv @ (design.T @ (weight * sig))
    resid = sig - design @ coef
    scatter2 = float((kernel * resid**2).sum() / kernel.sum())
    mean = float(coef[0])
    sd_mean = math.sqrt(max(float(inv[0, 0]), 0.0))
    prior_sd = max(math.sqrt(scatter2 + sd_mean**2), PRIOR_FLOOR_PX)
    if not math.isfinite(mean):
        return None
    return max(mean, 0.0), prior_sd
