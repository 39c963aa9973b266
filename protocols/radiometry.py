"""Section 4.4: relative radiometry as steps on the bench.

Steps: [setup] camera settings and the LED mounted on the stage (manual), the stage homed;
then per field position p (mm) [position-p]: move the stage (or ask the operator when the bench
has no stage), switch the LED on through the controller, take the mask frame (gain 5) and the
measurement frame (gain 1) at 375 ms, switch the LED off; then [analysis]: Table 4.16.

The LED is switched off in a ``finally`` of every position step, so a fault between on and off
never leaves it lit (and the runner's safe state repeats the off).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.radiometry import led_mask, mean_in_mask, radiometry_table
from benchlab.drivers.errors import BenchlabError, DeviceError
from benchlab.protocols.engine import Step, StepContext
from benchlab.protocols.params import RadiometryParams

if TYPE_CHECKING:
    from benchlab.session import Session

LED_TARGET = "led"
MASK_FRAME = "mask"
MEASUREMENT_FRAME = "measurement"


def position_step_id(position_mm: float) -> str:
    return f"position-{position_mm:g}"


def mask_of(mask_frame: npt.NDArray[Any], threshold_fraction: float) -> npt.NDArray[np.bool_]:
    """LED mask: pixels of the high-gain frame above ``threshold_fraction`` of the way from its
    median (the dark background) to its peak; the largest blob only."""
    img = np.asarray(mask_frame, dtype=np.float64)
    background, peak = float(np.median(img)), float(img.max())
    return led_mask(img, threshold=background + threshold_fraction * (peak - background))


def reading(
    mask_frame: npt.NDArray[Any], measurement_frame: npt.NDArray[Any], threshold_fraction: float
) -> tuple[float, int]:
    """Mean gray of the measurement frame inside the LED mask, and the mask's pixel count."""
    mask = mask_of(mask_frame, threshold_fraction)
    return mean_in_mask(measurement_frame, mask), int(mask.sum())


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
        if ctx.bench.has_stage:
            try:
                ctx.bench.home_stage(abort=ctx.runner.abort)
            except DeviceError:
                ctx.check_abort()  # stopped by the abort key or a quit: an abort, not a fault
                raise

    def _setup(self, ctx: StepContext) -> None:
        ctx.ask(ctx.step.prompt or "")
        self._restore(ctx)

    def _position(self, pos: float) -> Any:
        def action(ctx: StepContext) -> None:
            p = self.params
            target = p.stage_target_mm(pos)
            if ctx.bench.has_stage:
                ctx.check_abort()
                try:
                    ctx.bench.move_stage_mm(target, abort=ctx.runner.abort)
                except DeviceError:
                    ctx.check_abort()  # stopped by the abort key: an abort, not a fault
                    raise
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
            value, n = reading(mask, meas, p.mask_threshold_fraction)
            ctx.report({"position_mm": pos, "measured_mean_gray": value, "mask_pixels": n})

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
    from benchlab.protocols.characterise_calibration import session_linearisation

    linear, record = session_linearisation(session, params.measurement_gain, params.bits)
    rows: list[Mapping[str, Any]] = []
    for pos, sim in zip(params.positions_mm, params.simulated_irradiance_mw_per_mm2, strict=True):
        sid = position_step_id(pos)
        if not {MASK_FRAME, MEASUREMENT_FRAME} <= set(session.step_frames(sid)):
            continue  # not measured yet (an interrupted session): its results are partial
        mask, _ = session.load_frame(sid, MASK_FRAME)
        meas, _ = session.load_frame(sid, MEASUREMENT_FRAME)
        value, n = reading(mask, linear(meas), params.mask_threshold_fraction)
        rows.append({"position_mm": pos, "simulated": sim, "measured": value, "mask_pixels": n})
    if not rows:
        raise BenchlabError(f"{session.path}: no LED position measured yet; nothing to analyse")
    table = radiometry_table([r["position_mm"] for r in rows], [r["simulated"] for r in rows],
                             [r["measured"] for r in rows])
    out = []
    for r, t in zip(rows, table, strict=True):
        out.append({
            "position_mm": r["position_mm"],
            "simulated_mw_per_mm2": r["simulated"],
            "measured_mean_gray": round(r["measured"], 4),
            "simulated_normalised": round(t.simulated_normalised, 4),
            "measured_normalised": round(t.measured_normalised, 4),
            "difference": round(t.difference, 4),
            "mask_pixels": r["mask_pixels"],
        })
    summary = {"procedure": "radiometry", "positions_mm": list(params.positions_mm),
               "exposure_ms": params.exposure_ms, "mask_gain": params.mask_gain,
               "measurement_gain": params.measurement_gain, "linearised": record}
    return {"table_4_16": out}, summary
