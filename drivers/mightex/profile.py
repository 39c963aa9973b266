"""Per-model facts of the Mightex buffer cameras, as one profile the driver and simulator share.

The driver reads the profile of the model it *believes* it talks to; the simulator is built
from a profile of the model it *is*. A test that gives them different profiles shows whether
the driver notices (``tests/drivers/test_mightex_profile.py``).

Sources (tags of ``shared/docs/device-protocols.md``; every fact and its source is listed in
``docs/hardware/protocol-facts.md``):

* MCE-B013-U (MT9M001 CMOS): no public document names it. Its defaults follow the CMOS
  buffer-camera client [SH] (BTN-B013U, same sensor): a 2-byte exposure field in 0.05 ms
  units (max 750 ms), a 10-bit mode (that the MT9M001 is natively 10-bit is its data sheet's,
  not a protocol source's: assumed), 0.05 ms frame-time units. The 8 and 12-bit modes are the
  v1.0.6 document's [GC], written for the CCD camera; 12 bits on this sensor is assumed, and
  ``benchlab doctor`` checks every depth on the bench (``[camera] bit_depths``).
* The trailer layout is [GC]'s CCD struct: assumed for this camera. Its row/column order and
  its timestamp unit (1 ms in the vendor guide's text, 0.1 ms in its worked example) are
  profile facts ``benchlab doctor`` settles (``trailer_order``, ``timestamp_unit_ms``).
* Timing: ~100 ms after the work-mode command and ~3 s after power-up before the camera
  answers reliably: assumed ([SS] asks > 200 ms after the clock command, [SH] sleeps 2 s
  after set-up; no document gives a figure for these two).
* Buffer full: assumed that new frames are dropped ([GC] prints "camera buffer full" but no
  source says which frames a full buffer keeps); a grab clears the buffer first, so either
  policy gives the same frames.
"""

from __future__ import annotations

from dataclasses import dataclass

from benchlab.drivers.errors import SettingOutOfRangeError

#: The MCE-B013-U's PID is not public; the BTN-B013U (same sensor) uses 0x0428.
DEFAULT_PID = 0x0428
BUFFER_FULL_POLICIES = ("drop_new", "overwrite_oldest")
#: The trailer's first two words: line length then line count ([GC]'s CCD layout, assumed for
#: the CMOS camera), or the other way round. Only a non-square frame tells them apart.
TRAILER_ORDERS = ("row_column", "column_row")
#: Timestamp units the vendor guide gives: 1 ms in its text, 0.1 ms in its worked example.
TIMESTAMP_UNITS_MS = (1.0, 0.1)
#: Bin code -> rows combined into one (CGN-B013 CCD table; binning is vertical only). The
#: MT9M001 CMOS models use code 0 (no binning) only.
BIN_ROWS = {0x00: 1, 0x81: 2, 0x82: 3, 0x83: 4, 0x03: 4}


