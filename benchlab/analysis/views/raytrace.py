"""The radial view's ray-trace table (thesis chapter 5, section 5.1.1): format, reader, model.

The radial optics are rotationally symmetric, so one table row is enough per traced field
point: an object point on a cylinder around the endoscope axis and the image radius of its spot
centroid. The azimuth passes through unchanged (an object at azimuth ``phi`` is imaged at image
azimuth ``phi`` about the optical centre).

CSV format (``#`` lines are comments; one header line; one row per traced field point)
--------------------------------------------------------------------------------------
``depth_mm``
    Object depth: distance of the object cylinder from the endoscope side wall, mm.
``field_deg`` (optional)
    The ray tracer's field angle of the point (informative only).
``object_radius_mm``
    Radius of the object cylinder (distance from the axis), mm; one value per depth.
``object_z_mm``
    Axial position of the object point, mm (the thesis's coordinates: the effective viewpoint
    is at ``z = -6.4 mm``, the field of view at larger ``z``).
``image_radius_mm``
    Distance of the spot centroid from the optical centre on the sensor, mm.

Rules checked by :func:`parse_raytrace_csv` (errors name the line): the four required columns;
numbers everywhere; one object radius per depth; at least :data:`MIN_POINTS_PER_DEPTH` points per
depth; within a depth, in file order, image radius and axial position each strictly monotonic
(the map must be invertible). Depth blocks may come in any order.

Pre-processing (:meth:`RayTraceTable.resampled`): the points of every depth are resampled on
one uniform image-radius grid with a cubic spline, so each grid radius holds the object points
that image there at every depth - the thesis's "equal image radius" groups.

:func:`modelled_table` builds the table shipped as ``data/raytrace_radial_modelled.csv`` for
the simulated bench from what the thesis documents (see its docstring); it is a model, not a
Zemax trace.
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from benchlab.analysis.arrays import FloatArray

REQUIRED_COLUMNS = ("depth_mm", "object_radius_mm", "object_z_mm", "image_radius_mm")
OPTIONAL_COLUMNS = ("field_deg",)
#: A cubic spline through fewer points is not a spline.
MIN_POINTS_PER_DEPTH = 4
#: Endoscope (side wall) radius, mm (thesis chapter 4).
ENDOSCOPE_RADIUS_MM = 13.88
#: Effective viewpoint on the axis, mm (thesis section 5.1.6).
THESIS_VIEWPOINT_Z_MM = -6.4
#: Object depths of the thesis's database, mm from the side wall (section 5.1.1).
THESIS_DEPTHS_MM = tuple(float(d) for d in range(2, 12))
#: Field angles traced per depth: 36 between -20 and -60 deg (appendix G).
THESIS_FIELD_DEG = tuple(float(a) for a in np.linspace(-20.0, -60.0, 36))
#: Operational image radii of the radial view, mm (section 5.1.2: y = 15.6-16.54 mm with the
#: axis at 13.88 mm, i.e. 1.72-2.66 mm; also Table 4.14's -49 and -26 deg field points).
OPERATIONAL_IMAGE_RADIUS_MM = (1.72, 2.66)
#: Image radius of the common radial ROI centroid (Table 4.13: 477.43 px x 5.2 um), mm.
REFERENCE_IMAGE_RADIUS_MM = 477.43 * 5.2e-3
#: Object cylinder of the radial bar targets: 19.88 mm from the axis (section 5.2.2), i.e.
#: depth 6 mm from the side wall.
REFERENCE_OBJECT_RADIUS_MM = 19.88
#: Eq. 4.1 radial magnification, 16.63 / 0.95 (axial object mm per image mm).
EQ41_RADIAL_MAGNIFICATION = 17.5
#: Resampling step of the uniform image-radius grid, mm (1 um: far below a pixel).
GRID_STEP_MM = 0.001
#: Default tolerance on the viewpoint spread, mm (thesis: within 20 um over the field).
SVP_TOLERANCE_MM = 0.020
DEFAULT_TABLE_NAME = "raytrace_radial_modelled.csv"
DEFAULT_TABLE_PATH = Path(__file__).resolve().parents[1] / "data" / DEFAULT_TABLE_NAME


class RayTraceError(ValueError):
    """A ray-trace table that cannot be used (the message names the source and line)."""


@dataclass(frozen=True, eq=False)  # arrays inside: hashed and compared by identity
class RayTraceTable:
    """A validated ray-trace table: one entry per traced field point, grouped by depth.

    Attributes
    ----------
    depths_mm : ndarray (n_depths,)
        Object depths from the side wall, ascending.
    object_radius_mm : ndarray (n_depths,)
        Object cylinder radius of each depth.
    object_z_mm, image_radius_mm : tuple of ndarray
        Per depth, the field points' axial positions and image radii, sorted by image radius.
    source : str
        Where the table came from (file name or ``"<model>"``), for messages.
    """

    depths_mm: FloatArray
    object_radius_mm: FloatArray
    object_z_mm: tuple[FloatArray, ...]
    image_radius_mm: tuple[FloatArray, ...]
    source: str = "<table>"

    @property
    def n_depths(self) -> int:
        return int(self.depths_mm.size)

    @cached_property
    def sha256(self) -> str:
        """Hash of the table's numbers (not of comments or formatting)."""
        return hashlib.sha256(table_to_csv(self, comments=()).encode()).hexdigest()

    @property
    def image_radius_range_mm(self) -> tuple[float, float]:
        """Image radii covered by every depth (where the table can be used)."""
        lo = max(float(r[0]) for r in self.image_radius_mm)
        hi = min(float(r[-1]) for r in self.image_radius_mm)
        return lo, hi

    @cached_property
    def resampled(self) -> ResampledTable:
        """The pre-processed table (uniform image-radius grid, spline per depth)."""
        return resample(self)


