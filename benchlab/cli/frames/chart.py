"""``benchlab find-chart FRAME``, ``benchlab analyze FRAME --chart usaf`` and
``benchlab benchmark chart``: the USAF 1951 chart finder on the command line."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from benchlab.cli import positive_int
from benchlab.cli.output import (
    add_output_option,
    check_output,
    forced,
    print_outcome,
    write_output,
)
from benchlab.drivers.errors import BenchlabError

if TYPE_CHECKING:  # numpy / OpenCV are imported by the commands (fast `benchlab --help`)
    from benchlab.analysis.bars.result import ModulationResult
    from benchlab.analysis.chart.finder import ChartFit

#: What ``--chart`` takes.
ChartKind = Literal["usaf"]
CHART_KINDS: tuple[ChartKind, ...] = ("usaf",)


class ChartNotFound(BenchlabError):
    """No chart in the frame (printed as ``benchlab: error: FRAME: no chart found: ...``)."""


def locate(path: Path, magnification: float | None = None, whole: bool = False
           ) -> tuple[Any, ChartFit]:
    """Read an image and find the chart in it; a clear error when there is none.

    First the forward view's chart (groups 0-3 at its configured place, 0.5-2x the
    ``magnification``, default 16.3, Eq. 4.1); where that finds none or fits fewer than
    :data:`~benchlab.analysis.chart.finder.CONFIDENT_MIN_SETS` sets (or with ``whole``), the
    whole chart, groups -2 to 7, at any scale and rotation
    (:func:`benchlab.analysis.chart.whole.find_whole_chart`; ``magnification`` a hint that
    names the groups), whichever fits more sets.
    """
    from benchlab.analysis.chart.finder import (
        CONFIDENT_MIN_SETS,
        ChartNotFoundError,
        find_chart,
    )
    from benchlab.analysis.chart.layout import ChartLayout
    from benchlab.analysis.chart.whole import find_whole_chart
    from benchlab.analysis.mtf.frequency import FORWARD_MAGNIFICATION
    from benchlab.cli.frames.analysis import AnalysisInputError, read_image

    if magnification is not None and not magnification > 0:
        raise AnalysisInputError(f"--magnification must be > 0, got {magnification}")
    pixels = read_image(path)
    try:
        forward = None
        if not whole:
            try:
                forward = find_chart(pixels, ChartLayout(
                    magnification=magnification or FORWARD_MAGNIFICATION))
            except ChartNotFoundError:
                pass  # not the forward view's chart: the whole chart at any scale
            if forward is not None and forward.matched_sets >= CONFIDENT_MIN_SETS:
                return pixels, forward
        try:
            fit = find_whole_chart(pixels, magnification)
        except ChartNotFoundError:
            if forward is None:
                raise
            return pixels, forward
        # a forward fit on a few sets may be a coincidence in another part of the chart
        return pixels, (forward if forward is not None
                        and forward.matched_sets >= fit.matched_sets else fit)
    except ChartNotFoundError as exc:
        raise ChartNotFound(f"{path}: {exc}") from None
    except ValueError as exc:
        raise AnalysisInputError(f"{path}: {exc}") from exc


def groups_line(fit: ChartFit) -> str:
    """One line: the USAF groups with a confirmed set, and the chart model searched."""
    groups = fit.groups_found
    model = "whole chart, groups -2 to 7" if _is_whole(fit) else "forward-view chart"
    shown = ", ".join(str(g) for g in groups) if groups else "none confirmed"
    return f"groups in view: {shown} ({model})"


def pose_line(fit: ChartFit) -> str:
    """One line: pose, polarity, magnification."""
    p = fit.pose
    return (f"chart: offset ({p.offset_rc[0]:+.2f}, {p.offset_rc[1]:+.2f}) px from the configured "
            f"origin ({fit.layout.origin_rc[0]:g}, {fit.layout.origin_rc[1]:g}), scale "
            f"{p.scale:.4f}, rotation {p.rotation_deg:+.2f} deg, {fit.polarity} target; implied "
            f"magnification {fit.implied_magnification:.4g} (configured "
            f"{fit.configured_magnification:.4g}); {fit.matched_sets} sets fitted, residual "
            f"{fit.residual_px:.2f} px")


def format_elements(fit: ChartFit) -> str:
    """The table of placed elements, found first, then rejected with reasons."""
    head = (f"{'set':<7} {'status':<8} {'conf':>4}  {'centre (r, c)':>16}  {'roi r0,c0,r1,c1':<19} "
            f"{'obj lp/mm':>9} {'img lp/mm':>9} {'px/period':>9} {'measured':>8}")
    lines = [pose_line(fit), groups_line(fit), *(f"warning: {w}" for w in fit.warnings), "",
             head]
    listed = [*fit.found, *fit.rejected]
    if _is_whole(fit):  # the whole chart: most of its 120 sets are far off any frame
        off = [e for e in fit.rejected if e.reason and "runs off the frame" in e.reason]
        listed = [e for e in listed if e not in off]
    for el in listed:
        p = el.posed
        meas = "-" if el.measured_px_per_period is None else f"{el.measured_px_per_period:.2f}"
        roi = ",".join(map(str, el.roi))
        lines.append(
            f"{p.label:<7} {el.status:<8} {el.confidence:>4.2f}  "
            f"({p.centre_rc[0]:7.1f},{p.centre_rc[1]:7.1f})  {roi:<19} "
            f"{p.object_lp_per_mm:>9.3f} {p.image_lp_per_mm:>9.2f} {p.px_per_period:>9.2f} "
            f"{meas:>8}" + (f"  {el.reason or el.unmeasurable}"
                            if el.reason or el.unmeasurable else ""))
    if _is_whole(fit) and len(listed) < len(fit.elements):
        lines.append(f"({len(fit.elements) - len(listed)} sets of the whole chart run off the "
                     "frame: not listed; --json lists every set)")
    return "\n".join(lines)


def _is_whole(fit: ChartFit) -> bool:
    """Whether the fit is of the whole chart (groups -2 to 7), not the forward view's."""
    return any(g < 0 or g > 3 for g, _ in fit.layout.elements)


