"""Section 4.4: relative radiometry as steps on the bench.

Steps: [setup] camera settings and the LED mounted on the stage (manual), the stage homed;
then per field position p (mm) [position-p]: move the stage (or ask the operator when the bench
has no stage), switch the LED on through the controller, take the mask frame (gain 5) and the
measurement frame (gain 1) at 375 ms, switch the LED off; then [analysis]: Table 4.16.

The LED is switched off in a ``finally`` of every position step, so a fault between on and off
never leaves it lit (and the runner's safe state repeats the off).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.bars.roi import saturation_code
from benchlab.analysis.radiometry import (
    clipped_in_mask,
    mean_in_mask,
    radiometry_table,
    reading_mask,
)
from benchlab.drivers.errors import BenchlabError
from benchlab.protocols.engine import Step, StepContext
from benchlab.protocols.params import RadiometryParams, position_step_id

if TYPE_CHECKING:
    from benchlab.session import Session

LED_TARGET = "led"
MASK_FRAME = "mask"
MEASUREMENT_FRAME = "measurement"


def reading_mask_of(mask_frame: npt.NDArray[Any], measurement_frame: npt.NDArray[Any],
                    threshold_fraction: float) -> npt.NDArray[np.bool_]:
    """The pixels a reading averages (:func:`benchlab.analysis.radiometry.reading_mask`)."""
    return reading_mask(mask_frame, measurement_frame, threshold_fraction)


def reading_view(
    mask_frame: npt.NDArray[Any], measurement_frame: npt.NDArray[Any], threshold_fraction: float,
    *, linear: Callable[[Any], Any] | None = None,
) -> tuple[npt.NDArray[Any], npt.NDArray[np.bool_]]:
    """``(image, mask)`` of one position: the image a reading averages (the measurement
    frame, linearised by ``linear`` - the response calibration - when given) and the mask
    computed on that same image. The analysis and the report's overlay both use this, so the
    outline drawn is the mask averaged.

    Raises
    ------
    ValueError
        No LED in the frames (:func:`reading_mask_of`).
    """
    meas = np.asarray(measurement_frame)
    values = np.asarray(linear(meas)) if linear is not None else meas
    return values, reading_mask_of(mask_frame, values, threshold_fraction)


def saturation_code_of(frame: npt.NDArray[Any], bits: Any = None) -> float:
    """The code a frame clips at: its full scale from its recorded bit depth
    (:func:`~benchlab.analysis.sfr.measure.full_scale_of_frame`, as every analysis judges it),
    else what the data say (:func:`benchlab.analysis.bars.roi.saturation_code`), else its
    maximum."""
    from benchlab.analysis.sfr.measure import full_scale_of_frame

    raw = np.asarray(frame)
    top = full_scale_of_frame(raw, {"bits": bits})
    if top is not None:
        return float(top)
    code = saturation_code(raw, 1.0)
    return float(code) if code is not None else float(raw.max())


@dataclass(frozen=True)
class Reading:
    """One position's reading: mean inside the mask, the mask's size, and how many of its
    pixels are clipped in the measurement frame (then the mean is only a lower bound)."""

    mean_gray: float
    mask_pixels: int
    clipped_pixels: int
    saturation_code: float


def reading(
    mask_frame: npt.NDArray[Any], measurement_frame: npt.NDArray[Any], threshold_fraction: float,
    *, bits: Any = None, linear: Callable[[Any], Any] | None = None,
) -> Reading:
    """The reading of one position. ``bits``: the measurement frame's bit depth (its
    saturation code); ``linear``: the response calibration, applied before the mask and mean
    (clipping is counted on the raw codes).

    Raises
    ------
    ValueError
        No LED in the frames (:func:`reading_mask_of`).
    """
    meas = np.asarray(measurement_frame)
    values, mask = reading_view(mask_frame, meas, threshold_fraction, linear=linear)
    top = saturation_code_of(meas, bits)
    return Reading(mean_in_mask(values, mask), int(mask.sum()),
                   clipped_in_mask(meas, mask, top), top)


def clipped_note(r: Reading) -> str:
    """What a clipped row says instead of a number."""
    return (f"clipped: {r.clipped_pixels} of {r.mask_pixels} mask pixels at the saturation "
            f"code {r.saturation_code:g}; the mean ({r.mean_gray:.2f}) is only a lower bound "
            "- lower the LED current or the exposure")


class FrameContentError(BenchlabError):
    """A position's frames cannot be read (no LED in them): they are journalled as rejected,
    and a retry acquires new ones."""


class RadiometryProcedure:
    """The section 4.4 procedure for one parameter set."""

    name = "radiometry"

    def __init__(self, params: RadiometryParams) -> None:
        self.params = params

    def steps(self) -> list[Step]:
        p = self.params
        steps = [Step(
            "setup", "Radiometry set-up and camera settings", "manual", "section 4.4",
            self._setup,
            prompt="Radiometry set-up: LED (LED3R) on the stage facing the radial view, room "
            "dark.",
            restore=self._restore,
        )]
        for pos in p.positions_mm:
            steps.append(Step(
                position_step_id(pos), f"LED at {pos:g} mm: mask and measurement frames",
                "acquire", "section 4.4", self._position(pos),
                info={"position_mm": pos},
            ))
        steps.append(Step("analysis", "Analyse: Table 4.16", "analysis", "section 4.4",
                          self._analysis))
        return steps

    def _restore(self, ctx: StepContext) -> None:
        """Camera settings, LED mounted, stage homed (a resumed run may meet a fresh stage)."""
        ctx.bench.configure_camera(bits=self.params.bits)
        ctx.bench.mount(LED_TARGET)
        ctx.home_stage()

    def _setup(self, ctx: StepContext) -> None:
        ctx.ask(ctx.step.prompt or "")
        self._restore(ctx)

    def _position(self, pos: float) -> Any:
        def action(ctx: StepContext) -> None:
            p = self.params
            target = p.stage_target_mm(pos)
            if ctx.bench.has_stage:
                ctx.move_stage_mm(target)
            else:
                ctx.ask(f"Move the LED to field position {pos:g} mm.")
                ctx.bench.place_led_by_hand(pos)
            extra = {"position_mm": pos, "stage_mm": target, "led_channel": p.led_channel,
                     "led_current_ma": p.led_current_ma}
            ctx.check_abort()
            ctx.bench.led_on(p.led_channel, p.led_current_ma)
            try:
                mask = ctx.acquire(MASK_FRAME, exposure_ms=p.exposure_ms, gain=p.mask_gain,
                                   extra=extra)
                meas = ctx.acquire(MEASUREMENT_FRAME, exposure_ms=p.exposure_ms,
                                   gain=p.measurement_gain, extra=extra)
            finally:
                ctx.bench.led_off(p.led_channel)
            try:
                r = reading(mask, meas, p.mask_threshold_fraction, bits=p.bits)
            except ValueError as exc:  # the frames, not the bench: a retry takes new ones
                ctx.reject_frames((MASK_FRAME, MEASUREMENT_FRAME), str(exc))
                raise FrameContentError(f"LED at {pos:g} mm: {exc}; the frames are set aside "
                                        "and a retry takes new ones") from exc
            if r.clipped_pixels:
                ctx.session.log_event("frames_clipped", step=ctx.step.id,
                                      clipped_pixels=r.clipped_pixels,
                                      mask_pixels=r.mask_pixels)
            # a clipped mean is no number: the live view says "clipped", as Table 4.16 will
            shown: float | str = (r.mean_gray if not r.clipped_pixels else
                                  f"clipped ({r.clipped_pixels} px at {r.saturation_code:g})")
            ctx.report({"position_mm": pos, "measured_mean_gray": shown,
                        "mask_pixels": r.mask_pixels, "clipped_pixels": r.clipped_pixels})

        return action

    def _analysis(self, ctx: StepContext) -> None:
        self.analyze(ctx.session, ctx.runner.estimator)

    def analyze(self, session: Session, estimator: str | None) -> Path:
        tables, summary = analyze_radiometry(session, self.params)
        return Path(session.write_results(tables, summary=summary, estimator="led-mask-mean"))


def analyze_radiometry(
    session: Session, params: RadiometryParams
) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any]]:
    """Table 4.16 from a session's frames (measured normalised vs simulated normalised).

    When the session's bench configuration references a response calibration (``benchlab run
    characterise``), each measurement frame is linearised with it before the reading; the
    summary's ``linearised`` records which file (or None).
    """
    from benchlab.calibration import session_linearisation

    linear, record = session_linearisation(session, params.measurement_gain, params.bits)
    rows: list[dict[str, Any]] = []
    skipped: list[dict[str, Any]] = []
    for pos, sim in zip(params.positions_mm, params.simulated_irradiance_mw_per_mm2, strict=True):
        sid = position_step_id(pos)
        frames = session.step_frames(sid)
        if not {MASK_FRAME, MEASUREMENT_FRAME} <= set(frames):
            continue  # not measured yet (an interrupted session): its results are partial
        mask, _ = session.load_frame(sid, MASK_FRAME)
        meas, meta = session.load_frame(sid, MEASUREMENT_FRAME)
        try:
            got = reading(mask, meas, params.mask_threshold_fraction,
                          bits=meta.get("bits", params.bits), linear=linear)
        except ValueError as exc:  # these frames hold no reading: say so, analyse the rest
            files = [frames[n].relative_to(session.path).as_posix()
                     for n in (MASK_FRAME, MEASUREMENT_FRAME)]
            skipped.append({"step": sid, "position_mm": pos, "frames": files,
                            "reason": str(exc)})
            continue
        rows.append({"position_mm": pos, "simulated": sim, "reading": got})
    if not rows:
        why = "; ".join(f"{s['step']} ({', '.join(s['frames'])}): {s['reason']}"
                        for s in skipped)
        raise BenchlabError(f"{session.path}: no LED position measured yet; nothing to analyse"
                            if not skipped else f"{session.path}: no position has a reading: "
                            f"{why}")
    # Normalised over the clean rows only: a clipped mean is a lower bound, never a number.
    clean = [r for r in rows if not r["reading"].clipped_pixels]
    try:
        table = ({t.field_position_mm: t for t in radiometry_table(
            [r["position_mm"] for r in clean], [r["simulated"] for r in clean],
            [r["reading"].mean_gray for r in clean])} if clean else {})
    except ValueError as exc:  # e.g. every clean row's simulated irradiance is 0
        raise BenchlabError(f"{session.path}: Table 4.16 cannot be normalised over "
                            f"{[r['position_mm'] for r in clean]} mm: {exc}") from exc
    top_sim = max((float(r["simulated"]) for r in clean), default=0.0)
    out = []
    warnings = []
    for r in rows:
        rd: Reading = r["reading"]
        t = table.get(float(r["position_mm"])) if not rd.clipped_pixels else None
        sim_norm = (t.simulated_normalised if t else
                    float(r["simulated"]) / top_sim if top_sim > 0 else None)
        row: dict[str, Any] = {
            "position_mm": r["position_mm"],
            "simulated_mw_per_mm2": r["simulated"],
            "measured_mean_gray": round(rd.mean_gray, 4) if t is not None else None,
            "simulated_normalised": round(sim_norm, 4) if sim_norm is not None else None,
            "measured_normalised": round(t.measured_normalised, 4) if t else None,
            "difference": round(t.difference, 4) if t else None,
            "mask_pixels": rd.mask_pixels,
            "clipped_pixels": rd.clipped_pixels,
            "note": "",
        }
        if rd.clipped_pixels:
            row["note"] = clipped_note(rd)
            warnings.append(f"{position_step_id(r['position_mm'])}: {row['note']}")
        out.append(row)
    for s in skipped:
        warnings.append(f"{s['step']}: skipped ({', '.join(s['frames'])}): {s['reason']}")
    summary = {"procedure": "radiometry", "positions_mm": list(params.positions_mm),
               "exposure_ms": params.exposure_ms, "mask_gain": params.mask_gain,
               "measurement_gain": params.measurement_gain, "linearised": record,
               "normalised_over_mm": [r["position_mm"] for r in clean],
               "clipped_positions_mm": [r["position_mm"] for r in rows
                                        if r["reading"].clipped_pixels],
               "skipped": skipped, "warnings": warnings}
    return {"table_4_16": out}, summary
