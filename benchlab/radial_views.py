"""Radial view synthesis on files and sessions: the Python API behind ``benchlab unwrap``,
``perspective``, ``viewpoint`` and ``calibrate radial``.

Frames in, TIFFs out; the arithmetic is :mod:`benchlab.analysis.views.synthesis`. Every output TIFF
has two pages - the view (same dtype as the raw frame) and its validity mask (255 = a real
raw pixel, 0 = outside the frame or the table: *marked, never invented*) - and the mapping as
JSON in the first page's ImageDescription: ``format: benchlab-view``, ``view``, the table's
SHA-256, the centre, the object radius, the scale, the source frame and its SHA-256.

Example::

    from benchlab.radial_views import unwrap_file, unwrap_session
    info = unwrap_file("radial.tiff", out="radial.unwrap.tiff", object_radius_mm=19.88)
    version = unwrap_session("sessions/2026-..._mtf")   # -> results/vN (frames untouched)
"""

from __future__ import annotations

import io
import json
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import tifffile

from benchlab.analysis.views.calibrate import calibrate_from_rings, compare_tables
from benchlab.analysis.views.raytrace import (
    REFERENCE_OBJECT_RADIUS_MM,
    RayTraceError,
    RayTraceTable,
    read_raytrace_table,
    table_to_csv,
)
from benchlab.analysis.views.synthesis import (
    ViewMaps,
    apply_maps,
    fov_centre_of_frame,
    perspective_maps,
    unwrap_maps,
    viewpoint,
)
from benchlab.drivers.errors import BenchlabError
from benchlab.storage import (
    atomic_write_bytes,
    atomic_write_text,
    make_staging_dir,
    sha256_file,
    zlib_strips,
)

if TYPE_CHECKING:
    from benchlab.session import Session

VIEW_FORMAT = "benchlab-view"
VIEW_FORMAT_VERSION = 1
#: Results-version folder holding a session's unwrapped frames.
UNWRAPPED_DIR = "unwrapped"


class ViewSynthesisError(BenchlabError, ValueError):
    """Bad input to view synthesis (printed as ``benchlab: error: ...``)."""


def load_table(path: str | Path | None) -> RayTraceTable:
    """The ray-trace table at ``path`` (None: the shipped modelled one), errors as
    :class:`ViewSynthesisError` naming file and line."""
    try:
        return read_raytrace_table(path)
    except RayTraceError as exc:
        raise ViewSynthesisError(str(exc)) from exc


def read_frame(path: str | Path) -> npt.NDArray[Any]:
    """A raw monochrome 8/16-bit frame (TIFF, PNG or BMP; a TIFF stack is averaged).

    A colour frame (a TIFF with colour samples, contiguous or planar; a PNG/BMP with 3 or 4
    channels) whose channels are equal is read as its first channel; real colour is refused.

    Raises
    ------
    ViewSynthesisError
        Missing, unreadable, colour or non-2-D file, naming it.
    """
    p = Path(path)
    if not p.is_file():
        raise ViewSynthesisError(f"{p}: no such frame file")
    try:
        colour = False
        if p.suffix.lower() in (".tif", ".tiff"):
            with tifffile.TiffFile(p) as tif:
                series = tif.series[0]
                pixels, axes = np.asarray(series.asarray()), series.axes
            if "S" in axes:  # colour samples (RGB, contiguous or planar): last, like PNG's
                pixels, colour = np.moveaxis(pixels, axes.index("S"), -1), True
        else:
            import cv2

            decoded = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
            if decoded is None:
                raise ValueError("OpenCV could not decode it")
            pixels = np.asarray(decoded)
            colour = pixels.ndim == 3 and pixels.shape[-1] in (3, 4)
    except Exception as exc:  # readers raise many types for corrupt files
        raise ViewSynthesisError(f"{p}: not a readable image ({exc})") from exc
    if colour and pixels.ndim == 3 and pixels.shape[-1] in (3, 4):
        if not np.all(pixels[..., :3] == pixels[..., :1]):
            raise ViewSynthesisError(f"{p}: colour image; the radial view is monochrome")
        pixels = pixels[..., 0]
    if pixels.ndim == 3:
        pixels = np.asarray(pixels.mean(axis=0), dtype=np.float32)
    if pixels.ndim != 2 or pixels.size == 0:
        raise ViewSynthesisError(f"{p}: expected a 2-D monochrome frame, got {pixels.shape}")
    return pixels