def _find_chart_command(args: argparse.Namespace) -> int:
    path = Path(args.frame)
    if args.plot:  # before the analysis
        check_output(args.plot, force=forced(args), option="--plot")
    pixels, fit = locate(path, args.magnification, args.whole)
    if args.plot:
        from benchlab.report.chart import chart_png

        try:
            write_output(args.plot, chart_png(pixels, fit, str(path)), force=forced(args),
                         option="--plot")
        except OSError as exc:
            raise BenchlabError(f"cannot write {args.plot}: {exc.strerror or exc}") from exc
    return print_outcome(args.json, lambda: {"frame": str(path), **fit.to_dict()},
                         lambda: format_elements(fit), allow_nan=False)


# --------------------------------------------------------------------------- analyze --chart


def measure_chart(pixels: Any, fit: ChartFit, estimator: str | None) -> list[dict[str, Any]]:
    """Every found element measured: one dict per bar set.

    By default (``estimator`` None or ``auto``) the chart's own reading
    (:func:`benchlab.analysis.chart.reading.read_chart`: each set fitted at the geometry the
    pose gives it, the blur shared across the chart); a named estimator instead runs the
    generic estimator on each set's ROI with its priors, where the finder deems that reliable
    (:attr:`FoundElement.generic_unreliable`; otherwise the reason, not a number).
    """
    from benchlab.analysis import ESTIMATORS, estimate_modulation
    from benchlab.analysis.chart.reading import read_chart

    generic = estimator not in (None, "", "auto")
    if generic and estimator not in ESTIMATORS:
        raise ValueError(f"--estimator {estimator!r} unknown; choose auto or one of "
                         f"{', '.join(sorted(ESTIMATORS))}")
    readings: list[ModulationResult | None] = (
        [None] * len(fit.found) if generic else list(read_chart(pixels, fit)))
    rows = []
    for el, reading in zip(fit.found, readings, strict=True):
        r0, c0, r1, c1 = el.measurement_roi
        p = el.posed
        note = el.generic_unreliable if generic else el.unmeasurable
        result: dict[str, Any] | None = None
        if note is None:  # else no number: the note says why
            if reading is None:
                reading = estimate_modulation(pixels[..., r0:r1, c0:c1], estimator=str(estimator),
                                              **el.estimator_priors())
            result = reading.to_dict()
        rows.append({"element": f"G{p.group}E{p.element}", "orientation": p.orientation,
                     "label": p.label, "roi": list(el.measurement_roi),
                     "object_lp_per_mm": p.object_lp_per_mm,
                     "image_lp_per_mm": p.image_lp_per_mm, "px_per_period": p.px_per_period,
                     "theta_deg": p.theta_deg, "confidence": el.confidence,
                     "unmeasurable": note, "result": result})
    return rows


