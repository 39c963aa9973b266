"""Averaged MTF (Eq. 4.2) with sagittal and tangential kept beside it, and comparisons with the
Monte Carlo tolerance table (Table 4.15) and with simulated MTF curves.

The thesis's lesson (section 4.3.3): one averaged criterion hid a poor tangential MTF, so every
result here carries sagittal, tangential and their difference, never only the average.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchlab.analysis.bars.result import ModulationResult
from benchlab.analysis.mtf.frequency import nyquist_lp_per_mm
from benchlab.analysis.thesis_data import read_table

Value = float | ModulationResult | None


def _value(v: Value) -> float:
    """A modulation as a number: results use ``.modulation`` (0 when not resolved), ``None``
    (the thesis's N/A) is 0."""
    if v is None:
        return 0.0
    if isinstance(v, ModulationResult):
        return float(v.modulation)
    x = float(v)
    if not math.isfinite(x):
        raise ValueError(f"modulation must be finite, got {v}")
    return x


@dataclass(frozen=True)
class AveragedMTF:
    """Eq. 4.2 ``(T + S) / 2`` with its two parts and their gap (S - T)."""

    sagittal: float
    tangential: float
    average: float
    difference: float

    def to_dict(self) -> dict[str, float]:
        return {
            "sagittal": self.sagittal,
            "tangential": self.tangential,
            "average": self.average,
            "difference": self.difference,
        }


def averaged_mtf(sagittal: Value, tangential: Value) -> AveragedMTF:
    """Eq. 4.2: ``MTF_avg = (MTF_tangential + MTF_sagittal) / 2``, keeping both.

    Unresolved (N/A) counts as 0, as in Table 4.15 (radial 52.5 lp/mm: (0 + 0.60)/2 = 0.30).
    """
    s, t = _value(sagittal), _value(tangential)
    return AveragedMTF(s, t, (s + t) / 2.0, s - t)


@dataclass(frozen=True)
class MonteCarloRow:
    """One Table 4.15 prediction: P(averaged MTF > threshold) at a frequency."""

    view: str
    freq_lp_per_mm: float
    thresholds: dict[float, float]  # probability (0-1) -> averaged-MTF threshold

    def columns(self) -> dict[str, float]:
        """The thresholds as the table's columns, most probable first: ``{"p90": 0.46, ...}``."""
        return {f"p{round(100 * p)}": t for p, t in sorted(self.thresholds.items(),
                                                            reverse=True)}


def load_monte_carlo_table(path: str | Path) -> list[MonteCarloRow]:
    """Read a Monte Carlo table: CSV ``view,freq_lp_per_mm,p90,p80,...`` (``#`` comments).

    Columns ``pNN`` give the averaged MTF exceeded with probability NN %. The thesis's values:
    ``thesis_fixture_path("table_4_15_monte_carlo")``.

    Raises
    ------
    ValueError
        Missing columns or non-numeric cells (naming the file and row).
    """
    rows = read_table(path)
    out = []
    for i, r in enumerate(rows, start=1):
        try:
            thresholds = {
                int(k[1:]) / 100.0: float(v)
                for k, v in r.items()
                if k and k.startswith("p") and k[1:].isdigit() and v not in (None, "")
            }
            out.append(
                MonteCarloRow(r["view"].strip().lower(), float(r["freq_lp_per_mm"]), thresholds)
            )
        except (KeyError, ValueError, AttributeError) as exc:
            raise ValueError(f"{path}: row {i}: {exc}") from exc
        if not thresholds:
            raise ValueError(f"{path}: row {i}: no pNN probability columns")
    return out


@dataclass(frozen=True)
class MonteCarloComparison:
    """A measured averaged MTF placed in the Monte Carlo distribution.

    Attributes
    ----------
    excluded : bool
        Measurement above Nyquist (aliased): not compared.
    row : MonteCarloRow or None
        Prediction at the nearest simulated frequency of the same view.
    exceeded : tuple of float
        Probabilities whose thresholds the measurement exceeds (e.g. (0.9, 0.8)).
    percentile_band : str
        Human-readable placement.
    averaged : AveragedMTF
        The measurement, sagittal and tangential kept.
    """

    view: str
    freq_lp_per_mm: float
    averaged: AveragedMTF
    excluded: bool
    row: MonteCarloRow | None
    exceeded: tuple[float, ...]
    percentile_band: str


def compare_with_monte_carlo(
    view: str,
    freq_lp_per_mm: float,
    sagittal: Value,
    tangential: Value,
    table: list[MonteCarloRow],
    *,
    nyquist: float | None = None,
) -> MonteCarloComparison:
    """Place a measured averaged MTF (Eq. 4.2) in the Monte Carlo prediction (Table 4.15) at the
    nearest simulated frequency of the same view; above Nyquist the measurement is excluded.

    Thesis: forward 73.187 lp/mm, S 0.76, T 0.69 -> 0.725, above every threshold at 70 lp/mm.
    """
    avg = averaged_mtf(sagittal, tangential)
    key = view.strip().lower()
    nyq = nyquist_lp_per_mm() if nyquist is None else nyquist
    if freq_lp_per_mm > nyq:
        return MonteCarloComparison(
            key, freq_lp_per_mm, avg, True, None, (), "excluded: above Nyquist (aliased)"
        )
    rows = [r for r in table if r.view == key]
    if not rows:
        raise ValueError(f"no Monte Carlo rows for view {view!r}")
    row = min(rows, key=lambda r: abs(r.freq_lp_per_mm - freq_lp_per_mm))
    exceeded, band = monte_carlo_band(avg.average, row)
    return MonteCarloComparison(key, freq_lp_per_mm, avg, False, row, exceeded, band)


def monte_carlo_band(average: float, row: MonteCarloRow) -> tuple[tuple[float, ...], str]:
    """Place an averaged MTF among one Monte Carlo row's thresholds.

    Parameters
    ----------
    average : float
        Measured averaged MTF (Eq. 4.2).
    row : MonteCarloRow
        The prediction it is compared with.

    Returns
    -------
    exceeded : tuple of float
        Probabilities whose thresholds ``average`` exceeds, highest first.
    band : str
        The placement in words, e.g. ``"between the 80% and 50% thresholds (0.27 .. 0.45)"``.
    """
    exceeded = tuple(sorted((p for p, t in row.thresholds.items() if average > t), reverse=True))
    probs = sorted(row.thresholds)
    if not exceeded:
        band = f"below the {100 * max(probs):.0f}% threshold ({row.thresholds[max(probs)]:.2f})"
    elif len(exceeded) == len(probs):
        band = f"above the {100 * min(probs):.0f}% threshold ({row.thresholds[min(probs)]:.2f})"
    else:
        # Thresholds rise as the probability falls: the value beats the one at ``lo`` and
        # falls short of the next less probable one.
        lo = min(exceeded)
        nxt = max(p for p in probs if p < lo)
        band = (f"between the {100 * lo:.0f}% and {100 * nxt:.0f}% thresholds "
                f"({row.thresholds[lo]:.2f} .. {row.thresholds[nxt]:.2f})")
    return exceeded, band


@dataclass(frozen=True)
class SimulatedCurve:
    """One simulated MTF curve (view, field angle, direction S/T) on a frequency grid."""

    view: str
    field_angle_deg: float
    direction: str
    freqs_lp_per_mm: np.ndarray
    mtf: np.ndarray

    def at(self, freq_lp_per_mm: float) -> float:
        """Linear interpolation; ``ValueError`` outside the simulated range."""
        f = self.freqs_lp_per_mm
        if not f[0] <= freq_lp_per_mm <= f[-1]:
            raise ValueError(
                f"{freq_lp_per_mm} lp/mm outside the simulated range {f[0]}-{f[-1]} lp/mm"
            )
        return float(np.interp(freq_lp_per_mm, f, self.mtf))


def load_simulated_curves(path: str | Path) -> list[SimulatedCurve]:
    """Read simulated MTF curves: CSV ``view,field_angle_deg,direction,freq_lp_per_mm,mtf``
    (direction ``S`` or ``T``; ``#`` comments), e.g. exported from Zemax.

    Raises
    ------
    ValueError
        Bad rows (naming the file and row).
    """
    groups: dict[tuple[str, float, str], list[tuple[float, float]]] = {}
    for i, r in enumerate(read_table(path), start=1):
        try:
            key = (
                r["view"].strip().lower(),
                float(r["field_angle_deg"]),
                r["direction"].strip().upper()[:1],
            )
            groups.setdefault(key, []).append((float(r["freq_lp_per_mm"]), float(r["mtf"])))
        except (KeyError, ValueError, AttributeError) as exc:
            raise ValueError(f"{path}: row {i}: {exc}") from exc
    curves = []
    for (view, angle, direction), pts in groups.items():
        pts.sort()
        arr = np.asarray(pts, dtype=np.float64)
        curves.append(SimulatedCurve(view, angle, direction, arr[:, 0], arr[:, 1]))
    return curves


def compare_with_simulated(
    curves: list[SimulatedCurve],
    view: str,
    field_angle_deg: float,
    direction: str,
    freq_lp_per_mm: float,
    measured: Value,
) -> dict[str, float]:
    """Measured minus simulated MTF at one frequency for the matching curve
    (:func:`benchlab.analysis.geometry.nearest_field_point` picks ``field_angle_deg``)."""
    d = direction.strip().upper()[:1]
    match = [
        c
        for c in curves
        if c.view == view.strip().lower()
        and c.direction == d
        and abs(c.field_angle_deg - field_angle_deg) < 1e-9
    ]
    if not match:
        raise ValueError(f"no simulated curve for {view} {field_angle_deg} deg {direction}")
    sim = match[0].at(freq_lp_per_mm)
    m = _value(measured)
    return {"measured": m, "simulated": sim, "difference": m - sim}

