"""Field of view of the forward view (issue 41): the stage carries a dot-grid chart to each
object distance.

Steps (ids in brackets):

1. [setup] forward-view set-up, camera settings; the stage homed.
2. [mount] mount the dot chart on the stage carriage, square to the stage's travel, so that it
   is ``d`` mm from the lens's front with the stage at ``d - object_offset_mm`` (manual).
3. per distance ``d`` [distance-d]: move the stage, take ``frames`` frames (averaged by the
   analysis); the live view gets the number of dots found.
4. [analysis]: ``field_of_view``, ``image_height_mapping``, ``distortion`` (:mod:`.analysis`).

Every distance is its own journalled step, so a run killed mid-way resumes at the first
distance not taken; a resumed run re-mounts (replays ``mount``'s restore) and re-homes first.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from benchlab.drivers.errors import BenchlabError
from benchlab.protocols.engine import Step, StepContext
from benchlab.protocols.fov.params import FovParams, position_step_id

if TYPE_CHECKING:
    from benchlab.session import Session

TARGET = "dots"
SOURCE = "issue 41 (Tables 3.1, 4.14)"


def frame_name(k: int) -> str:
    return f"frame-{k}"


class FrameContentError(BenchlabError):
    """A distance's frames hold too few dots: journalled as rejected; a retry takes new ones."""


class FovProcedure:
    """The field-of-view measurement for one parameter set."""

    name = "fov"

    def __init__(self, params: FovParams) -> None:
        self.params = params

    def steps(self) -> list[Step]:
        p = self.params
        first = p.distances_mm[0]
        steps = [
            Step("setup", "Forward-view set-up and camera settings", "manual", SOURCE,
                 self._setup, prompt="Field-of-view set-up: back-lit dot-grid chart, the "
                 "prototype's forward view on the camera, its mechanical axis along the stage's "
                 "travel.", restore=self._restore),
            Step("mount", "Mount the dot chart on the carriage", "manual", SOURCE,
                 self._mount(ask=True),
                 prompt=(f"Mount the dot chart on the stage carriage, square to the travel, "
                         f"its large centre dot near the axis, so it is {first:g} mm from the "
                         f"lens's front with the stage at {p.stage_mm(first):g} mm."),
                 restore=self._mount(ask=False),
                 info={"object_offset_mm": p.object_offset_mm}),
        ]
        for z in p.distances_mm:
            steps.append(Step(
                position_step_id(z), f"Chart at {z:g} mm: {p.frames} frames", "acquire",
                SOURCE, self._position(z),
                info={"distance_mm": z, "stage_mm": p.stage_mm(z)},
            ))
        steps.append(Step("analysis", "Analyse: field of view, mapping, distortion", "analysis",
                          SOURCE, self._analysis))
        return steps

    # -- actions ------------------------------------------------------------------------------
    def _restore(self, ctx: StepContext) -> None:
        ctx.bench.configure_camera(bits=self.params.bits)
        world = getattr(ctx.bench, "world", None)
        if world is not None:  # the simulated lens and chart of these parameters
            from benchlab.scenes.dots import DotGridScene

            world.dots = DotGridScene(chart=self.params.chart(), lens=self.params.lens())
        ctx.home_stage()

    def _setup(self, ctx: StepContext) -> None:
        ctx.ask(ctx.step.prompt or "")
        self._restore(ctx)

    def _mount(self, ask: bool) -> Any:
        def action(ctx: StepContext) -> None:
            if ask:
                ctx.ask(ctx.step.prompt or "")
            ctx.bench.mount(TARGET)
            ctx.bench.carry_target(self.params.object_offset_mm)

        return action

    def _position(self, z: float) -> Any:
        def action(ctx: StepContext) -> None:
            p = self.params
            stage = p.stage_mm(z)
            if ctx.bench.has_stage:
                ctx.move_stage_mm(stage)
            else:  # no stage: the operator moves the chart (the carriage offset is the distance)
                ctx.ask(f"Move the chart to {z:g} mm from the lens's front.")
                ctx.bench.carry_target(z)
            extra = {"distance_mm": z, "stage_mm": stage,
                     "object_offset_mm": p.object_offset_mm}
            names = [frame_name(k) for k in range(p.frames)]
            frames = [ctx.acquire(n, exposure_ms=p.exposure_ms, gain=p.gain, extra=extra)
                      for n in names]
            from benchlab.protocols.fov.analysis import count_dots

            avg = np.mean(np.stack(frames).astype(np.float64), axis=0)
            try:
                found = count_dots(avg, p)
            except ValueError as exc:  # the frames, not the bench: a retry takes new ones
                ctx.reject_frames(tuple(names), str(exc))
                raise FrameContentError(f"chart at {z:g} mm: {exc}; the frames are set aside "
                                        "and a retry takes new ones") from exc
            ctx.report({"distance_mm": z, "dots_identified": found})

        return action

    def _analysis(self, ctx: StepContext) -> None:
        self.analyze(ctx.session, ctx.runner.estimator)

    def analyze(self, session: Session, estimator: str | None) -> Path:
        from benchlab.protocols.fov.analysis import analyze_fov

        tables, summary = analyze_fov(session, self.params)
        return Path(session.write_results(tables, summary=summary, estimator="dot-grid-fit"))
