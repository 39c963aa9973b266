"""``benchlab unwrap``, ``perspective``, ``viewpoint``, ``calibrate radial`` and
``benchmark viewsynth``: view synthesis of the radial view (thesis chapter 5).

The work is in :mod:`benchlab.radial_views` (files and sessions) and
:mod:`benchlab.analysis.views.synthesis` (the maps).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from benchlab.cli.output import add_output_option, check_output, print_outcome
from benchlab.drivers.errors import BenchlabError

DEPTH_HELP = ("assumed distance of the object from the endoscope axis, mm (default 19.88, the "
              "thesis's; the shipped table covers 15.88-24.88 = side-wall depths 2-11 mm)")


class ViewArgumentError(BenchlabError, ValueError):
    """A bad command-line value (printed as ``benchlab: error: ...``)."""


def parse_centre(text: str | None) -> tuple[float, float] | None:
    """``R,C`` (0-based row, column of the optical centre) or None."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        vals = tuple(float(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 2 or not all(math.isfinite(v) for v in vals):
        raise ViewArgumentError(f"--centre {text!r}: expected R,C (two numbers, 0-based)")
    return (vals[0], vals[1])


def parse_azimuth(text: str) -> tuple[float, float]:
    """``START:END`` in degrees."""
    parts = text.split(":")
    try:
        a0, a1 = (float(p) for p in parts)
    except ValueError:
        raise ViewArgumentError(f"--azimuth-deg {text!r}: expected START:END in degrees") \
            from None
    if not 0 < a1 - a0 <= 360:
        raise ViewArgumentError(f"--azimuth-deg {text!r}: need 0 < END - START <= 360")
    return (a0, a1)


def parse_size(text: str) -> tuple[int, int]:
    """``WxH`` in pixels."""
    try:
        w, h = (int(p) for p in text.lower().split("x"))
    except ValueError:
        raise ViewArgumentError(f"--size {text!r}: expected WxH, e.g. 640x480") from None
    if not (0 < w <= 8192 and 0 < h <= 8192):
        raise ViewArgumentError(f"--size {text!r}: width and height must be 1-8192")
    return (w, h)


def _table(args: argparse.Namespace) -> Any:
    from benchlab.radial_views import load_table

    return load_table(Path(args.table) if args.table else None)


def _outcome(info: dict[str, Any], as_json: bool, lines: list[str]) -> int:
    """``info`` as JSON (``--json``), else ``lines``; exit code 0."""
    return print_outcome(as_json, lambda: info, lambda: "\n".join(lines), indent=2,
                         default=str)


def unwrap_command(args: argparse.Namespace) -> int:
    from benchlab import radial_views as rv

    target = Path(args.target)
    common = dict(
        table=_table(args), centre_rc=parse_centre(args.centre),
        object_radius_mm=args.depth_mm, azimuth_deg=parse_azimuth(args.azimuth_deg),
        px_per_mm=args.px_per_mm, interpolation=args.interpolation,
        allow_extrapolation=args.allow_extrapolation,
    )
    if target.is_dir():
        if not (target / "session.json").is_file():
            raise ViewArgumentError(f"{target}: a folder but not a session (no session.json)")
        if args.out:
            raise ViewArgumentError("--out is for one frame; a session gets a new results "
                                    "version")
        version = rv.unwrap_session(target, **common)  # type: ignore[arg-type]
        from benchlab.session import read_results

        tables, doc = read_results(version)
        info = {"results": str(version), "unwrap": tables.get("unwrap", []),
                "summary": doc.get("summary", {}).get("unwrap")}
        lines = [f"{r['step_id']}__{r['frame']}: {r['cols']}x{r['rows']} px, "
                 f"{100 * r['valid_fraction']:.1f} % valid" for r in info["unwrap"]]
        lines.append(f"results: {version}  (frames untouched)")
        return _outcome(info, args.json, lines)
    if args.out:
        check_output(args.out, force=args.overwrite, option="--out")
    info = rv.unwrap_file(target, out=args.out, overwrite=args.overwrite,
                          **common)  # type: ignore[arg-type]
    rows, cols = info["frame_shape"]
    return _outcome(info, args.json, [
        f"unwrapped {target} -> {info['out']}",
        f"object radius {info['object_radius_mm']:g} mm"
        + (" (EXTRAPOLATED beyond the table)" if info["extrapolated"] else "")
        + f", {info['px_per_mm']:g} px/mm, azimuth {info['azimuth_deg'][0]:g}:"
        f"{info['azimuth_deg'][1]:g} deg, centre {info['centre_rc'][0]:.2f},"
        f"{info['centre_rc'][1]:.2f} ({info['centre_method']})",
        f"valid {100 * info['valid_fraction']:.1f} % (the rest is outside the {rows}x{cols} "
        "frame or the table: 0 in the view, 0 in the mask page)",
        f"table {info['table_source']} sha256 {info['table_sha256'][:16]}",
    ])


