"""``benchlab analyze IMAGE`` (one ROI of one image) and ``benchlab benchmark analysis``.

``benchlab analyze SESSION_FOLDER`` (a folder holding ``session.json``) is handed to the
procedures layer (:func:`benchlab.cli.runs.procedures.analyze_session_command`).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from benchlab.cli import UsageError, positive_int
from benchlab.cli.output import print_outcome
from benchlab.drivers.errors import BenchlabError

if TYPE_CHECKING:  # numpy is imported by the commands that use it (fast --help)
    import numpy.typing as npt

IMAGE_SUFFIXES = (".tif", ".tiff", ".png", ".bmp", ".jpg", ".jpeg")
ORIENTATION_CHOICES = ("sagittal", "tangential", "horizontal", "vertical")


class AnalysisInputError(BenchlabError, ValueError):
    """A bad image file or command-line value (printed as ``benchlab: error: ...``)."""


def read_image(path: Path) -> npt.NDArray[Any]:
    """A monochrome 8- or 16-bit image (TIFF, PNG, BMP or JPEG) as a 2-D array; a multi-page
    TIFF gives a (frames, rows, cols) stack, which the estimators average. PNG, BMP and JPEG
    are decoded by Pillow (:func:`benchlab.cli.frames.imagefile.decode_image`: a colour JPEG
    is read as its luminance).

    Raises
    ------
    AnalysisInputError
        Missing, unreadable, colour or unsupported file, naming it.
    """
    return read_image_and_metadata(path)[0]


def read_image_and_metadata(path: Path) -> tuple[npt.NDArray[Any], dict[str, Any] | None]:
    """:func:`read_image` and, for a benchlab frame (TIFF), its metadata (None otherwise)."""
    import numpy as np
    if not path.exists():
        raise AnalysisInputError(f"{path}: no such file")
    if not path.is_file():
        raise AnalysisInputError(f"{path}: not a file (a session folder needs session.json)")
    suffix = path.suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        raise AnalysisInputError(
            f"{path}: unsupported image type {suffix or '(none)'}; use TIFF, PNG, BMP or JPEG"
        )
    meta = None
    try:
        if suffix in (".tif", ".tiff"):
            from benchlab.storage import read_tiff_frame

            pixels, meta = read_tiff_frame(path)  # refuses colour and contradicted bit depth
        else:
            from benchlab.cli.frames.imagefile import decode_image

            pixels = decode_image(path)
    except BenchlabError:
        raise
    except Exception as exc:  # readers raise many types for corrupt files
        from benchlab.cli.frames.imagefile import ColourImageError

        if isinstance(exc, ColourImageError):
            raise AnalysisInputError(f"{path}: {exc}") from exc
        raise AnalysisInputError(f"{path}: not a readable image ({exc})") from exc
    pixels = np.asarray(pixels)
    if pixels.ndim not in (2, 3) or pixels.size == 0:
        raise AnalysisInputError(
            f"{path}: expected a 2-D monochrome image, got shape {pixels.shape}"
        )
    if pixels.dtype not in (np.uint8, np.uint16):
        raise AnalysisInputError(f"{path}: expected 8- or 16-bit pixels, got {pixels.dtype}")
    return pixels, meta


def roi_values(text: str | None, path: Path | None = None) -> tuple[int, int, int, int]:
    """``R0,C0,R1,C1`` (0-based, end-exclusive numpy slices) as written, before any image is
    read: four integers, R0, C0 >= 0, R1 > R0 and C1 > C0.

    Raises
    ------
    UsageError
        Missing, malformed, negative or reversed (naming the field).
    """
    if not text:
        where = f" ({path})" if path is not None else ""
        raise UsageError(f"--roi R0,C0,R1,C1 is required to analyse an image{where}")
    parts = [p.strip() for p in text.split(",")]
    names = ("R0", "C0", "R1", "C1")
    if len(parts) != 4:
        raise UsageError(f"--roi must be R0,C0,R1,C1 (4 integers), got {text!r}")
    values = []
    for name, part in zip(names, parts, strict=True):
        try:
            values.append(int(part))
        except ValueError:
            raise UsageError(f"--roi {name} must be an integer, got {part!r}") from None
    r0, c0, r1, c1 = values
    for name, v in (("R0", r0), ("C0", c0)):
        if v < 0:
            raise UsageError(f"--roi {name}={v} must be >= 0 (0-based pixel index)")
    for name, v, start_name, start in (("R1", r1, "R0", r0), ("C1", c1, "C0", c0)):
        if v <= start:
            raise UsageError(f"--roi {name}={v} must be > {start_name}={start} (R0,C0,R1,C1: "
                             "first row and column, then one past the last)")
    return r0, c0, r1, c1


def parse_roi(text: str | None, shape: tuple[int, ...], path: Path) -> tuple[int, int, int, int]:
    """``R0,C0,R1,C1`` (0-based, end-exclusive numpy slices) checked against the image.

    Raises
    ------
    UsageError
        Missing, malformed, negative or reversed (naming the field; :func:`roi_values`).
    AnalysisInputError
        Outside the image (naming the field).
    """
    # Malformed or reversed: a usage error (exit 2); outside this image: an input error.
    r0, c0, r1, c1 = roi_values(text, path)
    height, width = shape[-2], shape[-1]
    for name, v, top in (("R0", r0, height), ("C0", c0, width)):
        if v >= top:
            raise AnalysisInputError(f"--roi {name}={v} is outside 0..{top - 1} of {path}")
    for name, v, top in (("R1", r1, height), ("C1", c1, width)):
        if v > top:
            raise AnalysisInputError(
                f"--roi {name}={v} must be <= {top} ({'height' if name == 'R1' else 'width'} "
                f"of {path})")
    return r0, c0, r1, c1


def parse_pair(text: str, option: str) -> tuple[float, float]:
    """``A,B`` as two floats."""
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        return float(parts[0]), float(parts[1])
    except ValueError:
        raise AnalysisInputError(f"{option} must be two numbers A,B, got {text!r}") from None


def _format_result(result: Any, path: Path, roi: tuple[int, int, int, int]) -> str:
    d = result.diagnostics

    def num(v: float | None, fmt: str = ".2f") -> str:
        return "N/A" if v is None else format(v, fmt)

    rows = [
        ("image", str(path)),
        ("roi (r0,c0,r1,c1)", ",".join(map(str, roi))),
        ("estimator", result.estimator),
        ("resolved", "yes" if result.resolved else "no (thesis N/A)"),
        ("dark", num(result.dark)),
        ("bright", num(result.bright)),
        ("modulation (Eq. 2.9)", result.shown),
        (
            "uncertainty (1 sigma)",
            f"{result.uncertainty:.3f} [{result.interval[0]:.3f}, {result.interval[1]:.3f}] "
            f"{result.uncertainty_method}",
        ),
        ("fundamental modulation", num(result.fundamental_modulation, ".3f")),
        ("pixels", str(d.n_pixels)),
        ("px per period", num(d.px_per_period)),
        ("noise sigma", num(d.noise_sigma)),
        ("clipped", f"{100 * d.clipped_fraction:.2f}%"),
        ("aliased / phase-sensitive", f"{d.aliased} / {d.phase_sensitive}"),
    ]
    if result.lower_bound:
        rows.insert(7, ("lower bound", result.bound_reason))
    if d.bar_angle_deg is not None:
        rows.append(("bar angle (deg)", f"{d.bar_angle_deg:.2f} +- {d.bar_angle_sd_deg or 0:.2f}"))
    if d.uncertainty_model is not None:
        parts = f"{d.uncertainty_noise or 0:.4f} / {d.uncertainty_model:.4f}"
        rows.append(("uncertainty noise / model", parts))
    if d.bimodality is not None:
        rows.append(("histogram valley depth", f"{d.bimodality:.2f}"))
    if d.disagreement is not None:
        rows.append(("estimator disagreement", f"{d.disagreement:.3f}"))
    width = max(len(k) for k, _ in rows)
    lines = [f"{k:<{width}}  {v}" for k, v in rows]
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


def _check_options(args: argparse.Namespace) -> None:
    """Values that cannot be meant are usage errors (exit 2), never silently ignored."""
    if args.freq is not None and not (math.isfinite(args.freq) and args.freq > 0):
        raise UsageError(f"--freq must be a bar frequency > 0 lp/mm, got {args.freq:g}")
    if args.bootstrap is not None and args.bootstrap < 1:
        raise UsageError(f"--bootstrap must be a number of resamples >= 1, got {args.bootstrap}")
    if args.roi is not None:
        roi_values(args.roi)  # malformed or reversed: before any file is read


def analyze_command(args: argparse.Namespace) -> int:
    """``benchlab analyze TARGET``: a session folder goes to the procedures layer; an image has
    one ROI analysed; several session folders (or ``--all ROOT``) go to the batch."""
    from benchlab.cli.runs.batch import batch_command, batch_requested

    if batch_requested(args):
        return batch_command(args)
    if not args.target:
        print("benchlab: error: analyze needs an image, a session folder, or --all ROOT",
              file=sys.stderr)
        return 2
    args.target = args.target[0] if isinstance(args.target, list) else args.target
    target = Path(args.target)
    _check_options(args)
    if target.is_dir() and (target / "session.json").is_file():
        image_only = [opt for opt, value in (
            ("--roi", args.roi), ("--freq", args.freq), ("--peaks", args.peaks),
            ("--orientation", args.orientation), ("--bootstrap", args.bootstrap),
            ("--chart", getattr(args, "chart", None)),
            ("--linearise", getattr(args, "linearise", None)),
            ("--all-estimators", args.all_estimators or None)) if value is not None]
        if image_only:
            raise UsageError(f"{', '.join(image_only)}: for one image only; a session folder "
                             f"({target}) is re-analysed with its own ROIs (only --estimator)")
        from benchlab.cli.runs.procedures import analyze_session_command

        return int(analyze_session_command(args))
    from benchlab.analysis import ESTIMATORS, compare_estimators, estimate_modulation
    from benchlab.analysis.mtf.frequency import cycles_per_px

    if getattr(args, "magnification", None) is not None and not getattr(args, "chart", None):
        raise UsageError("--magnification applies with --chart only")
    if getattr(args, "chart", None):
        from benchlab.cli.frames.chart import analyze_chart_command

        return analyze_chart_command(args)
    if target.is_dir():
        raise AnalysisInputError(f"{target}: a folder without session.json; give an image file")
    pixels = read_image(target)
    linearised = None
    if getattr(args, "linearise", None):
        pixels, linearised = _linearise(pixels, target, Path(args.linearise))
    roi = parse_roi(args.roi, pixels.shape, target)
    if args.estimator is not None and args.estimator != "auto" and args.estimator not in ESTIMATORS:
        raise AnalysisInputError(
            f"--estimator {args.estimator!r} unknown; choose auto or one of "
            f"{', '.join(sorted(ESTIMATORS))}"
        )
    freq = cycles_per_px(args.freq) if args.freq is not None else None
    peaks = parse_pair(args.peaks, "--peaks") if args.peaks else None
    r0, c0, r1, c1 = roi
    region = pixels[..., r0:r1, c0:c1]
    kwargs: dict[str, Any] = {"freq_cycles_per_px": freq, "orientation": args.orientation}
    try:
        if args.all_estimators:
            results = compare_estimators(region, **kwargs)
        else:
            from benchlab.analysis.bars.estimators import resolve_estimator

            name = resolve_estimator(args.estimator)
            results = {
                name: estimate_modulation(
                    region, estimator=name, peaks=peaks, bootstrap=args.bootstrap or 0,
                    **kwargs
                )
            }
    except ValueError as exc:
        raise AnalysisInputError(f"{target}: {exc}") from exc

    def payload() -> dict[str, Any]:
        data: dict[str, Any]
        if len(results) == 1:
            data = next(iter(results.values())).to_dict()
        else:
            data = {"estimators": {k: r.to_dict() for k, r in results.items()}}
        data.update({"image": str(target), "roi": list(roi), "freq_lp_per_mm": args.freq,
                     "linearised": linearised})
        return data

    def text() -> str:
        shown = "\n\n".join(_format_result(r, target, roi) for r in results.values())
        if linearised is not None:
            shown += (f"\nlinearised with {linearised['file']} (v{linearised['version']}, gain "
                      f"{linearised['gain']:g}, {linearised['bits']}-bit curve)")
        return shown

    return print_outcome(args.json, payload, text, allow_nan=False)


def _linearise(pixels: npt.NDArray[Any], target: Path, calib: Path
               ) -> tuple[npt.NDArray[Any], dict[str, Any]]:
    """``--linearise``: the frame through the response calibration of its gain and bit depth
    (gain from the frame's benchlab metadata, else 1; 8-bit for uint8 files, else 12-bit)."""
    from benchlab.analysis.camera.photon_transfer import linearise, native_codes
    from benchlab.calibration import (
        curve_for,
        linearisation_record,
        load_calibration,
    )

    gain = 1.0
    if target.suffix.lower() in (".tif", ".tiff"):
        from benchlab.storage import load_frame_tiff

        try:
            gain = float(load_frame_tiff(target)[1].get("gain", 1.0))
        except Exception:  # noqa: BLE001 - a plain TIFF without benchlab metadata
            gain = 1.0
    bits = 8 if pixels.dtype.itemsize == 1 else 12
    doc = load_calibration(calib)
    try:
        codes = native_codes(pixels, bits)
    except ValueError as exc:
        raise AnalysisInputError(f"{target}: {exc}") from exc
    return linearise(codes, curve_for(doc, gain, bits)), linearisation_record(doc, gain, bits)


def _print_extremes(names: tuple[str, ...], seed: int) -> None:
    """The extremes bucket's table and the answer each of its buckets expects."""
    from benchlab.benchmarks.bars.extremes import expected_answers, format_extremes, run_extremes

    t0 = time.perf_counter()
    outcomes = run_extremes(names, seed)
    print(format_extremes(outcomes))
    print(f"{len(outcomes) // len(names)} extreme ROIs per estimator, "
          f"{time.perf_counter() - t0:.1f} s; ok = the expected answer:")
    print(expected_answers())


def _print_limits(seed: int) -> None:
    """The limits buckets' table (the default estimator)."""
    from benchlab.benchmarks.bars.limits import format_limits, run_limits

    t0 = time.perf_counter()
    outcomes = run_limits(seed=seed)
    print(format_limits(outcomes))
    print(f"{len(outcomes)} limit ROIs (seed {seed}), default estimator, "
          f"{time.perf_counter() - t0:.1f} s; ok = a value within 0.03 whose interval holds "
          "the truth, or a lower bound at most 0.01 above it")


def benchmark_command(args: argparse.Namespace) -> int:
    """``benchlab benchmark analysis``: the estimator speed/accuracy table per condition bucket."""
    from benchlab.analysis import ESTIMATORS
    from benchlab.benchmarks.bars.estimators import (
        Row,
        format_speed,
        format_table,
        format_worst,
        run_benchmark,
    )

    names = tuple(ESTIMATORS)
    if args.estimators:
        names = tuple(n.strip() for n in args.estimators.split(",") if n.strip())
        unknown = [n for n in names if n not in ESTIMATORS]
        if unknown:
            raise AnalysisInputError(
                f"--estimators: unknown {', '.join(unknown)}; choose from "
                f"{', '.join(sorted(ESTIMATORS))}"
            )
    n_cases = 300 if args.quick else args.cases
    if n_cases < 10:
        raise AnalysisInputError(f"--cases must be at least 10, got {n_cases}")
    if args.worst is not None and args.worst < 1:
        raise AnalysisInputError(f"--worst must be at least 1, got {args.worst}")
    if args.extremes_only:
        _print_extremes(names, args.seed)
        return 0
    if args.limits_only:
        _print_limits(args.seed)
        return 0
    t0 = time.perf_counter()
    rows: list[Row] = []
    cases, scores = run_benchmark(n_cases=n_cases, seed=args.seed, estimators=names,
                                  rows_out=rows)
    elapsed = time.perf_counter() - t0
    print(format_table(scores))
    if args.worst:
        print()
        print(format_worst(cases, rows, args.worst))
    print(f"\n{len(cases)} synthetic ROIs (seed {args.seed}) per estimator, {elapsed:.1f} s")
    print()
    _print_extremes(names, args.seed)
    print()
    _print_limits(args.seed)
    if not args.no_speed:
        shapes = ((40, 50), (100, 100), (200, 200)) if args.quick else (
            (40, 50), (100, 100), (200, 200), (500, 500), (1000, 1000))
        print()
        print(format_speed(names, shapes))
        print("(oblique 8 px bars, frequency given; median of best-of-3, this process)")
    sys.stdout.flush()
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``analyze`` and ``benchmark analysis``."""
    p = commands.add_parser(
        "analyze",
        help="bar modulation of one ROI of an image, or re-analyse a session folder",
        description=(
            "Measure the Eq. 2.9 bar modulation of one region of an 8- or 16-bit TIFF/PNG/BMP "
            "image. Given a session folder (with session.json) instead, re-analyse the whole "
            "session (only --estimator applies); several folders or --all ROOT re-analyse "
            "them in parallel with a summary table (exit 1 if any failed)."
        ),
    )
    p.add_argument("target", metavar="TARGET", nargs="*",
                   help="image file, or one or more session folders")
    p.add_argument(
        "--roi",
        metavar="R0,C0,R1,C1",
        help="region: rows R0..R1 and columns C0..C1, 0-based, end-exclusive (numpy slices)",
    )
    p.add_argument(
        "--estimator",
        metavar="NAME",
        help="auto (default: profilefit), profilefit, profilefit-fast, histogram, sinefit or "
        "variance",
    )
    p.add_argument(
        "--peaks", metavar="DARK,BRIGHT", help="use these dark and bright gray levels (manual)"
    )
    p.add_argument(
        "--freq",
        type=float,
        metavar="LP_PER_MM",
        help="bar frequency on the sensor, lp/mm (5.2 um pixels; Nyquist 96.15): a prior the "
        "measured period is checked against; above Nyquist the result is 'not resolved "
        "(aliased)'",
    )
    p.add_argument(
        "--orientation",
        choices=ORIENTATION_CHOICES,
        help="direction the intensity varies: horizontal (= sagittal, forward view) or "
        "vertical (= tangential); a prior checked against the measured direction (any angle) "
        "when omitted",
    )
    p.add_argument(
        "--all-estimators", action="store_true", help="run every estimator and compare them"
    )
    p.add_argument(
        "--bootstrap", type=int, default=None, metavar="N",
        help="bootstrap uncertainty, N >= 1 resamples (default: none)"
    )
    p.add_argument(
        "--linearise", metavar="CALIBRATION",
        help="linearise the frame first with a response calibration (benchlab run "
        "characterise): response-vN.json or a bench TOML referencing one; recorded in --json",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--chart", metavar="KIND",
        help="usaf: find the USAF 1951 chart (any place, scale, rotation) and measure every "
        "found element (Table 4.11 layout) instead of one --roi",
    )
    p.add_argument(
        "--magnification", type=float, default=None, metavar="M",
        help="with --chart: Eq. 4.1 object-to-image frequency factor (default 16.3, the forward "
        "view; ~1/M under an objective of magnification M); where the forward view's chart is "
        "not found, a hint naming the groups of the whole chart (groups -2 to 7)",
    )
    from benchlab.cli.runs.batch import add_batch_arguments

    add_batch_arguments(p)
    p.set_defaults(func=analyze_command)

    b = benchmarks.add_parser(
        "analysis",
        help="accuracy and speed of the modulation estimators on synthetic bar ROIs",
        description=(
            "Score the modulation estimators on seeded synthetic bar ROIs with known truth "
            "(angles 0-90 deg, period 2.2-40 px, PSF 0-4 px, SNR 5-200 with Poisson and read "
            "noise, 8/12-bit, shading, duty 0.4-0.6, ROIs 5x5 to 200x200, real clipping, flat, "
            "below-noise and aliased ROIs): bias, RMSE, share within 0.02/0.03, wrong "
            "resolved/unresolved calls and 95 % interval coverage per bucket of angle, period, "
            "SNR and ROI size, then microseconds per ROI up to 1000 x 1000."
        ),
    )
    b.add_argument("--quick", action="store_true", help="300 cases and a short speed table")
    b.add_argument("--cases", type=positive_int, default=1500,
                   help="number of synthetic ROIs (1500)")
    b.add_argument("--seed", type=int, default=0, help="random seed of the cases and noise")
    b.add_argument(
        "--estimators", metavar="A,B", help="comma-separated estimators (default: all)"
    )
    b.add_argument("--no-speed", action="store_true", help="skip the ROI-size speed table")
    b.add_argument("--extremes-only", action="store_true",
                   help="only the extremes bucket (no noise, no blur, dark level 0, clipping, "
                        "one-period and 1-px-wide ROIs, float TIFFs, 8-bit data in 16 bits)")
    b.add_argument("--limits-only", action="store_true",
                   help="only the limits buckets of the default estimator, 30-60 ROIs each "
                        "(near-Nyquist bars in narrow ROIs, 2.0-2.1 px with and without the "
                        "frequency, sharp bars at 3-5 px periods, two-code patterns, "
                        "over-exposed bars, bar structure vs noise, a three-bar element with "
                        "its ground)")
    b.add_argument(
        "--worst", type=positive_int, metavar="N",
        help="also list each estimator's N largest errors with the case parameters",
    )
    b.set_defaults(func=benchmark_command)
