"""Camera characterisation on the bench (EMVA 1288-style photon transfer) as steps.

Steps: [setup] uniform illumination of the sensor (manual), camera geometry, the flat target
(simulated bench: the sensor truth of ``[simulator]``); per (gain, bits) [sweep-gG-bB]: a probe
doubles the exposure until the frame saturates, then the exposure sweep (two lit frames and two
dark frames per step) and the L-frame lit / dark stacks for DSNU / PRNU; then [analysis]: the
figures per gain, the results tables and the response calibration for the bench configuration.

The LED is switched off in a ``finally`` around every lit pair, so a fault or an abort never
leaves it lit (and the runner's safe state repeats the off). Every decision of the sweep (the
probe's saturation exposure) is derived from saved frames, so a resumed run rebuilds the same
exposure list and reuses every frame already on disk.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.calibration import write_calibration
from benchlab.drivers.errors import SettingOutOfRangeError
from benchlab.protocols.characterise.analysis import (
    CURRENTS_EVENT,
    TRUTH_EVENT,
    analyze_characterise,
    config_step_id,
)
from benchlab.protocols.characterise.params import CharacteriseParams
from benchlab.protocols.engine import Step, StepContext

FLAT_TARGET = "flat"
EXPOSURE_STEP_MS = 0.05
#: A saturated probe start is halved at most this often (600 ms -> 0.15 ms) before the run is
#: refused.
MAX_PROBE_HALVINGS = 12
#: The current grid when no controller says otherwise (FA/FV/XA/XV: 0.1 mA); on the bench the
#: grid is the LED controller's own current step (``LightSource.current_step_ma``).
CURRENT_STEP_MA = 0.1
SETUP_PROMPT = ("Characterisation set-up: uniform illumination of the sensor (diffuser or "
                "back-lit flat target, lens off or defocused), lit by the LED; room dark. Dark "
                "frames are taken with the LED off.")


def _round_to(value: float, step: float, maximum: float) -> float:
    """``value`` on the grid of ``step`` (a whole number of steps, at least one, at most
    ``maximum``, itself on the grid); rounded to 9 decimals so 3 x 0.1 reads 0.3."""
    return round(min(max(round(value / step), 1) * step, maximum), 9)


def sweep_points(params: CharacteriseParams, x_sat: float,
                 current_step_ma: float | None = None) -> list[float]:
    """The swept values (exposure ms, or LED mA with ``vary = "led_current"``) for a
    saturating value ``x_sat``: log-spaced near dark, even in the middle, dense around
    saturation and beyond; rounded to the camera's 0.05 ms steps (or the LED controller's
    ``current_step_ma``: 1 mA on most SLC modules, 5 mA on CA, 0.1 mA on FA; default 0.1)."""
    p = params
    step, start, maximum = _sweep_axis(p, current_step_ma)
    lo = max(step, min(0.05 * x_sat, start) / 4)
    log_part = np.geomspace(lo, max(0.05 * x_sat, lo * 1.01), p.log_steps)
    lin_part = np.linspace(0.08 * x_sat, 0.85 * x_sat, p.linear_steps)
    near = np.linspace(0.87 * x_sat, p.beyond_saturation * x_sat, p.near_saturation_steps)
    return sorted({_round_to(float(x), step, maximum)
                   for x in np.concatenate([log_part, lin_part, near])})


def sweep_exposures(params: CharacteriseParams, t_sat_ms: float) -> list[float]:
    """:func:`sweep_points` of an exposure sweep."""
    return sweep_points(params, t_sat_ms)


def _sweep_axis(p: CharacteriseParams,
                current_step_ma: float | None = None) -> tuple[float, float, float]:
    """(rounding step, probe start, maximum) of the swept quantity. An LED current sweep
    stays on the controller's current step: the maximum is ``led.current_ma`` rounded down
    to it, the probe start rounded to it (at least one step)."""
    if p.vary == "led_current":
        step = current_step_ma or CURRENT_STEP_MA
        maximum = round(math.floor(p.led_current_ma / step + 1e-9) * step, 9)
        if maximum < step:
            raise SettingOutOfRangeError(
                f"led.current_ma {p.led_current_ma:g} mA is below the LED controller's "
                f"{step:g} mA current step: the current sweep would light nothing")
        return step, _round_to(p.probe_start_ma, step, maximum), maximum
    return EXPOSURE_STEP_MS, p.probe_start_ms, p.max_exposure_ms


def probe_saturation(
    grab: Callable[[str, float, bool], npt.NDArray[Any]], params: CharacteriseParams, bits: int,
    current_step_ma: float | None = None,
) -> tuple[float, bool]:
    """Value of the swept quantity at which the lit frame saturates: double it from the probe
    start until the median stops rising (< 3 % for a doubling) or reaches the top code, then
    extrapolate the last clearly unsaturated probe linearly to the saturated level. When no
    probe is clearly unsaturated (the probe start already saturates), halve it from the probe
    start (``probe-hNN`` frames, at most :data:`MAX_PROBE_HALVINGS`) until one is.

    ``grab(name, value, lit)`` returns a saved frame. Returns ``(x_sat, found)``; ``found`` is
    False when even the maximum (exposure or LED current) did not saturate.

    Raises
    ------
    SettingOutOfRangeError
        Naming ``sweep.probe_start_ms`` (``_ma``) when even the halved probes saturate.
    """
    step, start, maximum = _sweep_axis(params, current_step_ma)
    top = (1 << bits) - 1
    dark = float(np.median(grab("probe-dark", start, False)))
    x = start
    history: list[tuple[float, float]] = []
    for i in range(40):
        level = float(np.median(grab(f"probe-{i:02d}", x, True)))
        history.append((x, level))
        rising = len(history) < 2 or level > history[-2][1] + 0.03 * (history[-2][1] - dark)
        if level >= top or not rising:
            break
        if x >= maximum:
            return maximum, False
        x = min(round(2.0 * x, 9), maximum)  # twice a point on the grid is on it
    sat_level = history[-1][1]
    below = [(xx, lv) for xx, lv in history if lv - dark < 0.9 * (sat_level - dark)]
    if not below:  # the probe start saturates already: halve it until it does not
        below = _halve_probe(grab, params, (start, step, maximum), dark, sat_level)
    if below[-1][1] <= dark:
        return history[-1][0], True
    x_ok, level_ok = below[-1]
    return x_ok * (sat_level - dark) / (level_ok - dark), True


def _halve_probe(
    grab: Callable[[str, float, bool], npt.NDArray[Any]], params: CharacteriseParams,
    axis: tuple[float, float, float], dark: float, sat_level: float,
) -> list[tuple[float, float]]:
    """The first probe below the probe start (halved on the grid of ``axis`` = (start, step,
    maximum), at most :data:`MAX_PROBE_HALVINGS` times) clearly under the saturated level:
    ``[(x, level)]``."""
    start, step, maximum = axis
    field, unit = (("sweep.probe_start_ma", "mA") if params.vary == "led_current"
                   else ("sweep.probe_start_ms", "ms"))
    x = start
    for k in range(1, MAX_PROBE_HALVINGS + 1):
        half = _round_to(x / 2.0, step, maximum)
        if half >= x:
            break  # the grid's smallest value, still saturated
        x = half
        level = float(np.median(grab(f"probe-h{k:02d}", x, True)))
        if level - dark < 0.9 * (sat_level - dark):
            return [(x, level)]
    raise SettingOutOfRangeError(
        f"{field} {start:g} {unit}: the lit frame is saturated there and still at {x:g} {unit} "
        f"(halved {MAX_PROBE_HALVINGS} times at most, down to the {step:g} {unit} step): lower "
        f"{field}, the LED current or the light")


class CharacteriseProcedure:
    """The camera characterisation for one parameter set."""

    name = "characterise"

    def __init__(self, params: CharacteriseParams) -> None:
        self.params = params
        self._saved: dict[str, Any] = {}

    def steps(self) -> list[Step]:
        p = self.params
        steps = [Step("setup", "Characterisation set-up: uniform illumination", "manual",
                      "EMVA 1288 set-up", self._setup, prompt=SETUP_PROMPT,
                      restore=self._restore)]
        for gain, bits in p.configs:
            steps.append(Step(
                config_step_id(gain, bits), f"Gain {gain:g}, {bits}-bit: "
                f"{'LED current' if p.vary == 'led_current' else 'exposure'} sweep and stacks",
                "acquire", "EMVA 1288 photon transfer", self._sweep(gain, bits),
                info={"gain": gain, "bits": bits},
            ))
        steps.append(Step("analysis", "Analyse: photon transfer, DSNU/PRNU, calibration",
                          "analysis", "EMVA 1288", self._analysis))
        return steps

    def _restore(self, ctx: StepContext) -> None:
        """The flat target mounted; on the simulated bench, the sensor truth journalled."""
        ctx.bench.mount(FLAT_TARGET)
        world = ctx.bench.world
        if ctx.bench.sim_camera is not None and world is not None:
            ctx.session.log_event(TRUTH_EVENT, truth=self.params.sensor_truth().to_dict(),
                                  flat_e_per_ms_per_ma=world.flat_e_per_ms_per_ma)

    @contextlib.contextmanager
    def _simulated_sensor(self, ctx: StepContext) -> Iterator[None]:
        """The simulated camera has the ``[simulator]`` truth while a sweep runs, and its own
        again afterwards (later runs on the same simulated bench are unaffected)."""
        sim = getattr(ctx.bench, "sim_camera", None)
        if sim is None:
            yield
            return
        previous = sim.sensor.truth
        sim.sensor.truth = self.params.sensor_truth()
        try:
            yield
        finally:
            sim.sensor.truth = previous

    def _setup(self, ctx: StepContext) -> None:
        ctx.ask(ctx.step.prompt or "")
        self._restore(ctx)

    def _sweep(self, gain: float, bits: int) -> Callable[[StepContext], None]:
        def action(ctx: StepContext) -> None:
            with self._simulated_sensor(ctx):
                sweep(ctx)

        def sweep(ctx: StepContext) -> None:
            p = self.params
            ctx.bench.configure_camera(bits=bits, width=p.width, height=p.height)
            # Frames this step saved before (a resume): read once, not per frame.
            self._saved = dict(ctx.session.step_frames(ctx.step.id))
            extra = {"gain": gain, "bits": bits, "led_channel": p.led_channel,
                     "vary": p.vary}
            by_current = p.vary == "led_current"
            step_ma = self._current_step_ma(ctx)

            def frames(names: list[str], x: float, lit: bool,
                       more: dict[str, Any]) -> list[npt.NDArray[Any]]:
                exposure = p.exposure_ms if by_current else x
                current = x if by_current else p.led_current_ma
                return self._frames(ctx, names, exposure, gain, lit, current,
                                    {**extra, **more})

            x_sat, found = probe_saturation(
                lambda name, x, lit: frames([name], x, lit, {})[0], p, bits, step_ma)
            values = sweep_points(p, x_sat, step_ma)
            step, _, maximum = _sweep_axis(p, step_ma)
            x_stack = _round_to(p.stack_fraction * x_sat, step, maximum)
            if by_current:  # the journal says which currents the sweep set, on which grid
                ctx.session.log_event(CURRENTS_EVENT, step=ctx.step.id, current_step_ma=step_ma,
                                      currents_ma=values, stack_current_ma=x_stack)
            ctx.report({"gain": gain, "bits": bits, "vary": p.vary,
                        "saturation_exposure_ms" if not by_current else "saturation_current_ma":
                        x_sat, "probe_saturated": found, "steps": len(values),
                        **({"current_step_ma": step_ma, "currents_ma": values}
                           if by_current else {})})
            for i, x in enumerate(values):
                frames([f"e{i:03d}-lit-a", f"e{i:03d}-lit-b"], x, True, {"sweep_index": i})
                frames([f"e{i:03d}-dark-a", f"e{i:03d}-dark-b"], x, False, {"sweep_index": i})
            n = p.stack_frames
            frames([f"stack-lit-{k:03d}" for k in range(n)], x_stack, True, {"stack": "lit"})
            frames([f"stack-dark-{k:03d}" for k in range(n)], x_stack, False, {"stack": "dark"})

        return action

    def _current_step_ma(self, ctx: StepContext) -> float | None:
        """The LED controller's current step (None without a controller); a fixed current
        (``vary = "exposure"``) it cannot set is refused here, before any light."""
        p = self.params
        if ctx.bench.led is None:
            return None
        step = ctx.bench.led_current_step_ma(p.led_channel)
        steps = p.led_current_ma / step
        if p.vary != "led_current" and abs(steps - round(steps)) > 1e-6:
            raise SettingOutOfRangeError(
                f"led.current_ma {p.led_current_ma:g} mA cannot be set: the LED controller "
                f"drives {step:g} mA steps")
        return step

    def _frames(self, ctx: StepContext, names: list[str], exposure_ms: float, gain: float,
                lit: bool, current_ma: float, extra: dict[str, Any]) -> list[npt.NDArray[Any]]:
        """Acquire (or reuse) frames at one setting, the LED on only around lit frames."""
        p = self.params
        # The frame's own metadata carries the exposure the camera used (``exposure_ms``).
        meta = {**extra, "lit": lit, "led_current_ma": current_ma if lit else 0.0}
        missing = [n for n in names if n not in self._saved]
        if lit and missing:
            ctx.check_abort()
            ctx.bench.led_on(p.led_channel, current_ma)
            if ctx.bench.led is not None:  # the current the controller reports it drives
                meta["led_current_set_ma"] = ctx.bench.led.current_ma(p.led_channel)
        try:
            return [self._acquire(ctx, n, exposure_ms, gain, meta) for n in names]
        finally:
            if lit and missing:
                ctx.bench.led_off(p.led_channel)

    def _acquire(self, ctx: StepContext, name: str, exposure_ms: float, gain: float,
                 meta: dict[str, Any]) -> npt.NDArray[Any]:
        """``ctx.acquire`` without its per-frame journal scan: a sweep saves ~200 frames per
        step, and the saved set was read once when the step started."""
        if name in self._saved:
            return ctx.acquire(name, exposure_ms=exposure_ms, gain=gain, extra=meta)  # reuse
        ctx.check_abort()
        pixels, frame_meta = ctx.bench.grab(exposure_ms=exposure_ms, gain=gain)
        metadata = {**frame_meta, "step": ctx.step.id, "name": name, **meta}
        ctx.session.save_frame(ctx.step.id, name, pixels, metadata)
        return pixels

    def _analysis(self, ctx: StepContext) -> None:
        out = self.analyze(ctx.session, ctx.runner.estimator)
        calib = write_calibration(ctx.session, out, ctx.bench.config)
        ctx.session.log_event("response_calibration_written", **calib)
        ctx.report({"response_calibration": calib})

    def analyze(self, session: Any, estimator: str | None) -> Path:
        tables, summary = analyze_characterise(session, self.params)
        return Path(session.write_results(tables, summary=summary, estimator="photon-transfer"))


def run_notes(session_path: Path, results_summary: Any) -> list[str]:
    """What the operator should read after a run: warnings per configuration and where the
    response calibration went (and how to use it)."""
    from benchlab.session import Session

    lines = []
    for cfg in results_summary.get("summary", {}).get("configs", []):
        for w in cfg.get("warnings", []):
            lines.append(f"warning (gain {cfg['gain']:g}, {cfg['bits']}-bit): {w}")
    written = [e for e in Session.open(Path(session_path)).events()
               if e.get("kind") == "response_calibration_written"]
    if written:
        w = written[-1]
        lines.append(f"response calibration: {w['file']}")
        if w.get("bench_config"):
            lines.append(f"referenced by bench configuration: {w['bench_config']} (radiometry "
                         "runs with it are linearised; analyze --linearise FILE for frames)")
    return lines
