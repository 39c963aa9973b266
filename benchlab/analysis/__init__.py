"""Pure analysis functions: arrays in, numbers out. No devices, no files (except reading the
thesis tables and user-supplied comparison tables on request).

Vocabulary: ``modulation`` is always the Eq. 2.9 bar (square-wave) contrast; the sine-wave
quantities are ``fundamental_modulation`` and the MTF from :func:`ctf_to_mtf`.

The names below are imported on first use (PEP 562 ``__getattr__``): ``import benchlab.analysis``
costs nothing, and ``from benchlab.analysis import estimate_modulation`` loads only the modules
that name needs (start-up time of ``benchlab analyze``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from benchlab.analysis.coltman import (
        CtfToMtf,
        coltman_coefficient,
        ctf_to_mtf,
        mtf_from_fundamental,
        mtf_to_ctf,
    )
    from benchlab.analysis.estimators import (
        DEFAULT_ESTIMATOR,
        DISAGREEMENT_TOLERANCE,
        ESTIMATORS,
        bar_profile,
        compare_estimators,
        estimate_modulation,
    )
    from benchlab.analysis.frequency import (
        FORWARD_MAGNIFICATION,
        RADIAL_MAGNIFICATION,
        cycles_per_px,
        image_frequency_lp_per_mm,
        nyquist_lp_per_mm,
        px_per_period,
        usaf_bar_length_mm,
        usaf_bar_width_mm,
        usaf_frequency_lp_per_mm,
    )
    from benchlab.analysis.geometry import (
        FieldPoint,
        FovCircle,
        field_points,
        fov_centre,
        image_height_mm,
        image_height_px,
        nearest_field_point,
        roi_centroid,
        roi_orientation_relative_to_centre,
    )
    from benchlab.analysis.mtf_compare import (
        AveragedMTF,
        MonteCarloComparison,
        MonteCarloRow,
        SimulatedCurve,
        averaged_mtf,
        compare_with_monte_carlo,
        compare_with_simulated,
        load_monte_carlo_table,
        load_simulated_curves,
    )
    from benchlab.analysis.radiometry import (
        RadiometryRow,
        led_mask,
        mean_in_mask,
        normalise_to_max,
        radiometry_table,
    )
    from benchlab.analysis.result import Diagnostics, ModulationResult, eq29_modulation
    from benchlab.analysis.roi import ORIENTATION_AXIS, orientation_axis
    from benchlab.analysis.thesis_data import read_table, thesis_fixture_path

#: Public name -> the submodule that defines it.
_EXPORTS: dict[str, str] = {
    "CtfToMtf": "coltman",
    "coltman_coefficient": "coltman",
    "ctf_to_mtf": "coltman",
    "mtf_from_fundamental": "coltman",
    "mtf_to_ctf": "coltman",
    "DEFAULT_ESTIMATOR": "estimators",
    "DISAGREEMENT_TOLERANCE": "estimators",
    "ESTIMATORS": "estimators",
    "bar_profile": "estimators",
    "compare_estimators": "estimators",
    "estimate_modulation": "estimators",
    "FORWARD_MAGNIFICATION": "frequency",
    "RADIAL_MAGNIFICATION": "frequency",
    "cycles_per_px": "frequency",
    "image_frequency_lp_per_mm": "frequency",
    "nyquist_lp_per_mm": "frequency",
    "px_per_period": "frequency",
    "usaf_bar_length_mm": "frequency",
    "usaf_bar_width_mm": "frequency",
    "usaf_frequency_lp_per_mm": "frequency",
    "FieldPoint": "geometry",
    "FovCircle": "geometry",
    "field_points": "geometry",
    "fov_centre": "geometry",
    "image_height_mm": "geometry",
    "image_height_px": "geometry",
    "nearest_field_point": "geometry",
    "roi_centroid": "geometry",
    "roi_orientation_relative_to_centre": "geometry",
    "AveragedMTF": "mtf_compare",
    "MonteCarloComparison": "mtf_compare",
    "MonteCarloRow": "mtf_compare",
    "SimulatedCurve": "mtf_compare",
    "averaged_mtf": "mtf_compare",
    "compare_with_monte_carlo": "mtf_compare",
    "compare_with_simulated": "mtf_compare",
    "load_monte_carlo_table": "mtf_compare",
    "load_simulated_curves": "mtf_compare",
    "RadiometryRow": "radiometry",
    "led_mask": "radiometry",
    "mean_in_mask": "radiometry",
    "normalise_to_max": "radiometry",
    "radiometry_table": "radiometry",
    "Diagnostics": "result",
    "ModulationResult": "result",
    "eq29_modulation": "result",
    "ORIENTATION_AXIS": "roi",
    "orientation_axis": "roi",
    "read_table": "thesis_data",
    "thesis_fixture_path": "thesis_data",
}

__all__ = [
    "AveragedMTF",
    "CtfToMtf",
    "DEFAULT_ESTIMATOR",
    "DISAGREEMENT_TOLERANCE",
    "Diagnostics",
    "ESTIMATORS",
    "FORWARD_MAGNIFICATION",
    "FieldPoint",
    "FovCircle",
    "ModulationResult",
    "MonteCarloComparison",
    "MonteCarloRow",
    "ORIENTATION_AXIS",
    "RADIAL_MAGNIFICATION",
    "RadiometryRow",
    "SimulatedCurve",
    "averaged_mtf",
    "bar_profile",
    "coltman_coefficient",
    "compare_estimators",
    "compare_with_monte_carlo",
    "compare_with_simulated",
    "ctf_to_mtf",
    "cycles_per_px",
    "eq29_modulation",
    "estimate_modulation",
    "field_points",
    "fov_centre",
    "image_frequency_lp_per_mm",
    "image_height_mm",
    "image_height_px",
    "led_mask",
    "load_monte_carlo_table",
    "load_simulated_curves",
    "mean_in_mask",
    "mtf_from_fundamental",
    "mtf_to_ctf",
    "nearest_field_point",
    "normalise_to_max",
    "nyquist_lp_per_mm",
    "orientation_axis",
    "px_per_period",
    "radiometry_table",
    "read_table",
    "roi_centroid",
    "roi_orientation_relative_to_centre",
    "thesis_fixture_path",
    "usaf_bar_length_mm",
    "usaf_bar_width_mm",
    "usaf_frequency_lp_per_mm",
]


def __getattr__(name: str) -> Any:
    """Import the submodule that defines ``name`` on first access, then cache the value."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
