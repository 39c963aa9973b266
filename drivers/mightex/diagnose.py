"""Frame checks for bringing a camera up (``benchlab doctor``): is the decode right, is the
exposure unit right. Pure functions of frames and trailer values; each returns what is wrong,
in words, or nothing.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

#: A measured frame period may differ from the set exposure by this fraction.
PERIOD_TOLERANCE = 0.15


def depth_findings(pixels: npt.NDArray[np.integer], bits: int) -> list[str]:
    """What a frame's codes say about its bit depth and packing (empty: plausible).

    A packing or depth error shows as a pattern: codes above the range, low bits that are
    never set (data with fewer bits, MSB-aligned), the 10-bit client's packing read with the
    12-bit rule (bits 2 and 3 never set; 1023 reads 4083), or most codes in the used range
    missing.
    """
    values = np.asarray(pixels).ravel().astype(np.int64)
    top = (1 << bits) - 1
    found: list[str] = []
    vmax = int(values.max())
    if vmax > top:
        return [f"codes up to {vmax} in a {bits}-bit frame (max {top}): wrong decode"]
    never_set, _ = never_set_bits_finding(values, bits)
    if never_set:
        found.append(never_set)
    lo, hi = np.percentile(values, [1, 99])
    span = int(hi - lo) + 1
    if not found and span >= 64 and values.size >= 8 * span:
        used = np.unique(values[(values >= lo) & (values <= hi)]).size
        if used < span / 2:
            found.append(f"{100 * (1 - used / span):.0f} % of the codes between {int(lo)} and "
                         f"{int(hi)} never occur (missing codes: a packing error)")
    if np.mean(values == top) > 0.5:
        found.append(f"more than half the pixels at {top}: saturated, lower the light")
    return found


def never_set_bits_finding(pixels: npt.NDArray[np.integer], bits: int
                           ) -> tuple[str | None, bool]:
    """Bits of a frame deeper than 8 bits that are never set: the 10-bit client's packing
    read with the 12-bit rule (bits 2 and 3), or MSB-aligned data with fewer significant
    bits (the lowest ones). Returns ``(finding or None, decided)``; ``decided`` is False when
    the frame has too little spread (< 16 codes) to tell."""
    values = np.asarray(pixels).ravel().astype(np.int64)
    vmax, vmin = int(values.max()), int(values.min())
    if bits <= 8 or vmax - vmin < 16:
        return None, bits <= 8
    ored = int(np.bitwise_or.reduce(values - vmin))
    low_zero = (ored & -ored).bit_length() - 1 if ored else 0
    if bits == 12 and vmax >= 64 and not np.any(values & 0b1100):
        return ("bits 2 and 3 are never set: 10-bit data packed as the CMOS client does, "
                "decoded with the 12-bit rule (1023 reads 4083)"), True
    if low_zero >= 2:
        return (f"the lowest {low_zero} bits never change: the data has {bits - low_zero} "
                f"significant bits, not {bits} (MSB-aligned)"), True
    return None, True


def period_finding(exposure_ms: float, period_ms: float) -> str | None:
    """Whether the measured frame period (trailer timestamps of consecutive frames, free
    running, exposure longer than readout) fits the set exposure; else what the unit is."""
    ratio = period_ms / exposure_ms
    if abs(ratio - 1) <= PERIOD_TOLERANCE:
        return None
    return (f"frames come every {period_ms:g} ms at a set exposure of {exposure_ms:g} ms: "
            f"the camera's exposure unit is {ratio:.3g} x the profile's")


def ratio_finding(dark: float, short: float, long: float, factor: float) -> str | None:
    """Signal above dark of an exposure ``factor`` times longer should be ``factor`` times
    larger (linearity, and the unit of the exposure field)."""
    s1, s2 = short - dark, long - dark
    if s1 <= 0:
        return f"no signal above dark ({short:.1f} vs {dark:.1f}): is the light on?"
    ratio = s2 / s1
    if abs(ratio / factor - 1) <= 0.1:
        return None
    return (f"signal ratio {ratio:.3g} for exposures {factor:g} x apart: not linear, or "
            "the exposure is not what was set")