@dataclass(frozen=True)
class ResampledTable:
    """Axial position of each depth's object point on a uniform image-radius grid.

    ``z_mm[i, k]`` is the axial position at depth ``i`` of the object point imaged at
    ``rho_mm[k]``: column ``k`` is one equal-image-radius group across depths.
    """

    rho_mm: FloatArray
    object_radius_mm: FloatArray
    z_mm: FloatArray


def resample(table: RayTraceTable, step_mm: float = GRID_STEP_MM) -> ResampledTable:
    """Group equal-image-radius points across depths: a cubic spline of axial position over
    image radius per depth, evaluated on one uniform image-radius grid (thesis 5.1.1).

    Raises
    ------
    RayTraceError
        When the depths share no image radii.
    """
    lo, hi = table.image_radius_range_mm
    if not hi > lo:
        raise RayTraceError(f"{table.source}: the depths share no image radii ({lo} > {hi} mm)")
    n = max(2, int(math.floor((hi - lo) / step_mm)) + 1)
    rho: FloatArray = lo + step_mm * np.arange(n, dtype=np.float64)
    rho[-1] = min(rho[-1], hi)
    # here: scipy.interpolate costs 0.2-0.5 s CPU to import, and the scenes import this module
    # for every simulated run and depth re-analysis, which build no spline
    from scipy.interpolate import CubicSpline

    z = np.empty((table.n_depths, n))
    for i in range(table.n_depths):
        z[i] = CubicSpline(table.image_radius_mm[i], table.object_z_mm[i])(rho)
    for arr in (rho, z):
        arr.setflags(write=False)
    return ResampledTable(rho, table.object_radius_mm.copy(), z)