def perspective_command(args: argparse.Namespace) -> int:
    from benchlab import radial_views as rv

    check_output(args.out, force=args.overwrite, option="--out")
    info = rv.perspective_file(
        Path(args.frame), out=args.out, yaw_deg=args.yaw_deg, pitch_deg=args.pitch_deg,
        fov_deg=args.fov_deg, size_wh=parse_size(args.size), table=_table(args),
        centre_rc=parse_centre(args.centre), object_radius_mm=args.depth_mm,
        interpolation=args.interpolation, allow_extrapolation=args.allow_extrapolation,
        overwrite=args.overwrite,
    )
    return _outcome(info, args.json, [
        f"perspective {args.frame} -> {info['out']}",
        f"viewpoint z {info['viewpoint_z_mm']:.4f} mm, yaw {args.yaw_deg:g}, pitch "
        f"{args.pitch_deg:g}, fov {args.fov_deg:g} deg, cylinder {info['object_radius_mm']:g} mm",
        f"valid {100 * info['valid_fraction']:.1f} %",
    ])


def viewpoint_command(args: argparse.Namespace) -> int:
    from benchlab import radial_views as rv

    info = rv.viewpoint_report(_table(args), step_mm=args.step_mm)
    return print_outcome(args.json, lambda: info, lambda: _viewpoint_text(info), indent=2)


def _viewpoint_text(info: dict[str, Any]) -> None:
    """The viewpoint report as a table (printed)."""
    lo, hi = info["operational_image_radius_mm"]
    print(f"table {info['table']} (sha256 {info['table_sha256'][:16]})")
    print(f"effective viewpoint z = {info['effective_viewpoint_z_mm']:.4f} mm; SVP spread "
          f"{info['svp_spread_um']:.1f} um over image radii {lo:.3f}-{hi:.3f} mm")
    print(f"{'image radius mm':>15} {'viewpoint z mm':>15} {'spread um':>10} "
          f"{'line rms um':>11}  curved")
    for r in info["rows"]:
        print(f"{r['image_radius_mm']:>15.3f} {r['viewpoint_z_mm']:>15.4f} "
              f"{r['spread_um']:>10.1f} {r['line_residual_um']:>11.2f}  "
              f"{'yes' if r['curved'] else ''}")


