"""Radial view: spokes (sagittal) image at object / image radius, rings at Eq. 4.1."""

from __future__ import annotations

import pytest

from benchlab.analysis.mtf.frequency import azimuthal_image_frequency_lp_per_mm
from benchlab.protocols.mtf.analysis import radial_image_lp_per_mm
from benchlab.protocols.mtf.params import MtfParams
from benchlab.protocols.params import parse_params


def test_azimuthal_frequency_is_object_over_image_radius() -> None:
    assert azimuthal_image_frequency_lp_per_mm(1.0, 19.88, 2.485) == pytest.approx(8.0, 1e-3)
    assert azimuthal_image_frequency_lp_per_mm(0.0, 19.88, 2.0) == 0.0
    for bad in ((1.0, 0.0, 2.0), (1.0, 19.88, 0.0), (1.0, -1.0, 2.0)):
        with pytest.raises(ValueError, match="radii must be positive"):
            azimuthal_image_frequency_lp_per_mm(*bad)


def test_procedure_uses_each_roll_s_own_magnification() -> None:
    p = MtfParams(radial_roi=(250, 1000, 290, 1050), radial_object_radius_mm=19.88)
    centre = (560.5, 646.0)  # the ROI centroid (269.5, 1024.5) is 477.4 px = 2.483 mm away
    assert radial_image_lp_per_mm(2.0, "tangential", p, centre) == pytest.approx(35.0)
    assert radial_image_lp_per_mm(2.0, "sagittal", p, centre) == pytest.approx(
        2.0 * 19.88 / (477.45 * 5.2e-3), rel=1e-3)
    far = MtfParams(radial_roi=(250, 1000, 290, 1050), radial_object_radius_mm=39.76)
    assert radial_image_lp_per_mm(2.0, "sagittal", far, centre) == pytest.approx(
        2 * radial_image_lp_per_mm(2.0, "sagittal", p, centre))


def test_object_radius_is_a_validated_parameter() -> None:
    ok = parse_params("mtf", {"procedure": "mtf", "radial": {"object_radius_mm": 25.0}}, "x.toml")
    assert isinstance(ok, MtfParams) and ok.radial_object_radius_mm == 25.0
    with pytest.raises(Exception, match="radial.object_radius_mm"):
        parse_params("mtf", {"procedure": "mtf", "radial": {"object_radius_mm": 0}}, "x.toml")