def in_session_frames(path: Path) -> bool:
    """Whether ``path`` lies in a session's raw ``frames/`` folder (a folder named like the
    session's, beside its ``session.json``): nothing but acquired frames may be written there."""
    from benchlab.session import FRAMES_DIR, SESSION_FILE

    folder = path.absolute().parent
    return folder.name == FRAMES_DIR and (folder.parent / SESSION_FILE).is_file()


def encode_view_tiff(view: npt.NDArray[Any], valid: npt.NDArray[np.bool_],
                     meta: Mapping[str, Any]) -> bytes:
    """Two-page TIFF bytes: the view, then its validity mask; metadata JSON on page 1."""
    doc = {"format": VIEW_FORMAT, "version": VIEW_FORMAT_VERSION, **dict(meta)}
    buf = io.BytesIO()
    with tifffile.TiffWriter(buf) as tif:
        # zlib_strips: Python's zlib, as tifffile deflates without imagecodecs (same bytes)
        for page, description in ((np.asarray(view), json.dumps(doc, allow_nan=False)),
                                  (valid.astype(np.uint8) * 255,
                                   "valid mask (255 = raw pixel)")):
            strips, rows = zlib_strips(page)
            tif.write(strips, shape=page.shape, dtype=page.dtype, rowsperstrip=rows,
                      description=description, metadata=None, compression="zlib")
    return buf.getvalue()