@dataclass(frozen=True)
class CameraSpec:
    """What one camera model accepts and how it behaves (see the module docstring)."""

    model: str
    pid: int
    protocol: str
    exposure_bytes: int
    exposure_max_counts: int
    frame_time_unit_ms: float
    bit_depths: tuple[int, ...]
    max_width: int
    max_height: int
    #: Sensor pixel pitch, um (the MT9M001: 5.2 um square pixels, binning 1).
    pixel_pitch_um: float = 5.2
    exposure_unit_ms: float = 0.05
    min_size: int = 8
    size_step: int = 4
    bin_codes: tuple[int, ...] = (0,)
    gain_raw_min: int = 1
    gain_raw_max: int = 64
    max_buffer_count: int = 24
    #: Pause after the work-mode command (0x30) before the next command, seconds.
    work_mode_wait_s: float = 0.1
    #: How long the camera may stay silent after power-up or reset, seconds.
    power_up_wait_s: float = 3.0
    #: What a full camera buffer does with a new frame: "drop_new" or "overwrite_oldest".
    buffer_full: str = "drop_new"
    #: A frame's trailer may differ from the settings by this much and still be taken (the
    #: camera can raise an exposure to its minimum or clamp a gain); the trailer's values are
    #: then the frame's truth. Further off, the profile is wrong: the driver refuses the frame.
    exposure_tolerance_ms: float = 1.0
    exposure_tolerance_fraction: float = 0.02
    gain_tolerance_raw: int = 1
    #: Order of the trailer's first two words (:data:`TRAILER_ORDERS`); ``benchlab doctor``
    #: settles it with a full 1280 x 1024 frame.
    trailer_order: str = "row_column"
    #: Unit of the trailer's 16-bit timestamp, ms (:data:`TIMESTAMP_UNITS_MS`); ``benchlab
    #: doctor`` settles it against the host clock.
    timestamp_unit_ms: float = 1.0

    def __post_init__(self) -> None:
        if self.buffer_full not in BUFFER_FULL_POLICIES:
            raise SettingOutOfRangeError(
                f"camera profile {self.model}: buffer_full {self.buffer_full!r} is not one of "
                f"{', '.join(BUFFER_FULL_POLICIES)}")
        if self.exposure_bytes not in (2, 4):
            raise SettingOutOfRangeError(
                f"camera profile {self.model}: exposure_bytes must be 2 or 4, "
                f"got {self.exposure_bytes!r}")
        if self.trailer_order not in TRAILER_ORDERS:
            raise SettingOutOfRangeError(
                f"camera profile {self.model}: trailer_order {self.trailer_order!r} is not one "
                f"of {', '.join(TRAILER_ORDERS)}")
        if self.timestamp_unit_ms not in TIMESTAMP_UNITS_MS:
            raise SettingOutOfRangeError(
                f"camera profile {self.model}: timestamp_unit_ms {self.timestamp_unit_ms!r} is "
                f"not one of {', '.join(map(str, TIMESTAMP_UNITS_MS))}")

    def pixel_size_um(self, bin_code: int) -> tuple[float, float]:
        """A pixel's size on the sensor ``(x, y)``, um: the pitch, times the rows a bin code
        combines (:data:`BIN_ROWS`; vertical binning only) in y."""
        return self.pixel_pitch_um, self.pixel_pitch_um * BIN_ROWS.get(int(bin_code), 1)

    @property
    def exposure_max_ms(self) -> float:
        return self.exposure_max_counts * self.exposure_unit_ms

    @property
    def frame_time_max_ms(self) -> float:
        return 0xFFFF * self.frame_time_unit_ms

    def exposure_within_tolerance(self, set_counts: int, trailer_counts: int) -> bool:
        """Whether a trailer exposure is the set one, give or take the camera's own limits."""
        set_ms = set_counts * self.exposure_unit_ms
        off_ms = abs(trailer_counts - set_counts) * self.exposure_unit_ms
        return off_ms <= max(self.exposure_tolerance_ms,
                             self.exposure_tolerance_fraction * set_ms)


SPECS: dict[str, CameraSpec] = {
    # CMOS defaults ([SH], BTN-B013U, same MT9M001 sensor); 12-bit from v1.0.6 (assumed).
    "MCE-B013-U": CameraSpec(
        model="MCE-B013-U", pid=DEFAULT_PID, protocol="1.0.5", exposure_bytes=2,
        exposure_max_counts=15_000, frame_time_unit_ms=0.05, bit_depths=(8, 10, 12),
        max_width=1280, max_height=1024,
    ),
    # The v1.0.6 document's layout [GC]: 4-byte exposure up to 200 s, 0.1 ms frame time.
    "MCE-B013-U/v1.0.6": CameraSpec(
        model="MCE-B013-U/v1.0.6", pid=DEFAULT_PID, protocol="1.0.6", exposure_bytes=4,
        exposure_max_counts=4_000_000, frame_time_unit_ms=0.1, bit_depths=(8, 12),
        max_width=1280, max_height=1024,
    ),
    # Protocol v1.0.5 [SH]: 2-byte exposure (0.05 .. 750 ms), 8 and 10 bits.
    "BTN-B013U": CameraSpec(
        model="BTN-B013U", pid=0x0428, protocol="1.0.5", exposure_bytes=2,
        exposure_max_counts=15_000, frame_time_unit_ms=0.05, bit_depths=(8, 10),
        max_width=1280, max_height=1024,
    ),
}


#: The bench's camera (the thesis's MCE-B013-U): its sensor geometry is what analysis assumes
#: of a frame whose metadata does not say, and what the simulated camera is built with.
BENCH_CAMERA = SPECS["MCE-B013-U"]
PIXEL_PITCH_UM = BENCH_CAMERA.pixel_pitch_um
SENSOR_WIDTH_PX = BENCH_CAMERA.max_width
SENSOR_HEIGHT_PX = BENCH_CAMERA.max_height

def spec_for(model: str) -> CameraSpec:
    """The profile of ``model``; raises ``SettingOutOfRangeError`` listing the known models."""
    try:
        return SPECS[model]
    except KeyError:
        raise SettingOutOfRangeError(
            f"unknown camera model {model!r}: known models are {', '.join(sorted(SPECS))}"
        ) from None
