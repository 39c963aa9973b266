"""Depth of field (thesis section 2.2.4): the stage carries the chart through focus.

"Determined by varying the object distance to the imaging system and evaluating its
corresponding MTF performance without adjusting the imaging surface": the back focus is set
once (the MTF procedure's step 3, or by eye) and never touched here.

Steps (ids in brackets):

1. [setup] forward-view set-up, camera settings; the stage homed.
2. per segment ``i`` of the sweep (:meth:`DepthParams.segments`):
   [mount-i] mount the USAF chart (with its slanted edges) on the stage carriage so that it is
   at distance ``d`` from the prototype at stage coordinate ``s`` (manual; on the simulated
   bench the chart is mounted at that offset); then for each distance ``z`` of the segment
   [s<i>-z<z>] move the stage, take ``frames`` frames (saved, averaged by the analysis) and
   report the edges' MTF50 for the live view.
3. [analysis]: the ``depth_of_field`` table and the rest (:mod:`.analysis`).

Every position is its own journalled step, so a run killed mid-sweep resumes at the first
position not taken; a resumed run re-mounts (replays ``mount-i``'s restore) and re-homes first.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from benchlab.analysis.arrays import mean_of_frames
from benchlab.protocols.depth.params import DepthParams, Segment
from benchlab.protocols.engine import Step, StepContext

if TYPE_CHECKING:
    from benchlab.session import Session

TARGET = "usaf"


def frame_name(k: int) -> str:
    return f"frame-{k}"


def pattern_prefix(pattern: tuple[float, str] | None) -> str:
    """Step-id prefix of a radial pattern (``r2S-``); none for the forward chart."""
    return "" if pattern is None else f"r{pattern[0]:g}{pattern[1][0].upper()}-"


def position_step_id(segment: int, distance_mm: float,
                     pattern: tuple[float, str] | None = None) -> str:
    """The step of one distance of one segment (also its frames' file names)."""
    return f"{pattern_prefix(pattern)}s{segment}-z{distance_mm:g}"


def target_of(pattern: tuple[float, str] | None) -> object:
    """What is mounted: the USAF chart, or a rolled radial pattern."""
    return TARGET if pattern is None else ("radial", pattern[0], pattern[1])


class DepthProcedure:
    """The depth-of-field sweep for one parameter set."""

    name = "depth"

    def __init__(self, params: DepthParams) -> None:
        self.params = params

    def segments(self) -> list[Segment]:
        return self.params.segments()

    def steps(self) -> list[Step]:
        p = self.params
        steps = [Step(
            "setup", "Forward-view set-up and camera settings", "manual", "section 2.2.4",
            self._setup, prompt="Depth-of-field set-up: back-lit USAF chart (with its slanted "
            "edges) on the stage carriage in front of the prototype; back focus set and locked "
            "- it is not touched during the sweep.", restore=self._restore,
        )]
        for pattern in p.patterns:
            pre = pattern_prefix(pattern)
            what = ("the chart" if pattern is None else
                    f"the {pattern[0]:g} lp/mm pattern rolled {pattern[1]}")
            where = "from the prototype" if pattern is None else "from the side wall"
            for seg in self.segments():
                first, last = seg.distances_mm[0], seg.distances_mm[-1]
                steps.append(Step(
                    f"{pre}mount-{seg.index}", f"Mount {what} for {first:g}-{last:g} mm",
                    "manual", "section 2.2.4", self._mount(seg, pattern),
                    prompt=(f"Segment {seg.index + 1}: mount {what} on the carriage so it is "
                            f"{first:g} mm {where} with the stage at "
                            f"{seg.stage_mm(first):g} mm (distances {first:g}-{last:g} mm)."),
                    restore=self._mount(seg, pattern, ask=False),
                    info={"object_offset_mm": seg.object_offset_mm},
                ))
                for z in seg.distances_mm:
                    steps.append(Step(
                        position_step_id(seg.index, z, pattern),
                        f"{what.capitalize()} at {z:g} mm: {p.frames} frames",
                        "acquire", "section 2.2.4", self._position(seg, z, pattern),
                        info={"distance_mm": z, "segment": seg.index,
                              "stage_mm": seg.stage_mm(z)},
                    ))
        steps.append(Step("analysis", "Analyse: through-focus curves, best focus, DOF",
                          "analysis", "section 2.2.4", self._analysis))
        return steps

    # -- actions ------------------------------------------------------------------------------
    def _restore(self, ctx: StepContext) -> None:
        ctx.bench.configure_camera(bits=self.params.bits)
        world = getattr(ctx.bench, "world", None)
        if world is not None:  # the view's lens (a world left by another depth run: replaced)
            world.through_focus = self.params.lens()
        ctx.home_stage()

    def _setup(self, ctx: StepContext) -> None:
        ctx.ask(ctx.step.prompt or "")
        self._restore(ctx)

    def _mount(self, seg: Segment, pattern: tuple[float, str] | None, ask: bool = True) -> Any:
        def action(ctx: StepContext) -> None:
            if ask:
                ctx.ask(ctx.step.prompt or "")
            ctx.bench.mount(target_of(pattern))
            ctx.bench.carry_target(self.params.object_distance_mm(seg.object_offset_mm))

        return action

    def _position(self, seg: Segment, z: float, pattern: tuple[float, str] | None) -> Any:
        def action(ctx: StepContext) -> None:
            p = self.params
            stage = seg.stage_mm(z)
            if ctx.bench.has_stage:
                ctx.move_stage_mm(stage)
            else:  # no stage: the operator moves the chart (the carriage offset is the distance)
                ctx.ask(f"Move the {'chart' if pattern is None else 'pattern'} to {z:g} mm "
                        f"{'from the prototype' if pattern is None else 'from the side wall'}.")
                ctx.bench.carry_target(self.params.object_distance_mm(z))
            extra = {"distance_mm": z, "segment": seg.index, "stage_mm": stage,
                     "object_offset_mm": seg.object_offset_mm}
            frames = [ctx.acquire(frame_name(k), exposure_ms=p.exposure_ms, gain=p.gain,
                                  extra=extra) for k in range(p.frames)]
            if ctx.runner.on_result is not None and pattern is None:
                from benchlab.protocols.depth.analysis import position_summary

                avg = mean_of_frames(frames)
                ctx.report({"distance_mm": z, **position_summary(avg, p, z)})

        return action

    def _analysis(self, ctx: StepContext) -> None:
        self.analyze(ctx.session, ctx.runner.estimator)

    def analyze(self, session: Session, estimator: str | None) -> Path:
        from benchlab.protocols.depth.analysis import analyze_depth
        from benchlab.protocols.depth.radial_rois import ESTIMATOR as RADIAL_ESTIMATOR

        tables, summary = analyze_depth(session, self.params)
        # what read the through-focus points: the slanted edges, or the radial bars
        used = RADIAL_ESTIMATOR if self.params.view == "radial" else "edge-sfr"
        return Path(session.write_results(tables, summary=summary, estimator=used))