def load_view_tiff(path: str | Path) -> tuple[npt.NDArray[Any], npt.NDArray[np.bool_],
                                              dict[str, Any]]:
    """``(view, valid, meta)`` of a TIFF written by this module.

    Raises
    ------
    ViewSynthesisError
        Not readable or not a benchlab view.
    """
    try:
        with tifffile.TiffFile(path) as tif:
            first = tif.pages.first
            view = first.asarray()
            desc = first.description
            valid = tif.pages[1].asarray() > 0 if len(tif.pages) > 1 else np.ones(view.shape,
                                                                                   bool)
        meta = json.loads(desc)
    except Exception as exc:  # tifffile/json raise many types for foreign files
        raise ViewSynthesisError(f"{path}: not a readable benchlab view TIFF ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != VIEW_FORMAT:
        raise ViewSynthesisError(f"{path}: TIFF has no benchlab view metadata")
    return view, valid, meta


def _centre(frame: npt.NDArray[Any], centre_rc: tuple[float, float] | None,
            source: str) -> tuple[tuple[float, float], str]:
    if centre_rc is not None:
        return (float(centre_rc[0]), float(centre_rc[1])), "given"
    try:
        return fov_centre_of_frame(frame)
    except ValueError as exc:
        raise ViewSynthesisError(
            f"{source}: cannot find the optical centre from the field-of-view mask ({exc}); "
            "give --centre R,C"
        ) from exc


def _write(out: Path, view: npt.NDArray[Any], maps: ViewMaps, meta: dict[str, Any],
           overwrite: bool) -> None:
    try:
        atomic_write_bytes(out, encode_view_tiff(view, maps.valid, meta), overwrite=overwrite)
    except FileExistsError as exc:
        raise ViewSynthesisError(f"{out}: exists; choose another --out (or --overwrite)") from exc


def _check_out(out: Path, source: Path) -> None:
    if out.exists() and source.exists() and out.resolve() == source.resolve():
        raise ViewSynthesisError(f"{out}: is the input frame; raw frames are never overwritten")
    if in_session_frames(out):  # later writers would journal it as an unreadable frame
        raise ViewSynthesisError(f"{out}: in a session's raw frames/ folder, which holds "
                                 "acquired frames only; choose another --out")


def _check_view(view: npt.NDArray[Any], maps: ViewMaps, source: Path) -> None:
    """Refuse a view with no valid pixel (a frame that is not the radial view it should be)."""
    if not np.any(maps.valid):
        raise ViewSynthesisError(f"{source}: no pixel of the {view.shape[1]}x{view.shape[0]} "
                                 "view falls on the frame (0 % valid): wrong --centre, frame or "
                                 "table?; nothing written")


def unwrap_file(
    frame_path: str | Path,
    *,
    out: str | Path | None = None,
    table: RayTraceTable | None = None,
    centre_rc: tuple[float, float] | None = None,
    object_radius_mm: float = REFERENCE_OBJECT_RADIUS_MM,
    azimuth_deg: tuple[float, float] = (0.0, 360.0),
    px_per_mm: float = 20.0,
    interpolation: str = "linear",
    allow_extrapolation: bool = False,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Unwrap one raw frame to ``out`` (default ``<frame>.unwrap.tiff`` beside the frame, or in
    the current folder for a session's raw frame); returns the metadata.

    Raises
    ------
    ViewSynthesisError
        Unreadable frame, bad table or parameters, existing output.
    """
    src = Path(frame_path)
    frame = read_frame(src)
    target = Path(out) if out is not None else src.with_name(src.stem + ".unwrap.tiff")
    if out is None and in_session_frames(target):  # never beside a session's raw frames
        target = Path(src.stem + ".unwrap.tiff")
    _check_out(target, src)
    tab = table if table is not None else load_table(None)
    centre, how = _centre(frame, centre_rc, str(src))
    try:
        maps = unwrap_maps(tab, frame.shape, centre, object_radius_mm=object_radius_mm,
                           azimuth_deg=azimuth_deg, px_per_mm=px_per_mm,
                           allow_extrapolation=allow_extrapolation)
        view = apply_maps(frame, maps, interpolation)
    except ValueError as exc:
        raise ViewSynthesisError(f"{src}: {exc}") from exc
    _check_view(view, maps, src)
    meta = {**maps.meta, "centre_method": how, "interpolation": interpolation,
            "source": str(src), "source_sha256": sha256_file(src)}
    _write(target, view, maps, meta, overwrite)
    return {**meta, "out": str(target)}


def perspective_file(
    frame_path: str | Path,
    *,
    out: str | Path,
    yaw_deg: float,
    pitch_deg: float,
    fov_deg: float,
    size_wh: tuple[int, int],
    table: RayTraceTable | None = None,
    centre_rc: tuple[float, float] | None = None,
    object_radius_mm: float = REFERENCE_OBJECT_RADIUS_MM,
    interpolation: str = "linear",
    allow_extrapolation: bool = False,
    overwrite: bool = False,
) -> dict[str, Any]:
    """A perspective view of one raw frame through the effective viewpoint, to ``out``."""
    src = Path(frame_path)
    frame = read_frame(src)
    target = Path(out)
    _check_out(target, src)
    tab = table if table is not None else load_table(None)
    centre, how = _centre(frame, centre_rc, str(src))
    try:
        maps = perspective_maps(tab, frame.shape, centre, object_radius_mm=object_radius_mm,
                                yaw_deg=yaw_deg, pitch_deg=pitch_deg, fov_deg=fov_deg,
                                size_wh=size_wh, allow_extrapolation=allow_extrapolation)
        view = apply_maps(frame, maps, interpolation)
    except ValueError as exc:
        raise ViewSynthesisError(f"{src}: {exc}") from exc
    _check_view(view, maps, src)
    meta = {**maps.meta, "centre_method": how, "interpolation": interpolation,
            "source": str(src), "source_sha256": sha256_file(src)}
    _write(target, view, maps, meta, overwrite)
    return {**meta, "out": str(target)}


def viewpoint_report(table: RayTraceTable | None = None, step_mm: float = 0.02) -> dict[str, Any]:
    """Effective viewpoint, SVP spread and the per-image-radius rows, as plain data."""
    tab = table if table is not None else load_table(None)
    try:
        vp = viewpoint(tab, step_mm=step_mm)
    except RayTraceError as exc:
        raise ViewSynthesisError(str(exc)) from exc
    return {
        "table": tab.source,
        "table_sha256": tab.sha256,
        "effective_viewpoint_z_mm": vp.effective_viewpoint_z_mm,
        "svp_spread_um": vp.svp_spread_um,
        "operational_image_radius_mm": list(vp.operational_mm),
        "tolerance_um": vp.tolerance_mm * 1e3,
        "curved_count": int(vp.curved.sum()),
        "rows": vp.rows(),
    }


def calibrate_radial_file(
    frame_path: str | Path,
    *,
    object_lp_per_mm: float,
    object_radius_mm: float,
    out: str | Path,
    centre_rc: tuple[float, float] | None = None,
    reference: RayTraceTable | None = None,
    axial_increases_inward: bool = True,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Self-calibrate a one-depth table from a tangential ring frame; write it to ``out`` and
    compare it with ``reference`` (default the shipped table)."""
    src = Path(frame_path)
    frame = read_frame(src)
    centre, how = _centre(frame, centre_rc, str(src))
    target = Path(out)
    _check_out(target, src)
    try:
        cal = calibrate_from_rings(frame, object_lp_per_mm=object_lp_per_mm,
                                   object_radius_mm=object_radius_mm, centre_rc=centre,
                                   axial_increases_inward=axial_increases_inward,
                                   source=str(target))
    except ValueError as exc:
        raise ViewSynthesisError(f"{src}: {exc}") from exc
    ref = reference if reference is not None else load_table(None)
    try:
        comparison: dict[str, Any] = compare_tables(cal.table, ref, object_radius_mm)
    except RayTraceError as exc:
        comparison = {"error": str(exc)}
    comments = (
        "benchlab ray-trace table - SELF-CALIBRATED from a tangential ring frame, not traced.",
        f"frame {src} (sha256 {sha256_file(src)[:16]}), {object_lp_per_mm:g} lp/mm at "
        f"{object_radius_mm:g} mm from the axis, centre {centre[0]:.2f},{centre[1]:.2f} ({how}).",
        f"{cal.ring_radius_mm.size} rings, fit residual {cal.fit_residual_um:.1f} um. One depth: "
        "usable at that depth only; axial origin at the innermost ring (arbitrary).",
    )
    text = table_to_csv(cal.table, comments)
    try:
        atomic_write_text(target, text, overwrite=overwrite)
    except FileExistsError as exc:
        raise ViewSynthesisError(f"{target}: exists; choose another --out (or --overwrite)") \
            from exc
    return {"out": str(target), "rings": int(cal.ring_radius_mm.size),
            "fit_residual_um": cal.fit_residual_um, "period_px": cal.period_px,
            "centre_rc": list(centre), "centre_method": how,
            "reference": ref.source, "comparison": comparison}


# --------------------------------------------------------------------------- sessions
def _is_radial(meta: Mapping[str, Any], name: str) -> bool:
    target = (meta.get("bench") or {}).get("target")
    kind = target[0] if isinstance(target, list | tuple) and target else target
    return name == "radial" or kind in ("radial", "card") or (
        isinstance(kind, str) and kind.startswith(("radial", "card")))


def unwrap_session(
    session_path: str | Path,
    *,
    table: RayTraceTable | None = None,
    centre_rc: tuple[float, float] | None = None,
    object_radius_mm: float = REFERENCE_OBJECT_RADIUS_MM,
    azimuth_deg: tuple[float, float] = (0.0, 360.0),
    px_per_mm: float = 20.0,
    interpolation: str = "linear",
    allow_extrapolation: bool = False,
) -> Path:
    """Unwrap every radial frame of a session into a new results version.

    The new version carries the previous version's tables and summary forward (so it stays a
    complete snapshot), adds ``unwrap`` (one row per frame) and ``viewpoint`` tables and an
    ``unwrapped/`` folder of view TIFFs. Frames are checked against their journalled hashes
    and never modified. The centre is fitted once from all radial frames' field of view
    unless given.

    Raises
    ------
    ViewSynthesisError
        No radial frames, or bad parameters.
    """
    from benchlab.session import Session

    session = Session.open(Path(session_path))
    session.hold("benchlab unwrap")  # a live run or analysis writing it is named and refused
    try:
        return _unwrap_held(session, table, centre_rc, object_radius_mm, azimuth_deg,
                            px_per_mm, interpolation, allow_extrapolation)
    finally:
        session.release()


def _unwrap_held(
    session: Session, table: RayTraceTable | None, centre_rc: tuple[float, float] | None,
    object_radius_mm: float, azimuth_deg: tuple[float, float], px_per_mm: float,
    interpolation: str, allow_extrapolation: bool,
) -> Path:
    """:func:`unwrap_session` on a session this process holds."""
    from scipy import ndimage

    from benchlab.analysis.geometry import fov_centre
    from benchlab.session import read_results

    frames: list[tuple[str, str, npt.NDArray[Any]]] = []
    # each step's current take (an earlier take a retake superseded is not unwrapped)
    for step_id, name, _ in sorted(session.current_frames(), key=lambda f: f[2]):
        pixels, meta = session.load_frame(step_id, name)  # checks the journalled hash
        if _is_radial(meta, name):
            frames.append((step_id, name, np.asarray(pixels)))
    if not frames:
        raise ViewSynthesisError(f"{session.path}: no radial frames to unwrap")
    tab = table if table is not None else load_table(None)
    if centre_rc is None:
        mask = np.zeros(frames[0][2].shape, dtype=bool)
        for _, _, px in frames:
            level = 0.05 * float(np.percentile(px, 99.9))
            mask |= ndimage.binary_opening(px > level, iterations=2)
        try:
            circle = fov_centre(ndimage.binary_fill_holes(mask))
        except ValueError as exc:
            raise ViewSynthesisError(f"{session.path}: no field-of-view circle ({exc}); "
                                     "give --centre R,C") from exc
        centre, how = circle.centre_rc, f"{circle.method} over {len(frames)} frames"
    else:
        centre, how = (float(centre_rc[0]), float(centre_rc[1])), "given"
    try:
        maps = unwrap_maps(tab, frames[0][2].shape, centre, object_radius_mm=object_radius_mm,
                           azimuth_deg=azimuth_deg, px_per_mm=px_per_mm,
                           allow_extrapolation=allow_extrapolation)
    except ValueError as exc:
        raise ViewSynthesisError(f"{session.path}: {exc}") from exc
    session.results_dir.mkdir(exist_ok=True)
    staging = make_staging_dir(session.results_dir, ".unwrap-")
    rows: list[dict[str, Any]] = []
    try:
        for step_id, name, px in frames:
            if px.shape != tuple(maps.meta["frame_shape"]):
                raise ViewSynthesisError(f"{step_id}__{name}: frame shape {px.shape} differs")
            view = apply_maps(px, maps, interpolation)
            file = f"{step_id}__{name}.unwrap.tiff"
            src = session.step_frames(step_id)[name]  # the current take, as loaded
            meta = {**maps.meta, "centre_method": how, "interpolation": interpolation,
                    "source": src.relative_to(session.path).as_posix(),
                    "source_sha256": sha256_file(src)}
            atomic_write_bytes(staging / file, encode_view_tiff(view, maps.valid, meta))
            rows.append({"step_id": step_id, "frame": name, "file": f"{UNWRAPPED_DIR}/{file}",
                         "rows": maps.shape[0], "cols": maps.shape[1],
                         "valid_fraction": maps.valid_fraction})
        previous = session.latest_results()
        tables: dict[str, list[dict[str, Any]]] = {}
        summary: dict[str, Any] = {}
        estimator = "unwrap"
        if previous is not None:
            tables, doc = read_results(previous)
            summary = dict(doc.get("summary") or {})
            estimator = str(doc.get("estimator") or estimator)
        vp_rows: list[dict[str, Any]] = []
        if tab.n_depths > 1:
            vp_rows = [dict(r) for r in viewpoint(tab).rows()]
        tables = {**tables, "unwrap": rows, "viewpoint": vp_rows}
        summary["unwrap"] = {k: maps.meta[k] for k in (
            "table_sha256", "table_source", "centre_rc", "object_radius_mm", "px_per_mm",
            "azimuth_deg", "extrapolated", "z_top_mm")}
        summary["unwrap"].update(centre_method=how, interpolation=interpolation,
                                 carried_from=previous.name if previous else None)
        # The views move into the version before it appears: never a version without them.
        version = session.write_results(tables, summary=summary, estimator=estimator,
                                        extra_dirs={UNWRAPPED_DIR: staging})
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return version
