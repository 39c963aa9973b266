"""Field of view of the forward view (issue 41): the stage carries a dot-grid chart to each
object distance.

Steps (ids in brackets):

1. [setup] forward-view set-up, camera settings; the stage homed.
2. [mount] mount the dot chart on the stage carriage, square to the stage's travel, so that it
   is ``d`` mm from the lens's front with the stage at ``d - object_offset_mm`` (manual).
3. per distance ``d`` [distance-d]: move the stage, take ``frames`` frames (averaged by the
   analysis); the live view gets the number of dots found.
4. [radial-mount] the radial set-up: the forward view capped, the ring tube on the carriage,
   coaxial, its wide ring at ``object_offset_mm`` (the thesis's axial z) with the stage at 0;
   the stage homed (manual; absent with ``radial.enabled = false``).
5. per position ``p`` [radial-p]: move the stage to ``p - object_offset_mm``, take ``frames``
   frames; the live view gets the number of rings identified.
6. [analysis]: ``field_of_view``, ``image_height_mapping``, ``distortion`` (:mod:`.analysis`).

Every distance is its own journalled step, so a run killed mid-way resumes at the first
distance not taken; a resumed run re-mounts (replays ``mount``'s restore) and re-homes first.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from benchlab.analysis.arrays import mean_of_frames
from benchlab.drivers.errors import BenchlabError
from benchlab.protocols.engine import Step, StepContext
from benchlab.protocols.fov.params import FovParams, position_step_id
from benchlab.protocols.fov.radial_params import radial_step_id

if TYPE_CHECKING:
    from benchlab.session import Session

TARGET = "dots"
TUBE = "rings"
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
        steps += self._radial_steps()
        steps.append(Step("analysis", "Analyse: field of view, mapping, distortion", "analysis",
                          SOURCE, self._analysis))
        return steps

    def _radial_steps(self) -> list[Step]:
        plan = self.params.radial
        if plan is None:
            return []
        first = plan.positions_mm[0]
        steps = [Step(
            "radial-mount", "Mount the ring tube on the carriage", "manual", SOURCE,
            self._mount_tube(ask=True),
            prompt=(f"Radial set-up: cap the forward view; mount the ring tube "
                    f"({plan.tube_radius_mm:g} mm radius) on the stage carriage, coaxial with the "
                    f"prototype, so its wide ring is at z = {first:g} mm (the thesis's axial "
                    f"coordinate) with the stage at {plan.stage_mm(first):g} mm."),
            restore=self._mount_tube(ask=False),
            info={"object_offset_mm": plan.object_offset_mm})]
        for p in plan.positions_mm:
            steps.append(Step(
                radial_step_id(p), f"Wide ring at z = {p:g} mm: {self.params.frames} frames",
                "acquire", SOURCE, self._radial_position(p),
                info={"position_mm": p, "stage_mm": plan.stage_mm(p)}))
        return steps

    # -- actions ------------------------------------------------------------------------------
    def _restore(self, ctx: StepContext) -> None:
        ctx.bench.configure_camera(bits=self.params.bits)
        world = getattr(ctx.bench, "world", None)
        if world is not None:  # the simulated lens and chart of these parameters
            from benchlab.scenes.dots import DotGridScene

            world.dots = DotGridScene(chart=self.params.chart(), lens=self.params.lens())
            if self.params.radial is not None:
                from benchlab.scenes.rings import RingTubeScene

                world.rings = RingTubeScene(tube=self.params.radial.tube())
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

            found = _count_on_average(ctx, names, frames, lambda avg: count_dots(avg, p),
                                      f"chart at {z:g} mm")
            ctx.report({"distance_mm": z, "dots_identified": found})

        return action

    def _mount_tube(self, ask: bool) -> Any:
        def action(ctx: StepContext) -> None:
            assert self.params.radial is not None
            if ask:
                ctx.ask(ctx.step.prompt or "")
            ctx.bench.mount(TUBE)
            ctx.bench.carry_target(self.params.radial.object_offset_mm)
            ctx.home_stage()

        return action

    def _radial_position(self, p: float) -> Any:
        def action(ctx: StepContext) -> None:
            plan = self.params.radial
            assert plan is not None
            stage = plan.stage_mm(p)
            if ctx.bench.has_stage:
                ctx.move_stage_mm(stage)
            else:  # no stage: the operator slides the tube (the carriage offset is the position)
                ctx.ask(f"Slide the tube so its wide ring is at z = {p:g} mm.")
                ctx.bench.carry_target(p)
            extra = {"position_mm": p, "stage_mm": stage,
                     "object_offset_mm": plan.object_offset_mm}
            names = [frame_name(k) for k in range(self.params.frames)]
            frames = [ctx.acquire(n, exposure_ms=self.params.exposure_ms, gain=self.params.gain,
                                  extra=extra) for n in names]
            from benchlab.protocols.fov.radial_analysis import count_rings

            found = _count_on_average(ctx, names, frames, lambda avg: count_rings(avg, plan),
                                      f"tube at {p:g} mm")
            ctx.report({"position_mm": p, "rings_identified": found})

        return action

    def _analysis(self, ctx: StepContext) -> None:
        self.analyze(ctx.session, ctx.runner.estimator)

    def analyze(self, session: Session, estimator: str | None) -> Path:
        from benchlab.protocols.fov.analysis import analyze_fov

        tables, summary = analyze_fov(session, self.params)
        return Path(session.write_results(tables, summary=summary, estimator="dot-grid-fit"))


def _count_on_average(ctx: StepContext, names: list[str], frames: list[Any],
                      count: Callable[[Any], int], where: str) -> int:
    """``count`` on the mean of one position's frames; a failure sets those frames aside
    (the frames, not the bench: a retry takes new ones) and fails the step naming ``where``."""
    avg = mean_of_frames(frames)
    try:
        return count(avg)
    except ValueError as exc:
        ctx.reject_frames(tuple(names), str(exc))
        raise FrameContentError(f"{where}: {exc}; the frames are set aside and a retry takes "
                                "new ones") from exc
