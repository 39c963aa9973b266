"""Spatial frequencies of the bench: USAF 1951 legend (Table 4.9), magnification (Eq. 4.1),
sensor sampling and Nyquist.
"""

from __future__ import annotations

import math

from benchlab.drivers.mightex.profile import PIXEL_PITCH_UM

#: Object-to-image frequency factors of the prototype (Eq. 4.1): 20.1/1.23 and 16.63/0.95.
FORWARD_MAGNIFICATION = 16.3
RADIAL_MAGNIFICATION = 17.5


def usaf_frequency_lp_per_mm(group: int, element: int) -> float:
    """USAF 1951 object frequency, ``2 ** (group + (element - 1) / 6)`` lp/mm (Table 4.9).

    Raises ``ValueError`` for elements outside 1..6.
    """
    if not 1 <= element <= 6:
        raise ValueError(f"USAF element must be 1..6, got {element}")
    return float(2.0 ** (group + (element - 1) / 6.0))


def usaf_bar_width_mm(group: int, element: int) -> float:
    """Width of one bar (= one space) of a USAF element: half a period, in mm."""
    return 0.5 / usaf_frequency_lp_per_mm(group, element)


def usaf_bar_length_mm(group: int, element: int) -> float:
    """Length of a USAF bar: five bar widths."""
    return 5.0 * usaf_bar_width_mm(group, element)


def image_frequency_lp_per_mm(object_lp_per_mm: float, magnification: float) -> float:
    """Image-plane frequency: object frequency times the object/image size ratio (Eq. 4.1)."""
    if magnification <= 0:
        raise ValueError(f"magnification must be positive, got {magnification}")
    return object_lp_per_mm * magnification


def azimuthal_image_frequency_lp_per_mm(
    object_lp_per_mm: float, object_radius_mm: float, image_radius_mm: float
) -> float:
    """Image-plane frequency of bars running along the axis of a rotationally symmetric view
    (the radial view's *sagittal* roll: spokes).

    Around the circle the azimuth is kept, so a period of the object's arc at radius ``R``
    images onto the arc at image radius ``r``: the frequency scales by ``R / r`` (19.88 / 2.48
    = 8.0 at the thesis's radial ROI), not by Eq. 4.1's axial magnification (17.5).

    Parameters
    ----------
    object_lp_per_mm : float
        Frequency of the pattern on the object cylinder (lp/mm).
    object_radius_mm : float
        Distance of the object cylinder from the axis (mm).
    image_radius_mm : float
        Distance of the measured point from the image centre on the sensor (mm).
    """
    if object_radius_mm <= 0 or image_radius_mm <= 0:
        raise ValueError(f"radii must be positive, got object {object_radius_mm} mm, image "
                         f"{image_radius_mm} mm")
    return object_lp_per_mm * object_radius_mm / image_radius_mm


def cycles_per_px(freq_lp_per_mm: float, pixel_pitch_um: float = PIXEL_PITCH_UM) -> float:
    """Sensor-plane frequency in cycles per pixel."""
    return freq_lp_per_mm * pixel_pitch_um / 1000.0


def nyquist_lp_per_mm(pixel_pitch_um: float = PIXEL_PITCH_UM) -> float:
    """Nyquist frequency of the sensor: 1 / (2 * pitch) (96.15 lp/mm at 5.2 um)."""
    return 1000.0 / (2.0 * pixel_pitch_um)


def px_per_period(freq_lp_per_mm: float, pixel_pitch_um: float = PIXEL_PITCH_UM) -> float:
    """Pixels per bar period at an image frequency (inf at zero frequency)."""
    c = cycles_per_px(freq_lp_per_mm, pixel_pitch_um)
    return math.inf if c == 0 else 1.0 / c
