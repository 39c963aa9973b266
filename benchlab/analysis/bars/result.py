"""The one result type every modulation estimator returns.

Vocabulary: ``modulation`` is always the bar (square-wave) contrast of Eq. 2.9 of the thesis,
``(bright - dark) / (bright + dark)``. The sine-wave quantity (amplitude of the fundamental over
the mean) is kept in the separately named field ``fundamental_modulation``; turning either into
a sine-wave MTF is :func:`benchlab.analysis.mtf.coltman.ctf_to_mtf`'s job.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

#: The sign a lower bound is shown with (tables, report, catalogue, CLI).
AT_LEAST = "\u2265"
#: The same in ASCII, accepted wherever a bound is read back from text.
AT_LEAST_ASCII = ">="


def format_modulation(modulation: float | None, resolved: bool = True,
                      lower_bound: bool = False, measurable: bool = True,
                      fmt: str = ".3f") -> str:
    """A modulation as text: ``"0.970"``, ``"\u2265 0.970"`` for a lower bound, ``"not resolved"``
    or ``"not measurable"`` - never a bound shown as a plain value.

    Parameters
    ----------
    modulation : float or None
        The reading (``None``: not resolved).
    resolved, lower_bound, measurable : bool
        The reading's flags (:class:`ModulationResult`).
    fmt : str
        Number format.

    Returns
    -------
    str
    """
    if not measurable:
        return "not measurable"
    if modulation is None or not resolved:
        return "not resolved"
    text = format(float(modulation), fmt)
    return f"{AT_LEAST} {text}" if lower_bound else text


#: Frequencies (cycles/px) from which sampling phase visibly changes a bar reading.
PHASE_SENSITIVE_CYCLES_PER_PX = 0.35
#: Nyquist frequency in cycles per pixel.
NYQUIST_CYCLES_PER_PX = 0.5
#: Clipped-pixel fraction above which a result is flagged (sfrmat's 0.5 %).
CLIPPED_FRACTION_LIMIT = 0.005


def _json_float(value: float | None) -> float | None:
    """``None`` for missing or non-finite numbers, else a plain float."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