def format_table_411(fit: ChartFit, rows: list[dict[str, Any]]) -> str:
    """Table 4.11 layout: one line per element, sagittal and tangential side by side."""
    by: dict[str, dict[str, dict[str, Any]]] = {}
    for r in rows:
        by.setdefault(r["element"], {})[r["orientation"]] = r

    def cell(r: dict[str, Any] | None) -> str:
        if r is None:
            return f"{'-':>17}"
        res = r["result"]
        if res is None:
            return f"{'not measured':>17}"
        if not res.get("resolved"):
            return f"{'N/A':>9} {0.0:>7.2f}"
        return f"{res['dark']:>4.0f}/{res['bright']:<4.0f} {res['modulation']:>7.2f}"

    lines = [pose_line(fit), groups_line(fit), *(f"warning: {w}" for w in fit.warnings), "",
             f"{'element':<8} {'obj lp/mm':>9} {'img lp/mm':>9}  {'S dark/bright':>13} "
             f"{'S mod':>5}  {'T dark/bright':>13} {'T mod':>5}"]
    for name, pair in by.items():
        any_row = next(iter(pair.values()))
        lines.append(f"{name:<8} {any_row['object_lp_per_mm']:>9.3f} "
                     f"{any_row['image_lp_per_mm']:>9.2f}  {cell(pair.get('sagittal')):>19}  "
                     f"{cell(pair.get('tangential')):>19}")
    unmeasured = [f"{r['label']} {r['unmeasurable']}" for r in rows if r["unmeasurable"]]
    if unmeasured:
        lines.append("")
        lines.append("found, not measured: " + "; ".join(unmeasured))
    shown = fit.rejected
    if _is_whole(fit):
        shown = [e for e in shown if not (e.reason and "runs off the frame" in e.reason)]
    if shown:
        lines.append("")
        lines.append("not measured: " + "; ".join(f"{e.label} {e.reason}" for e in shown))
    if len(shown) < len(fit.rejected):
        lines.append(f"({len(fit.rejected) - len(shown)} sets of the whole chart run off the "
                     "frame: not listed)")
    return "\n".join(lines)


def analyze_chart_command(args: argparse.Namespace) -> int:
    """``benchlab analyze FRAME --chart usaf``: find the chart, measure every found element."""
    from benchlab.cli.frames.analysis import AnalysisInputError

    if args.chart not in CHART_KINDS:
        raise AnalysisInputError(f"--chart {args.chart!r} unknown; choose {', '.join(CHART_KINDS)}")
    path = Path(args.target)
    if path.is_dir():
        raise AnalysisInputError(f"{path}: --chart needs an image file, not a folder")
    for option in ("roi", "peaks", "freq", "orientation"):
        if getattr(args, option, None) is not None:
            raise AnalysisInputError(f"--{option} does not apply with --chart: every found "
                                     "element has its own ROI, frequency and orientation")
    pixels, fit = locate(path, getattr(args, "magnification", None),
                         bool(getattr(args, "whole_chart", False)))
    try:
        rows = measure_chart(pixels, fit, args.estimator)
    except ValueError as exc:
        raise AnalysisInputError(f"{path}: {exc}") from exc
    def payload() -> dict[str, Any]:
        summary = {k: v for k, v in fit.to_dict().items() if k != "elements"}
        rejected = [{"label": e.label, "reason": e.reason} for e in fit.rejected]
        return {"image": str(path), "chart": summary, "rows": rows, "rejected": rejected}

    return print_outcome(args.json, payload, lambda: format_table_411(fit, rows),
                         allow_nan=False)