# --------------------------------------------------------------------------- reading
def _number(text: str, column: str, where: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise RayTraceError(f"{where}: column {column!r} is not a number ({text!r})") from None
    if not math.isfinite(value):
        raise RayTraceError(f"{where}: column {column!r} is not finite ({text!r})")
    return value


def parse_raytrace_csv(text: str, source: str = "<table>") -> RayTraceTable:
    """Parse and validate ray-trace CSV text (format in the module docstring).

    Parameters
    ----------
    text : str
        The file's content.
    source : str
        Name used in error messages (usually the path).

    Raises
    ------
    RayTraceError
        Missing columns, a non-number, two object radii in one depth, a depth with too few
        points, or non-monotonic image radius / axial position - naming ``source:line``.
    """
    numbered = [
        (i + 1, ln) for i, ln in enumerate(text.splitlines())
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    if not numbered:
        raise RayTraceError(f"{source}: no header line")
    header_line, header_text = numbered[0]
    header = [h.strip() for h in next(csv.reader([header_text]))]
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise RayTraceError(
            f"{source}:{header_line}: missing column(s) {', '.join(missing)} "
            f"(need {', '.join(REQUIRED_COLUMNS)})"
        )
    col = {name: header.index(name) for name in REQUIRED_COLUMNS}
    blocks: dict[float, list[tuple[int, float, float, float]]] = {}
    for line_no, line in numbered[1:]:
        cells = next(csv.reader([line]))
        where = f"{source}:{line_no}"
        if len(cells) < len(header):
            raise RayTraceError(f"{where}: {len(cells)} cells, header has {len(header)}")
        vals = {name: _number(cells[j].strip(), name, where) for name, j in col.items()}
        if vals["object_radius_mm"] <= 0 or vals["image_radius_mm"] < 0:
            raise RayTraceError(f"{where}: object radius must be > 0 and image radius >= 0")
        blocks.setdefault(vals["depth_mm"], []).append(
            (line_no, vals["object_radius_mm"], vals["object_z_mm"], vals["image_radius_mm"])
        )
    if not blocks:
        raise RayTraceError(f"{source}: header but no rows")
    depths = sorted(blocks)
    radii, zs, rhos = [], [], []
    for depth in depths:
        rows = blocks[depth]
        first = rows[0][0]
        if len(rows) < MIN_POINTS_PER_DEPTH:
            raise RayTraceError(
                f"{source}:{first}: depth {depth:g} mm has {len(rows)} point(s); "
                f"need at least {MIN_POINTS_PER_DEPTH}"
            )
        for line_no, radius, _, _ in rows:
            if radius != rows[0][1]:
                raise RayTraceError(
                    f"{source}:{line_no}: object radius {radius:g} mm differs from "
                    f"{rows[0][1]:g} mm earlier in depth {depth:g} mm"
                )
        rho = np.array([r[3] for r in rows])
        z = np.array([r[2] for r in rows])
        for name, arr in (("image_radius_mm", rho), ("object_z_mm", z)):
            steps = np.sign(np.diff(arr))
            if steps.size and (np.any(steps == 0) or np.any(steps != steps[0])):
                k = int(np.flatnonzero((steps == 0) | (steps != steps[0]))[0]) + 1
                raise RayTraceError(
                    f"{source}:{rows[k][0]}: {name} is not strictly monotonic within depth "
                    f"{depth:g} mm ({arr[k - 1]:g} then {arr[k]:g})"
                )
        order = np.argsort(rho)
        radii.append(rows[0][1])
        zs.append(z[order])
        rhos.append(rho[order])
    radius_arr = np.array(radii)
    if np.any(np.diff(radius_arr) <= 0):
        raise RayTraceError(f"{source}: object radius must grow with depth, got {radii}")
    table = RayTraceTable(np.array(depths), radius_arr, tuple(zs), tuple(rhos), source)
    lo, hi = table.image_radius_range_mm
    if not hi > lo:
        raise RayTraceError(f"{source}: the depths share no image radii ({lo:g} > {hi:g} mm)")
    return table


def read_raytrace_table(path: str | Path | None = None) -> RayTraceTable:
    """Read and validate a ray-trace CSV file (``None``: the shipped modelled table).

    Raises
    ------
    RayTraceError
        Unreadable file or invalid content, naming the file and line.
    """
    p = DEFAULT_TABLE_PATH if path is None else Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RayTraceError(f"{p}: cannot read ray-trace table ({exc})") from exc
    return parse_raytrace_csv(text, str(p))


def table_to_csv(
    table: RayTraceTable,
    comments: tuple[str, ...] = (),
    field_deg: tuple[FloatArray, ...] | None = None,
) -> str:
    """The table as CSV text in the documented format (``repr`` precision)."""
    buf = io.StringIO()
    for line in comments:
        buf.write(f"# {line}\n" if line else "#\n")
    writer = csv.writer(buf, lineterminator="\n")
    cols = ["depth_mm", *(["field_deg"] if field_deg is not None else []), *REQUIRED_COLUMNS[1:]]
    writer.writerow(cols)
    for i, depth in enumerate(table.depths_mm):
        for k in range(table.object_z_mm[i].size):
            row = [f"{depth:.6g}"]
            if field_deg is not None:
                row.append(f"{field_deg[i][k]:.6g}")
            row += [
                f"{table.object_radius_mm[i]:.6g}",
                f"{table.object_z_mm[i][k]:.9g}",
                f"{table.image_radius_mm[i][k]:.9g}",
            ]
            writer.writerow(row)
    return buf.getvalue()


# --------------------------------------------------------------------------- the model
#: Mild barrel term of the modelled image radius over line-of-sight slope, mm.
_MODEL_CURVATURE_MM = 0.05
#: Slope (tan of elevation) of the line of sight through the reference point.
_MODEL_T_REF = 0.80
#: Growth of the line-of-sight bend outside the operational radii (mm of axial error per mm of
#: depth per mm^2 of image radius outside the band) and its small tilt inside it.
_MODEL_BEND_OUTSIDE = 0.1
_MODEL_BEND_INSIDE = 4e-4

MODEL_COMMENTS = (
    "benchlab ray-trace table, radial view - MODELLED, NOT A ZEMAX TRACE.",
    "Built by benchlab.analysis.views.raytrace.modelled_table() from what the thesis documents:",
    "endoscope radius 13.88 mm; depths 2-11 mm from the side wall in 1 mm steps; 36 field",
    "points per depth between -20 and -60 deg (field angle = -elevation of the line of sight);",
    "a single viewpoint on the axis at z = -6.4 mm; axial magnification 17.5 (Eq. 4.1,",
    "16.63 / 0.95) at the radial ROI (image radius 2.4826 mm) on the 19.88 mm cylinder; image",
    "radii 1.38-2.97 mm, beyond the simulated annulus (1.56-2.83 mm) on both sides. Lines of",
    "sight bend slightly (viewpoint spread < 20 um) inside the operational radii 1.72-2.66 mm",
    "and more outside them, as the thesis's fig. 5.5 shows for rays outside the design field.",
    "Columns: depth_mm, field_deg, object_radius_mm, object_z_mm, image_radius_mm (mm).",
)


def _model_rho_of_slope(t: FloatArray) -> FloatArray:
    """Modelled image radius (mm) of the line of sight with slope ``t`` = dz / dr."""
    m = REFERENCE_OBJECT_RADIUS_MM / EQ41_RADIAL_MAGNIFICATION
    dt = t - _MODEL_T_REF
    return np.asarray(REFERENCE_IMAGE_RADIUS_MM - m * dt - _MODEL_CURVATURE_MM * dt**2)


def _model_bend(rho_mm: FloatArray) -> FloatArray:
    """Extra axial slope (mm per mm of depth) that bends the lines of sight off the SVP."""
    lo, hi = OPERATIONAL_IMAGE_RADIUS_MM
    outside = np.maximum(lo - rho_mm, 0.0) + np.maximum(rho_mm - hi, 0.0)
    inside = _MODEL_BEND_INSIDE * (rho_mm - (lo + hi) / 2.0) / ((hi - lo) / 2.0)
    return np.asarray(_MODEL_BEND_OUTSIDE * outside**2 + np.where(outside > 0, 0.0, inside))


def modelled_table(
    depths_mm: tuple[float, ...] = THESIS_DEPTHS_MM,
    field_deg: tuple[float, ...] = THESIS_FIELD_DEG,
) -> tuple[RayTraceTable, tuple[FloatArray, ...]]:
    """The simulated bench's ray-trace table, modelled from the thesis's facts.

    Each field angle ``a`` is a line of sight leaving the viewpoint (axis, z = -6.4 mm) with
    elevation ``-a`` above the radial plane, slope ``t = tan(-a)``. Its image radius is a smooth
    decreasing function of ``t`` whose derivative gives the Eq. 4.1 axial magnification
    (dz / d(image radius) = 17.5) at the reference point (19.88 mm cylinder, image radius of the
    radial ROI). A point at object radius ``R`` on it sits at ``z = -6.4 + R t``, plus a small
    bend that grows with distance from the 19.88 mm cylinder and from the operational radii.

    Returns
    -------
    table, field_deg
        The table and, per depth, the field angle of each point.
    """
    t = np.tan(np.radians(-np.asarray(field_deg, dtype=np.float64)))
    rho = _model_rho_of_slope(t)
    bend = _model_bend(rho)
    radii = ENDOSCOPE_RADIUS_MM + np.asarray(depths_mm, dtype=np.float64)
    zs, rhos, fields = [], [], []
    order = np.argsort(rho)
    for radius in radii:
        z = THESIS_VIEWPOINT_Z_MM + radius * t + bend * (radius - REFERENCE_OBJECT_RADIUS_MM)
        zs.append(z[order])
        rhos.append(rho[order].copy())
        fields.append(np.asarray(field_deg, dtype=np.float64)[order])
    table = RayTraceTable(
        np.asarray(depths_mm, dtype=np.float64), radii, tuple(zs), tuple(rhos), "<model>"
    )
    return table, tuple(fields)


def modelled_table_csv() -> str:
    """The text of the shipped table (what ``data/raytrace_radial_modelled.csv`` holds)."""
    table, fields = modelled_table()
    return table_to_csv(table, MODEL_COMMENTS, fields)