def calibrate_radial_command(args: argparse.Namespace) -> int:
    from benchlab import radial_views as rv

    check_output(args.out, force=args.overwrite, option="--out")
    info = rv.calibrate_radial_file(
        Path(args.frame), object_lp_per_mm=args.object_lp_per_mm, object_radius_mm=args.depth_mm,
        out=args.out, centre_rc=parse_centre(args.centre),
        reference=_table(args), axial_increases_inward=not args.axial_outward,
        overwrite=args.overwrite,
    )
    cmp = info["comparison"]
    lines = [f"calibrated {args.frame} -> {info['out']} ({info['rings']} rings, fit residual "
             f"{info['fit_residual_um']:.1f} um, centre {info['centre_rc'][0]:.2f},"
             f"{info['centre_rc'][1]:.2f} {info['centre_method']})"]
    if "error" in cmp:
        lines.append(f"not comparable with {info['reference']}: {cmp['error']}")
    else:
        lines.append(
            f"vs {info['reference']} at {args.depth_mm:g} mm, after an axial shift of "
            f"{cmp['axial_shift_mm']:.3f} mm: RMS {cmp['rms_axial_um']:.1f} um axial "
            f"(max {cmp['max_axial_um']:.1f}), {cmp['rms_image_radius_um']:.2f} um image radius; "
            f"magnification {cmp['magnification_calibrated']:.3f} vs "
            f"{cmp['magnification_reference']:.3f} ({cmp['magnification_error_pct']:+.2f} %)")
    return _outcome(info, args.json, lines)


def benchmark_command(args: argparse.Namespace) -> int:
    from benchlab.benchmarks.viewsynth import format_figures, run_benchmark

    figs, raw = run_benchmark(quick=args.quick)
    return print_outcome(
        args.json, lambda: {"figures": [f.__dict__ for f in figs], **raw},
        lambda: format_figures(figs) + "\n(times: min and median of repeats on a shared machine)",
        status=0 if all(f.ok is not False for f in figs) else 1, indent=2, default=str)