# --------------------------------------------------------------------------- benchmark


def _benchmark_command(args: argparse.Namespace) -> int:
    from benchlab.benchmarks.chart import (
        format_benchmark,
        format_psf_check,
        run_chart_benchmark,
        run_psf_check,
    )

    t0 = time.perf_counter()
    if args.whole:
        from benchlab.benchmarks.whole_chart import (
            format_whole_chart_benchmark,
            run_whole_chart_benchmark,
        )

        print(format_whole_chart_benchmark(run_whole_chart_benchmark(frames=args.frames,
                                                                     seed=args.seed)))
        print(f"\n{time.perf_counter() - t0:.1f} s")
        return 0
    if args.psf_check:
        print(format_psf_check(run_psf_check(seed=args.seed)))
        print(f"\nseed {args.seed}, {time.perf_counter() - t0:.1f} s")
        return 0
    summary = run_chart_benchmark(frames=args.frames, seed=args.seed,
                                  control_frames=args.control)
    print(format_benchmark(summary))
    print(f"\n{args.frames} + {args.control} control frames, seed {args.seed}, "
          f"{time.perf_counter() - t0:.1f} s")
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``find-chart`` and ``benchmark chart``."""
    p = commands.add_parser(
        "find-chart", help="locate and label every USAF 1951 element in a frame",
        description=(
            "Find the USAF 1951 chart in an 8- or 16-bit TIFF/PNG/BMP/JPEG frame at any offset, "
            "scale and rotation, positive or negative target. First the forward view's chart "
            "(0.5-2x the configured magnification); where there is none, the whole chart "
            "(groups -2 to 7, e.g. groups 4-7 under a microscope) at any scale, "
            "--magnification then a hint that names the groups. Prints the pose, the implied "
            "magnification, the groups in view and every bar set: found (with confidence, ROI, "
            "object and image frequency, px per period) or rejected with the reason (clipped by "
            "the FOV, above Nyquist, too small, ambiguous). Exit status 1 with 'no chart found' "
            "when there is none. Example: benchlab find-chart scope.jpg --magnification 0.25"),
    )
    p.add_argument("frame", metavar="FRAME", help="image file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_output_option(p, "--plot", metavar="FILE",
                      help="write a PNG of the frame with the found chart")
    p.add_argument("--magnification", type=float, default=None,
                   help="object-to-image frequency factor, Eq. 4.1 (image lp/mm = object lp/mm x "
                        "it; default 16.3, the forward view; ~1/M under an objective of "
                        "magnification M): the forward chart's scale, the whole chart's hint")
    p.add_argument("--whole", action="store_true",
                   help="search the whole chart (groups -2 to 7) at any scale straight away")
    p.set_defaults(func=_find_chart_command)

    b = benchmarks.add_parser(
        "chart", help="chart finder: found share, labels, ROI centre error, modulation, speed",
        description=(
            "Render the simulated USAF chart at random poses (offset anywhere it fits in the "
            "forward disc, scale 0.7-1.4, rotation +-15 deg, vignetting, dust, sensor noise, "
            "positive and negative, 8/12-bit) and score the finder against the scene's truth."),
    )
    b.add_argument("--frames", type=positive_int, default=40, help="random poses (default 40)")
    b.add_argument("--seed", type=int, default=0, help="random seed")
    b.add_argument("--control", type=int, default=8,
                   help="extra poses at rotation 0 scoring the modulation alone (default 8)")
    b.add_argument("--psf-check", action="store_true",
                   help="instead: read single three-bar sets rendered through non-Gaussian PSFs "
                        "(defocus disc, Gaussian + halo, disc + Gaussian) and print, per PSF, "
                        "bar width and direction, the share within 0.03, the 95 %% interval "
                        "coverage and the contrast reversals called reversed (~15 s)")
    b.add_argument("--whole", action="store_true",
                   help="instead: the whole-chart finder (groups -2 to 7) on --frames random "
                        "frames at 0.2-10x the scale of a microscope's groups 4-7, any "
                        "rotation, half of them JPEG: found, magnification, groups named, sets "
                        "labelled, time")
    b.set_defaults(func=_benchmark_command)
