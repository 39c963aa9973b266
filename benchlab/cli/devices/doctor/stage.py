"""Step 8: the stage's identity, homing and the measured scale."""

from __future__ import annotations

import contextlib
import math
from typing import Any

from benchlab.cli.devices.doctor.base import (
    GAUGE_ERROR_MM,
    SCALE_MATCH,
    SCALE_MOVE_MAX_MM,
    DoctorBase,
    _one_line,
)


class StageSteps(DoctorBase):
    """Step 8: the stage's identity, homing and the measured scale."""

    # ---- 8: the stage ---------------------------------------------------------------------
    def open_stage(self, stack: contextlib.ExitStack) -> Any:
        from benchlab.drivers.apt.stage import AptStage

        step = "8 stage identity"
        cfg = self.config.stage
        if cfg is None:
            self.add(step, "skip", "no [stage] section in the bench file")
            return None
        port = self._serial_port("stage", cfg.port)
        if not port:
            self.add(step, "FAIL", "no [stage] port" + self._ports_seen(), "set [stage] port "
                     "(a path, or hwgrep://0403:FAF0 or hwgrep://SERIAL for a Thorlabs cube)")
            return None
        stage = stack.enter_context(AptStage(
            port, counts_per_mm=cfg.counts_per_mm, travel_mm=cfg.travel_mm,
            completion_tolerance_counts=cfg.tolerance_counts))
        info = stage.info
        self.add(step, "ok", f"{info.model} serial {info.serial}, firmware {info.firmware_str}, "
                 f"{cfg.counts_per_mm:g} counts/mm assumed")
        return stage

    def check_stage(self, stage: Any) -> None:
        homed = self.attempt("8 stage homing", "the stage did not report homed: check that "
                             "the actuator's cable is in and nothing blocks the reverse end",
                             lambda: self.check_homing(stage))
        if not homed:
            self.skip(("8 stage scale",), "the stage is not homed (step 8 homing)")
            return
        self.attempt("8 stage scale", "the measured move did not end as commanded",
                     lambda: self.check_scale(stage))

    def check_homing(self, stage: Any) -> bool:
        if not self._ask("home the stage (it drives to its reverse limit)?"):
            self.add("8 stage homing", "skip", "not homed (answered no)")
            return False
        from benchlab.drivers.errors import DeviceTimeoutError

        home = stage.get_home_params()
        timeout_s = stage.home_timeout_s(home) / self.stage_time_scale + stage.timeout_s
        try:
            stage.home(timeout_s=timeout_s)
        except DeviceTimeoutError as exc:
            lo, hi = stage.travel_mm
            fast = (f"; simulated time runs {self.stage_time_scale:g}x fast"
                    if self.stage_time_scale != 1 else "")
            raise DeviceTimeoutError(
                f"the controller never reported homed within {timeout_s:.3g} s, the time "
                f"homing from anywhere in {hi - lo:g} mm takes at its home velocity of "
                f"{home.velocity_mm_s:g} mm/s (read from it){fast}; the stage was stopped "
                f"({_one_line(exc)})") from exc
        self.add("8 stage homing", "ok", f"homed at {stage.position_mm:.4f} mm (home velocity "
                 f"{home.velocity_mm_s:g} mm/s read from the controller)")
        return True

    def check_scale(self, stage: Any) -> bool:
        """A relative move from home, measured (a zeroed dial gauge; the simulator's carriage
        on the simulated bench): the counts/mm of the actuator."""
        from benchlab.drivers.apt.protocol import ACTUATOR_COUNTS_PER_MM

        cfg = self.config.stage
        assert cfg is not None
        step = "8 stage scale"
        lo, hi = cfg.travel_mm
        start_mm = stage.position_mm
        distance = round(min(SCALE_MOVE_MAX_MM, 0.8 * (hi - lo), hi - start_mm), 3)
        if distance <= 0:
            self.add(step, "skip", f"the scale was NOT measured: home ({start_mm:g} mm) is not "
                     f"below the travel's upper end ({hi:g} mm)", "check [stage] travel_mm")
            return True
        gauge = self.sims.get("stage") is not None or (
            self.replaying and self.simulate)
        if not gauge and not self._ask("zero the dial gauge against the carriage now; done?"):
            self.add(step, "skip", "the scale was NOT measured (no zeroed dial gauge)")
            return True
        if not self._ask(f"move the stage {distance:g} mm forward from home, to measure the "
                         "scale?"):
            self.add(step, "skip", "the scale was NOT measured (no measured move: answered no)")
            return True
        start = self._physical_mm()
        stage.move_by_mm(distance)
        end = self._physical_mm()
        self._landing(stage, start_mm + distance)
        moved = end - start if start is not None and end is not None else self._measure(
            f"dial gauge reading now, mm (commanded {distance:g} mm)?")
        if moved is None or moved <= 0:
            self.add(step, "skip", "the scale was NOT measured (no dial gauge reading given)")
            return True
        counts = round(distance * cfg.counts_per_mm)
        measured = counts / moved
        name, value = min(ACTUATOR_COUNTS_PER_MM.items(),
                          key=lambda kv: abs(kv[1] / measured - 1))
        off = abs(value / measured - 1)
        moved_how = (f"a relative move of {distance:g} mm from home (travel {lo:g}..{hi:g} "
                     "mm)")
        how_sure = (f"a {GAUGE_ERROR_MM:g} mm gauge error over {moved:.3f} mm is "
                    f"{100 * GAUGE_ERROR_MM / moved:.2f} %; the known scales are 0.73 % apart"
                    if start is None else "measured by the simulator's carriage")
        if off > SCALE_MATCH:
            self.add(step, "FAIL", f"{measured:.1f} counts/mm measured over {moved:.3f} mm: no "
                     f"known actuator within {100 * SCALE_MATCH:g} % ({how_sure})",
                     "set [stage] counts_per_mm to the measured value")
        elif math.isclose(value, cfg.counts_per_mm):
            self.add(step, "ok", f"{measured:.1f} counts/mm measured over {moved:.3f} mm by "
                     f"{moved_how}: {name} ({value:g}, {100 * off:.2f} % off), as the bench "
                     f"file says ({how_sure})")
        else:
            self.learned[("stage", "actuator")] = name
            self.add(step, "FAIL", f"{measured:.1f} counts/mm measured: this is "
                     f"{name} ({value:g}), the bench file assumes {cfg.counts_per_mm:g} "
                     f"({how_sure})", f'set [stage] actuator = "{name}" (written to the '
                     "bench file)")
        return True

    def _landing(self, stage: Any, target_mm: float) -> None:
        """How far from its target the carriage settled (counts), against the tolerance."""
        cfg = self.config.stage
        assert cfg is not None
        off = round((stage.position_mm - target_mm) * cfg.counts_per_mm)
        if abs(off) > 5:  # more than a servo's usual settling: worth a line
            self.add("8 stage landing", "warn", f"the move settled {off:+d} counts off its "
                     f"target (within the bench file's tolerance of {cfg.tolerance_counts} "
                     "counts)", f"fine as it is; to refuse such moves set [stage] "
                     f"tolerance_counts below {abs(off)}")

    def _physical_mm(self) -> float | None:
        sim = self.sims.get("stage")
        if sim is None and not (self.replaying and self.simulate):
            return None
        return self.outside.get("carriage-mm", lambda: float(sim.position_mm))  # type: ignore[union-attr]