def _view_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--table", metavar="CSV",
                   help="ray-trace table (default: the shipped modelled table)")
    p.add_argument("--centre", metavar="R,C",
                   help="optical centre, 0-based row,col (default: from the field-of-view mask)")
    p.add_argument("--depth-mm", type=float, default=19.88, help=DEPTH_HELP)
    p.add_argument("--interpolation", default="linear",
                   choices=("nearest", "linear", "cubic", "lanczos"),
                   help="cv2.remap interpolation (default linear = bilinear)")
    p.add_argument("--allow-extrapolation", action="store_true",
                   help="accept a depth outside the table (flagged in the output metadata)")
    p.add_argument("--force", "--overwrite", dest="overwrite", action="store_true",
                   help="replace an existing --out file")
    p.add_argument("--json", action="store_true", help="print the mapping as JSON")


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``unwrap``, ``perspective``, ``viewpoint``, ``calibrate radial`` and
    ``benchmark viewsynth``."""
    p = commands.add_parser(
        "unwrap", help="unwrap the radial view (estimated orthographic view, thesis 5.2)",
        description="Unwrap the radial annulus of a raw frame into the estimated orthographic "
        "view at an assumed object depth: columns are arc length around the axis, rows axial "
        "position (row 0 farthest), both at --px-per-mm. The output TIFF has the view, then a "
        "validity mask page (0 = outside the frame or table: marked, never invented), and the "
        "mapping (table hash, centre, depth, scale) in its metadata. On a session folder every "
        "radial frame is unwrapped into a new results version; frames are untouched.\n\n"
        "example: benchlab unwrap radial.tiff --depth-mm 19.88 --px-per-mm 20 --out u.tiff",
    )
    p.add_argument("target", metavar="FRAME|SESSION", help="raw frame or session folder")
    _view_options(p)
    p.add_argument("--azimuth-deg", default="0:360", metavar="START:END",
                   help="azimuth range, degrees from +column towards +row (default 0:360; a "
                   "negative start needs '=': --azimuth-deg=-90:90)")
    p.add_argument("--px-per-mm", type=float, default=20.0,
                   help="output pixels per object mm (default 20)")
    add_output_option(p, "--out", help="output TIFF (default FRAME.unwrap.tiff next to the "
                      "frame; for a frame in a session's frames/ folder, in the current folder: "
                      "nothing is ever written into a session's frames/)")
    p.set_defaults(func=unwrap_command)

    p = commands.add_parser(
        "perspective", help="perspective view through the effective viewpoint (thesis 5.1)",
        description="Synthesize a pinhole view from the radial frame: the pinhole sits at the "
        "table's effective viewpoint on the axis, looks along azimuth --yaw-deg, tilted "
        "--pitch-deg towards the field (+z); rays meet the object cylinder at --depth-mm.\n\n"
        "example: benchlab perspective radial.tiff --yaw-deg -40 --pitch-deg 45 --fov-deg 90 "
        "--size 640x480 --out p.tiff",
    )
    p.add_argument("frame", metavar="FRAME")
    _view_options(p)
    p.add_argument("--yaw-deg", type=float, required=True, help="viewing azimuth, degrees")
    p.add_argument("--pitch-deg", type=float, required=True,
                   help="viewing elevation towards +z, degrees (-90..90)")
    p.add_argument("--fov-deg", type=float, required=True, help="horizontal field of view")
    p.add_argument("--size", required=True, metavar="WxH", help="output size in pixels")
    add_output_option(p, "--out", required=True, help="output TIFF")
    p.set_defaults(func=perspective_command)

    p = commands.add_parser(
        "viewpoint", help="effective viewpoint and SVP spread of a ray-trace table",
        description="Back-project each equal-image-radius group of the table's depths to the "
        "axis (thesis 5.1.2): the viewpoint per image radius, its distance from the effective "
        "viewpoint (um), the straight-line residual, and where lines of sight are curved.",
    )
    p.add_argument("--table", metavar="CSV", help="ray-trace table (default: shipped model)")
    p.add_argument("--step-mm", type=float, default=0.05, help="image-radius step of the rows")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=viewpoint_command)

    cal = commands.add_parser(
        "calibrate", help="calibrate without a ray tracer (radial)",
        description="Calibrations from frames of known targets.",
    )
    cal_sub = cal.add_subparsers(dest="calibration", metavar="WHAT", required=True)
    p = cal_sub.add_parser(
        "radial", help="ray-trace table from a tangential ring frame",
        description="Fit axial position against image radius from a tangential ring target "
        "(bars around the cylinder) of known frequency at a known depth, write a one-depth "
        "ray-trace table that unwrap accepts at that depth, and report how far it is from the "
        "shipped (or --table) table after the best axial shift (rings fix no axial origin).\n\n"
        "example: benchlab calibrate radial rings.tiff --object-lp-per-mm 1 --depth-mm 19.88 "
        "--out mytable.csv",
    )
    p.add_argument("frame", metavar="FRAME")
    p.add_argument("--object-lp-per-mm", type=float, required=True,
                   help="printed frequency of the ring target")
    p.add_argument("--depth-mm", type=float, required=True,
                   help="distance of the target from the axis, mm")
    p.add_argument("--force", "--overwrite", dest="overwrite", action="store_true",
                   help="replace an existing --out")
    add_output_option(p, "--out", required=True, metavar="TABLE.csv", help="table to write")
    p.add_argument("--centre", metavar="R,C", help="optical centre (default: FOV mask)")
    p.add_argument("--table", metavar="CSV", help="table to compare with (default: shipped)")
    p.add_argument("--axial-outward", action="store_true",
                   help="axial position grows outward in the image (default: inward, as the "
                   "shipped table)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=calibrate_radial_command)

    b = benchmarks.add_parser(
        "viewsynth", help="view synthesis accuracy and speed on the simulated scenes",
        description="Straightness and scale of the unwrapped card grid, period of unwrapped "
        "0.5 lp/mm bars (both roll directions), the table's viewpoint spread, map-building "
        "and remap times, and the ring self-calibration against the table. Exit 1 when a "
        "target is missed.",
    )
    b.add_argument("--quick", action="store_true", help="fewer timing repeats")
    b.add_argument("--json", action="store_true", help="print JSON")
    b.set_defaults(func=benchmark_command)
