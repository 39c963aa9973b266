"""Table 4.10: the MTF test procedure as steps on the bench.

Steps (ids in brackets; Table 4.10 step numbers in ``Step.table_step``):

1. [setup] forward-view set-up; camera in continuous (normal) mode, full 1280 x 1024 frame
   (no decimation), frames kept lossless (TIFF, never JPEG).
2. [thread] thread the prototype onto the camera (manual).
3. [focus] adjust back focus for the sharpest USAF chart: live sharpness readings, then the
   operator confirms best focus.
4. [forward] acquire the forward-view image (unity gain, 300 ms by default).
5. [radial-setup] change to the radial-view set-up (manual).
6-8. for each frequency f: [roll-f-sagittal] roll the pattern sagittal (manual),
   [radial-f-sagittal] acquire; [roll-f-tangential], [radial-f-tangential] likewise.
Then [analysis]: Tables 4.11-4.15 into ``results/vN``.

On the simulated bench a confirmed manual step mounts the matching target in the simulated
world (``bench.mount``), so the frames show what the operator was asked to set up.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from benchlab.protocols.engine import Step, StepContext
from benchlab.protocols.mtf.analysis import (
    FORWARD_FRAME,
    analyze_forward_frame,
    analyze_mtf,
    analyze_radial_frame,
    radial_step_id,
)
from benchlab.protocols.mtf.params import MtfParams
from benchlab.protocols.mtf.targets import SIMULATED_TARGET_EVENT

if TYPE_CHECKING:
    from benchlab.session import Session

FORWARD_TARGET = "usaf"
DARK_TARGET = "dark"


def _record_simulated_levels(ctx: StepContext, view: str, target: Any) -> None:
    """On the simulated bench, journal the mounted target's printed levels (8-bit codes of its
    dark and bright print): the ``simulator_truth`` of the analysis is computed with them."""
    world = getattr(ctx.bench, "world", None)
    scene = world.scene_for(target) if world is not None else None
    if scene is not None and hasattr(scene, "dark_dn8") and hasattr(scene, "bright_dn8"):
        ctx.session.log_event(SIMULATED_TARGET_EVENT, step=ctx.step.id, view=view,
                              dark_dn8=float(scene.dark_dn8), bright_dn8=float(scene.bright_dn8))


def _fmt(f: float) -> str:
    return f"{f:g}"


class MtfProcedure:
    """The Table 4.10 procedure for one parameter set."""

    name = "mtf"

    def __init__(self, params: MtfParams) -> None:
        self.params = params

    # -- steps --------------------------------------------------------------------------------
    def steps(self) -> list[Step]:
        p = self.params
        steps = [
            Step(
                "setup", "Forward-view set-up and camera settings", "manual", "Table 4.10 step 1",
                self._setup,
                prompt=("Forward-view set-up (fig. 4.7a): back-lit USAF 1951 chart in front of "
                        "the prototype."),
                restore=self._restore_setup,
            ),
            Step(
                "thread", "Thread the prototype onto the camera", "manual", "Table 4.10 step 2",
                self._manual, prompt="Thread the prototype onto the camera; the turning sets "
                "the back focus.",
            ),
            Step(
                "focus", "Adjust back focus for the sharpest chart", "focus", "Table 4.10 step 3",
                self._focus, prompt="Adjust back focus until the USAF chart is as sharp as "
                "possible (maximise the sharpness figure); confirm at best focus.",
                info={"exposure_ms": p.exposure_ms, "gain": p.gain},
            ),
            Step(
                "forward", "Acquire the forward-view image", "acquire", "Table 4.10 step 4",
                self._acquire_forward,
            ),
            Step(
                "radial-setup", "Change to the radial-view set-up", "manual", "Table 4.10 step 5",
                self._radial_setup,
                prompt="Change to the radial-view set-up (figs. 4.7b, 4.8): back-lit paper "
                "patterns in annular mounts. Back focus stays frozen.",
                restore=lambda ctx: ctx.bench.mount(DARK_TARGET),
            ),
        ]
        for i, f in enumerate(p.radial_frequencies_lp_per_mm):
            for orient in ("sagittal", "tangential"):
                table_step = 6 if orient == "sagittal" else 7
                label = f"Table 4.10 step {table_step}" + (" (step 8)" if i else "")
                how = ("so the bars run along the endoscope axis" if orient == "sagittal"
                       else "the other way, so the bars run around the cylinder")
                target = ("radial", f, orient)
                steps.append(Step(
                    f"roll-{_fmt(f)}-{orient}", f"Roll the {_fmt(f)} lp/mm pattern {orient}",
                    "manual", label, self._mount_step(target),
                    prompt=f"Roll the {_fmt(f)} lp/mm pattern into a cylinder {how} "
                    f"({orient} radial test) and mount it.",
                    restore=self._mount_step(target, ask=False),
                    info={"freq_lp_per_mm": f, "orientation": orient},
                ))
                steps.append(Step(
                    radial_step_id(f, orient), f"Acquire radial {_fmt(f)} lp/mm {orient}",
                    "acquire", label, self._radial_acquire(f, orient),
                    info={"freq_lp_per_mm": f, "orientation": orient},
                ))
        steps.append(Step("analysis", "Analyse: Tables 4.11-4.15", "analysis", "section 4.3",
                          self._analysis))
        return steps

    # -- actions ------------------------------------------------------------------------------
    def _configure(self, ctx: StepContext) -> dict[str, Any]:
        return ctx.bench.configure_camera(bits=self.params.bits)

    def _restore_setup(self, ctx: StepContext) -> None:
        self._configure(ctx)
        ctx.bench.mount(FORWARD_TARGET)

    def _setup(self, ctx: StepContext) -> None:
        ctx.ask(ctx.step.prompt or "")
        ctx.bench.mount(FORWARD_TARGET)
        _record_simulated_levels(ctx, "forward", FORWARD_TARGET)
        settings = self._configure(ctx)
        ctx.session.log_event("camera_configured", step=ctx.step.id, settings=settings,
                              lossless="TIFF (zlib), never JPEG")

    def _manual(self, ctx: StepContext) -> None:
        ctx.ask(ctx.step.prompt or "")

    def _radial_setup(self, ctx: StepContext) -> None:
        ctx.ask(ctx.step.prompt or "")
        ctx.bench.mount(DARK_TARGET)

    def _focus(self, ctx: StepContext) -> None:
        # Imported here: it loads OpenCV, which a re-analysis never needs (start-up, issue 11).
        from benchlab.analysis.focus.sharpness import sharpness

        p = self.params
        readings: list[float] = []
        for _ in range(p.focus_frames):
            ctx.check_abort()
            pixels, _ = ctx.bench.grab(exposure_ms=p.exposure_ms, gain=p.gain)
            readings.append(sharpness(pixels))
            ctx.report({"sharpness": readings[-1], "best": max(readings)})
        ctx.session.log_event("focus_sharpness", step=ctx.step.id, readings=readings)
        ctx.ask(f"{ctx.step.prompt} Sharpness now {readings[-1]:.1f} "
                f"(best seen {max(readings):.1f}).")

    def _acquire_forward(self, ctx: StepContext) -> None:
        p = self.params
        pixels = ctx.acquire(FORWARD_FRAME, exposure_ms=p.exposure_ms, gain=p.gain,
                             extra={"view": "forward", "target": FORWARD_TARGET})
        rows = analyze_forward_frame(pixels, p, self._estimator(ctx))
        chart = rows[0].get("chart") if rows else None
        # the journal keeps where the chart was found (or that it was not) for this frame
        ctx.session.log_event("chart_located", step=ctx.step.id, chart=chart,
                              offset_px=rows[0].get("chart_offset_px") if rows else None)
        for row in rows:
            ctx.report(row)

    def _mount_step(self, target: Any, ask: bool = True) -> Any:
        def action(ctx: StepContext) -> None:
            if ask:
                ctx.ask(ctx.step.prompt or "")
            ctx.bench.mount(target)
            if ask:
                _record_simulated_levels(ctx, "radial", target)

        return action

    def _radial_acquire(self, f: float, orient: str) -> Any:
        def action(ctx: StepContext) -> None:
            p = self.params
            pixels = ctx.acquire(
                "radial", exposure_ms=p.exposure_ms, gain=p.gain,
                extra={"view": "radial", "freq_lp_per_mm": f, "orientation": orient},
            )
            ctx.report(analyze_radial_frame(pixels, f, orient, p, self._estimator(ctx)))

        return action

    def _estimator(self, ctx: StepContext) -> str | None:
        return ctx.runner.estimator or self.params.estimator or None

    def _analysis(self, ctx: StepContext) -> None:
        self.analyze(ctx.session, self._estimator(ctx))

    # -- offline ------------------------------------------------------------------------------
    def analyze(self, session: Session, estimator: str | None) -> Path:
        """Analyse the session's saved frames into a new results version."""
        tables, summary, used = analyze_mtf(session, self.params, estimator)
        return Path(session.write_results(tables, summary=summary, estimator=used))