@dataclass(frozen=True)
class Diagnostics:
    """What an estimator saw, so a reader can judge the number.

    Attributes
    ----------
    n_pixels : int
        Pixels in the ROI (after averaging frames, per frame).
    px_per_period : float or None
        Pixels per bar period from the frequency passed in (or estimated); ``None`` if unknown
        or at zero frequency.
    freq_cycles_per_px : float or None
        Bar frequency used, cycles/pixel (``None`` if unknown).
    clipped_fraction : float
        Fraction of pixels at or above ``max_code`` (0 when ``max_code`` is unknown).
    noise_sigma : float
        Per-pixel noise standard deviation in the ROI's gray units (given or estimated).
    aliased : bool
        Frequency above Nyquist (0.5 cycles/px): bars shown are alias, exclude from comparisons.
    phase_sensitive : bool
        Frequency from 0.35 cycles/px up to Nyquist: the reading depends on sampling phase.
    disagreement : float or None
        Largest |difference| in modulation between estimators, when :func:`compare_estimators`
        computed it.
    bimodality : float or None
        Histogram valley depth: 1 - valley/lower peak (0 = unimodal, 1 = empty valley).
    separation_sigma : float or None
        Distance between dark and bright levels in units of ``noise_sigma``.
    code_step : float or None
        Spacing of the gray codes found in the data (16 for 12-bit data stored MSB-aligned).
    smoothing_codes : float or None
        Gaussian smoothing applied to the histogram, in gray units.
    n_frames : int
        Frames averaged before analysis.
    bar_angle_deg, bar_angle_sd_deg : float or None
        Measured direction of intensity variation (deg from the column axis) and its
        standard uncertainty (``profilefit``).
    period_sd_px : float or None
        Standard uncertainty of the measured period (px).
    phase_cycles : float or None
        Bar phase at the ROI centre (cycles; 0 = a bright bar centred there).
    duty, blur_sigma_px : float or None
        Fitted bright fraction and Gaussian blur of the imaged bar model.
    uncertainty_noise, uncertainty_model : float or None
        The two parts of ``uncertainty``: noise propagated through the fit, and the model and
        sampling-phase term.
    saturation_code : float or None
        Top code found in the data (a plateau at the maximum) or from the bit depth.
    """

    n_pixels: int
    px_per_period: float | None = None
    freq_cycles_per_px: float | None = None
    clipped_fraction: float = 0.0
    noise_sigma: float = 0.0
    aliased: bool = False
    phase_sensitive: bool = False
    disagreement: float | None = None
    bimodality: float | None = None
    separation_sigma: float | None = None
    code_step: float | None = None
    smoothing_codes: float | None = None
    n_frames: int = 1
    bar_angle_deg: float | None = None
    bar_angle_sd_deg: float | None = None
    period_sd_px: float | None = None
    phase_cycles: float | None = None
    duty: float | None = None
    blur_sigma_px: float | None = None
    uncertainty_noise: float | None = None
    uncertainty_model: float | None = None
    saturation_code: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe mapping (non-finite numbers become ``None``)."""
        out: dict[str, Any] = {}
        for key, value in asdict(self).items():
            out[key] = _json_float(value) if isinstance(value, float) else value
        return out


@dataclass(frozen=True)
class ModulationResult:
    """Bar modulation of one ROI by one estimator.

    Attributes
    ----------
    estimator : str
        Registry name of the estimator (see :data:`benchlab.analysis.ESTIMATORS`).
    dark, bright : float or None
        Dark and bright gray levels (ROI gray units); both ``None`` when not resolved.
    modulation : float
        Eq. 2.9 bar contrast in [0, 1]; exactly 0.0 when not resolved (the thesis's N/A), never
        NaN. Negative only for a contrast reversal (spurious resolution: the bars image
        brighter than the spaces), which only the chart reading
        (:mod:`benchlab.analysis.bars.knownbars`) reports, with a warning saying so.
    resolved : bool
        Whether the bars were told apart.
    diagnostics : Diagnostics
        See :class:`Diagnostics`.
    uncertainty : float
        Standard uncertainty (1 sigma) of ``modulation``; 0.0 when not resolved.
    interval : tuple of float
        Approximate 95 % interval of ``modulation``, clipped to [0, 1] ([-1, 1] for a contrast
        reversal).
    uncertainty_method : str
        ``"analytic"``, ``"bootstrap"`` or ``"frames"``.
    fundamental_modulation : float or None
        Sine-wave quantity: fundamental amplitude over the mean (not Eq. 2.9); ``None`` if the
        estimator does not measure it.
    warnings : tuple of str
        Human-readable caveats (aliasing, clipping, few pixels, ...).
    measurable : bool
        False when the ROI cannot give a reading at all (it spans less than one bar period):
        not a finding about the bars, so tables show "not measurable", never the thesis's N/A
        0 (:func:`not_measurable`).
    lower_bound : bool
        True when ``modulation`` is a lower bound of the bars' contrast, not an estimate of it:
        the data cannot say how far the contrast goes beyond it (a bright level clipped at the
        saturation code, a dark level clipped at 0, or bars plainly resolved that the
        estimator's model could not fit; :mod:`benchlab.analysis.bars.extremes`). Shown as
        ``>= 0.970``, never as a plain value; ``bound_reason`` says why. ``interval`` stays the
        reading's own: the contrast lies at or above its lower end.
    bound_reason : str
        Why ``modulation`` is a bound (empty when it is a value).
    """

    estimator: str
    dark: float | None
    bright: float | None
    modulation: float
    resolved: bool
    diagnostics: Diagnostics
    uncertainty: float = 0.0
    interval: tuple[float, float] = (0.0, 0.0)
    uncertainty_method: str = "analytic"
    fundamental_modulation: float | None = None
    warnings: tuple[str, ...] = field(default_factory=tuple)
    measurable: bool = True
    lower_bound: bool = False
    bound_reason: str = ""

    def __post_init__(self) -> None:
        if not math.isfinite(self.modulation):
            raise ValueError(f"{self.estimator}: modulation must be finite, got {self.modulation}")
        if not self.resolved and (
            self.modulation != 0.0 or self.dark is not None or self.bright is not None
        ):
            raise ValueError("an unresolved result has modulation 0 and no dark/bright levels")
        if self.lower_bound and not (self.resolved and self.bound_reason):
            raise ValueError("a lower bound is a resolved reading with its reason")

    @property
    def shown(self) -> str:
        """The reading as a person reads it: ``"0.970"``, ``">= 0.970"`` for a lower bound,
        ``"not resolved"`` or ``"not measurable"`` (:func:`format_modulation`)."""
        return format_modulation(self.modulation, self.resolved, self.lower_bound,
                                 self.measurable)

    def with_updates(self, **changes: Any) -> ModulationResult:
        """Copy with some fields replaced (``diagnostics`` fields via ``diagnostics=...``)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe mapping: ``estimator, dark, bright, modulation, resolved, ...``."""
        return {
            "estimator": self.estimator,
            "dark": _json_float(self.dark),
            "bright": _json_float(self.bright),
            "modulation": float(self.modulation),
            "resolved": bool(self.resolved),
            "uncertainty": _json_float(self.uncertainty),
            "interval": [_json_float(self.interval[0]), _json_float(self.interval[1])],
            "uncertainty_method": self.uncertainty_method,
            "fundamental_modulation": _json_float(self.fundamental_modulation),
            "warnings": list(self.warnings),
            "diagnostics": self.diagnostics.to_dict(),
            "measurable": self.measurable,
            "lower_bound": self.lower_bound,
            "bound_reason": self.bound_reason,
            "shown": self.shown,
        }


#: Sampling-phase term (1 sigma) per modulation and squared phase gap (cycles^2): a blurred
#: bar profile sampled up to half the largest phase gap from its extreme falls short of it.
PHASE_GAP_SD = 0.5


def sampling_phase_sd(modulation: float, max_gap_cycles: float) -> float:
    """Sampling-phase uncertainty (1 sigma) of a contrast read from lines that sample the bar
    phase with a largest gap of ``max_gap_cycles``: ``PHASE_GAP_SD * modulation * gap**2``.

    Parameters
    ----------
    modulation : float
        The reading.
    max_gap_cycles : float
        Largest gap between sampled bar phases (cycles, 0-1; 0: every phase sampled).

    Returns
    -------
    float
    """
    return PHASE_GAP_SD * modulation * max_gap_cycles**2


def eq29_modulation(dark: float, bright: float) -> float:
    """Eq. 2.9 of the thesis: ``(bright - dark) / (bright + dark)``.

    Parameters
    ----------
    dark, bright : float
        Dark and bright gray levels (any linear unit, dark-subtracted or not).

    Returns
    -------
    float
        The bar modulation.

    Raises
    ------
    ValueError
        If ``bright + dark <= 0`` (undefined contrast) or a level is not finite.
    """
    if not (math.isfinite(dark) and math.isfinite(bright)):
        raise ValueError(f"levels must be finite, got dark={dark}, bright={bright}")
    total = bright + dark
    if total <= 0:
        raise ValueError(f"bright + dark must be positive, got {bright} + {dark}")
    return (bright - dark) / total


def unresolved(
    estimator: str, diagnostics: Diagnostics, warnings: tuple[str, ...] | list[str] = ()
) -> ModulationResult:
    """The thesis's N/A: modulation 0, no levels."""
    return ModulationResult(
        estimator=estimator,
        dark=None,
        bright=None,
        modulation=0.0,
        resolved=False,
        diagnostics=diagnostics,
        uncertainty=0.0,
        interval=(0.0, 0.0),
        warnings=tuple(warnings),
    )


#: The reason every estimator gives for an ROI too narrow for one bar period.
LESS_THAN_ONE_PERIOD = "not measurable (ROI spans < 1 bar period)"


def not_measurable(
    estimator: str, diagnostics: Diagnostics, warnings: tuple[str, ...] | list[str] = ()
) -> ModulationResult:
    """No reading possible (the ROI spans less than one bar period): unresolved in form, but
    ``measurable`` False and :data:`LESS_THAN_ONE_PERIOD` first among the warnings, so that
    no table takes it for bars that were not told apart."""
    return replace(unresolved(estimator, diagnostics, (LESS_THAN_ONE_PERIOD, *warnings)),
                   measurable=False)


def resolved(
    estimator: str,
    dark: float,
    bright: float,
    modulation: float,
    diagnostics: Diagnostics,
    sd: float,
    warnings: tuple[str, ...] | list[str] = (),
    fundamental_modulation: float | None = None,
) -> ModulationResult:
    """A resolved reading with a 1-sigma uncertainty ``sd`` and its 95 % interval in [0, 1]."""
    return ModulationResult(
        estimator=estimator,
        dark=dark,
        bright=bright,
        modulation=float(modulation),
        resolved=True,
        diagnostics=diagnostics,
        uncertainty=sd,
        interval=(max(0.0, modulation - 1.96 * sd), min(1.0, modulation + 1.96 * sd)),
        fundamental_modulation=fundamental_modulation,
        warnings=tuple(warnings),
    )
