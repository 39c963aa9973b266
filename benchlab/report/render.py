"""``benchlab report SESSION``: one self-contained HTML file (images embedded, nothing fetched).

The page is a list of sections, one renderer per result kind (:data:`SECTIONS`): a new kind of
result adds a module with a :class:`Section` and one entry here, not a branch in the page code.
Contents of an MTF session: identity, results tables, measured CTF against the simulated optics
converted to CTF, Table 4.15's verdict with the Monte Carlo bands, the frames with their ROIs and,
for every ROI, the evidence behind its number (crop, histogram with the levels used, across-bar
profile, reading with its interval, estimator, warnings). Radiometry: the fall-off and the frames
with their LED masks. The report only reads the session: frames and results are untouched.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.drivers.errors import BenchlabError
from benchlab.report.field_choice import FieldChoice, choose_fields
from benchlab.report.html import (
    annotated_image,
    caption,
    display_8bit,
    downsample,
    enlarge,
    esc,
    figure_img,
    flatten,
    key_value_table,
    local_time,
    png_data_uri,
    svg_rect,
)
from benchlab.report.tables import TABLE_VIEWS, html_table
from benchlab.session import Session, read_results

_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:1250px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:0.9em}
th,td{border:1px solid #bbb;padding:2px 8px;text-align:right}
th{background:#eee} h2{border-bottom:1px solid #ccc;margin-top:2em}
table.kv td{text-align:left} table.kv th{text-align:left}
img.plot{max-width:100%} .note{color:#555;font-size:0.9em}
.frame{position:relative;display:inline-block;margin:4px;vertical-align:top}
.frame svg{position:absolute;left:0;top:0} .frame img{image-rendering:pixelated}
.roi-label{font-family:system-ui,sans-serif;paint-order:stroke;stroke:#000;stroke-width:2px}
.roi-panel{border:1px solid #ccc;border-radius:4px;margin:8px 0;padding:4px 8px}
.roi-panel h4{margin:2px 0 6px} .roi-body{display:flex;flex-wrap:wrap;gap:10px;align-items:start}
.roi-body img.crop{image-rendering:pixelated;border:1px solid #888}
.state{font-size:0.8em;padding:1px 6px;border-radius:3px;color:#fff}
.state-resolved{background:#2e7d32} .state-unresolved{background:#c0392b}
.state-aliased{background:#8e44ad} .state-not-measurable{background:#7f8c8d}
ul.warnings{color:#a35c00;margin:0;font-size:0.9em}
ul.headline{font-size:1.05em} .warn{color:#a35c00}
"""


class ReportError(BenchlabError):
    """The session has nothing to report yet (no results), or its results lack what a
    section needs (named: file, row, key)."""


class _Row(dict[str, Any]):
    """A results row that names its file, row and key when a section asks for a key it does
    not have (a damaged or hand-edited file): ``benchlab: error: ...``, never a traceback."""

    def __init__(self, data: dict[str, Any], path: Path, index: int) -> None:
        super().__init__(data)
        self._where = f"{path}: row {index + 1}"

    def __missing__(self, key: str) -> Any:
        raise ReportError(f"{self._where} has no {key!r}; the report needs it (re-run "
                          "benchlab analyze on the session to write a new results version)")


def _named_rows(results: Path, tables: dict[str, Any], doc: dict[str, Any]
                ) -> dict[str, list[dict[str, Any]]]:
    from benchlab.session import result_file_stem

    named = doc.get("table_files")
    files: dict[str, Any] = named if isinstance(named, dict) else {}
    out: dict[str, list[dict[str, Any]]] = {}
    for name, rows in tables.items():
        if not isinstance(rows, list):
            continue  # not a table (read_results checks the ones summary.json lists)
        path = results / f"{files.get(name) or result_file_stem(name)}.json"
        out[name] = [_Row(r, path, i) if isinstance(r, dict) else r
                     for i, r in enumerate(rows)]
    return out


@dataclass
class ReportContext:
    """What every section renderer reads: the session and its latest results."""

    session: Session
    results_path: Path
    tables: dict[str, list[dict[str, Any]]]
    doc: dict[str, Any]
    _frames: dict[tuple[str, str], tuple[npt.NDArray[Any], dict[str, Any]]] = field(
        default_factory=dict)

    @property
    def summary(self) -> dict[str, Any]:
        return dict(self.doc.get("summary") or {})

    def frame(self, step_id: str, name: str) -> tuple[npt.NDArray[Any], dict[str, Any]] | None:
        """A saved frame (cached: several sections draw the same one); None if not saved."""
        key = (step_id, name)
        if key not in self._frames:
            if name not in self.session.step_frames(step_id):
                return None
            self._frames[key] = self.session.load_frame(step_id, name)
        return self._frames[key]


@dataclass(frozen=True)
class Section:
    """One part of the page. ``procedures`` limits it to sessions of those procedures."""

    title: str
    render: Callable[[ReportContext], str]
    procedures: tuple[str, ...] | None = None
    anchor: str = ""


# -- identity, tables, parameters ---------------------------------------------------------------
def _identity(ctx: ReportContext) -> str:
    meta = ctx.session.meta
    status = ctx.session.status  # "interrupted" when its writer died, whatever the file says
    if ctx.doc.get("partial"):
        status += (f" - results PARTIAL ({ctx.doc.get('steps_done')} of "
                   f"{ctx.doc.get('steps_total')} steps done)")
    stale = ctx.session.results_stale()
    if stale:
        status += f" - results STALE: {stale}"
    rows: list[tuple[str, Any]] = [
        ("operator", meta.get("operator") or "-"), ("status", status),
        ("started", local_time(meta.get("started_at"))),
        ("finished", local_time(meta.get("finished_at"))),
        ("software", meta.get("software_version")),
        ("results", f"{ctx.results_path.name} (estimator {ctx.doc.get('estimator')}, "
                    f"{local_time(ctx.doc.get('created_at'))})")]
    for rt in ctx.session.retakes():  # steps taken again (benchlab resume --retake)
        what = (", ".join(f"{k} take {v}" for k, v in sorted((rt.get("current") or {}).items()))
                + " current" if rt["status"] == "adopted" else
                f"{rt['status']}: the previous takes of {', '.join(rt['steps'])} stay current")
        rows.append((f"retake {rt['id']}", what + (f" - {rt['reason']}" if rt["reason"] else "")))
    for kind, dev in (meta.get("devices") or {}).items():
        if isinstance(dev, dict):
            rows.append((kind, ", ".join(f"{k} {v}" for k, v in dev.items())))
        else:
            rows.append((kind, str(dev)))
    return key_value_table(rows)


def _partial_mark(ctx: ReportContext) -> str:
    """The mark every result of an unfinished run carries (README: tables ``[PARTIAL]``)."""
    return " [PARTIAL]" if ctx.doc.get("partial") else ""


def _tables(ctx: ReportContext) -> str:
    summ = ctx.summary
    notes = []
    for key in ("forward_estimator", "radial_estimator", "image_centre_method",
                "chart_offset_px"):
        if summ.get(key) is not None:
            notes.append(f"{key.replace('_', ' ')}: {summ[key]}")
    chart = summ.get("chart")
    if isinstance(chart, dict):  # e.g. an implied magnification off the configured one
        notes += [f"chart finder warning: {w}" for w in chart.get("warnings") or ()]
    centre = summ.get("image_centre_rc")
    if centre:
        notes.append("image centre (row, col): " + ", ".join(f"{float(v):.1f}" for v in centre))
    out = []
    if notes:
        out.append("<p class='note'>" + esc("; ".join(notes)) + ". Coordinates are 0-based "
                   "(row, col); the thesis quotes 1-based ones.</p>")
    from benchlab.table_4_15 import verdict_rows

    for name, rows in ctx.tables.items():
        view = TABLE_VIEWS.get(name)
        if view is not None and rows:
            shown = verdict_rows(rows) if name == "table_4_15" else rows
            out.append(f"<h3>{esc(view.title)}{esc(_partial_mark(ctx))}</h3>"
                       f"{html_table(shown, view.columns)}")
    return "".join(out)


def _parameters(ctx: ReportContext) -> str:
    return key_value_table(flatten(ctx.session.meta.get("params") or {}), "kv params")


# -- MTF ----------------------------------------------------------------------------------------
def _ctf(ctx: ReportContext) -> str:
    from benchlab.protocols.mtf.curves import load_curves
    from benchlab.report.mtf import ctf_figure

    choice = choose_fields(ctx.session, ctx.tables)
    curves_file = str(ctx.session.params.get("analysis", {}).get("simulated_mtf_file", ""))
    try:
        curves = load_curves(curves_file or None)
    except (OSError, ValueError) as exc:
        curves, note = [], f"<p class='note'>No simulated curves: {esc(str(exc))}</p>"
    else:
        note = ""
    return (_ctf_caption(ctx.summary.get("target_contrast") or {})
            + note + _field_choice_note(choice) + ctf_figure(ctx.tables, curves, choice.fields))


def _field_choice_note(choice: FieldChoice) -> str:
    """Which mapping picked the solid curves (the measured one when an fov session exists)."""
    return "<p class='note'>" + "<br>".join(esc(line) for line in choice.lines) + "</p>"


def _target_text(view: str, t: dict[str, Any] | None) -> str:
    """One view's target contrast in words: value, 1 sigma and source."""
    if not t or t.get("value") is None or isinstance(t.get("value"), list) and \
            None in t["value"]:
        why = (t or {}).get("source") or "not recorded (results from before 0.2.0)"
        return f"{view}: unknown ({why})"
    v = t["value"]
    shown = (f"{v:.3f}" if not isinstance(v, list) else
             "per pattern " + ", ".join(f"{x:.3f}" for x in v))
    return f"{view}: {shown} +- {float(t.get('uncertainty') or 0.0):.3f}, {t.get('source')}"


def _ctf_caption(targets: dict[str, Any]) -> str:
    """What the bar-contrast plot compares, with each target's contrast and its source."""
    known = [_target_text(v, targets.get(v)) for v in ("forward", "radial")]
    return ("<p class='note caption'>Compared: <b>the lens's share of the bar contrast</b> (black "
            "points: the measured Eq. 2.9 contrast divided by the target's own contrast, "
            "1 sigma with both uncertainties propagated) <b>with the simulated lens</b> "
            "(lines: the sine-wave MTF of the Table 4.14 field points converted to square-wave "
            "contrast, CTF, with Coltman's series, each lobe past a zero with its reversed "
            "sign, never above 1; solid where a test's nearest field point). Grey dots: the "
            "readings as measured (lens and target together). Target contrast - "
            + esc("; ".join(known)) + ". Where a target's contrast is unknown the reading is "
            "drawn as measured (open squares) and lies below its curve by that contrast. "
            "Triangles: not resolved; crosses: aliased (above Nyquist) - neither is a measured "
            "0. Legends under each panel.</p>")


def _verdict(ctx: ReportContext) -> str:
    from benchlab.report.mtf import verdict_section

    return verdict_section(ctx.tables.get("table_4_15", []), _partial_mark(ctx))


def _sfr(ctx: ReportContext) -> str:
    from benchlab.protocols.mtf.curves import load_curves
    from benchlab.report.sfr import render_sfr_section

    curves_file = str(ctx.session.params.get("analysis", {}).get("simulated_mtf_file", ""))
    try:
        curves = load_curves(curves_file or None)
    except (OSError, ValueError):
        curves = []
    return render_sfr_section(ctx.tables, curves)


def _radial_roi(ctx: ReportContext, meta: dict[str, Any]) -> list[int]:
    roi = meta.get("roi") or ctx.session.params.get("radial", {}).get("roi")
    return list(roi) if roi else [249, 999, 290, 1050]


def _radial_frames(ctx: ReportContext) -> list[tuple[dict[str, Any], str, str]]:
    frames = [(r, orient, f"radial-{r['object_lp_per_mm']:g}-{orient}")
              for r in ctx.tables.get("table_4_12", []) for orient in ("sagittal", "tangential")]
    return [f for f in frames if ctx.frame(f[2], "radial") is not None]


def _mtf_frames(ctx: ReportContext) -> str:
    parts = []
    rows = ctx.tables.get("table_4_11", [])
    fwd = ctx.frame("forward", "forward")
    if fwd is not None:
        px, _ = fwd
        small, scale = downsample(display_8bit(px), 640)
        boxes = [(r["sagittal_roi"], "#f1c40f", r["element"] + "S") for r in rows] + [
            (r["tangential_roi"], "#00bcd4", r["element"] + "T") for r in rows]
        overlay = "".join(svg_rect(c0 * scale, r0 * scale, (c1 - c0) * scale, (r1 - r0) * scale,
                                   color) for (r0, c0, r1, c1), color, _ in boxes)
        parts.append(annotated_image(png_data_uri(small), small.shape[1], small.shape[0], overlay,
                                     "forward view with the element ROIs"))
        if boxes:  # the ROIs at full resolution, enlarged 2x, labelled
            rr0 = max(min(b[0][0] for b in boxes) - 16, 0)
            cc0 = max(min(b[0][1] for b in boxes) - 12, 0)
            rr1 = min(max(b[0][2] for b in boxes) + 16, px.shape[0])
            cc1 = min(max(b[0][3] for b in boxes) + 30, px.shape[1])
            k = max(1, min(4, 900 // max(cc1 - cc0, 1)))
            zoom = enlarge(display_8bit(px[rr0:rr1, cc0:cc1]), k)
            # Sagittal labels above their box, tangential below: neighbours never overlap.
            overlay = "".join(svg_rect((c0 - cc0) * k, (r0 - rr0) * k, (c1 - c0) * k,
                                       (r1 - r0) * k, color, label, 11.0,
                                       "above" if label.endswith("S") else "below")
                              for (r0, c0, r1, c1), color, label in boxes)
            parts.append(annotated_image(png_data_uri(zoom), zoom.shape[1], zoom.shape[0],
                                         overlay, "zoom on the ROIs (full resolution)"))
        parts.append("<p class='note'>Sagittal ROIs yellow, tangential cyan. The overview is "
                     "reduced with an area filter; the zoom shows every pixel.</p>")
    radial = _radial_frames(ctx)
    for r, orient, sid in radial:
        loaded = ctx.frame(sid, "radial")
        assert loaded is not None
        px, meta = loaded
        r0, c0, r1, c1 = _radial_roi(ctx, meta)
        m = 50
        rr0, cc0 = max(r0 - m, 0), max(c0 - m, 0)
        rr1, cc1 = min(r1 + m, px.shape[0]), min(c1 + m, px.shape[1])
        crop = display_8bit(px[rr0:rr1, cc0:cc1], 255.0 if px.dtype == np.uint8 else None)
        overlay = (svg_rect(c0 - cc0, r0 - rr0, c1 - c0, r1 - r0, "#f1c40f")
                   + f"<text x='4' y='14' fill='#f1c40f' font-size='12' class='roi-label'>"
                   f"{r['object_lp_per_mm']:g} lp/mm {orient}</text>")
        parts.append(annotated_image(png_data_uri(crop), crop.shape[1], crop.shape[0], overlay,
                                     f"radial {r['object_lp_per_mm']:g} {orient}"))
    if radial:
        parts.append("<p class='note'>Radial frames around the common ROI (yellow), at full "
                     "resolution.</p>")
    return "".join(parts)


def _evidence(ctx: ReportContext) -> str:
    from benchlab.report.roi import RoiReading, roi_panel

    summ = ctx.summary
    est_f = str(summ.get("forward_estimator") or ctx.doc.get("estimator"))
    est_r = str(summ.get("radial_estimator") or ctx.doc.get("estimator"))
    why = ("the default (auto)" if ctx.doc.get("estimator") in (None, "", "auto")
           else "chosen for this analysis")
    parts = []
    fwd = ctx.frame("forward", "forward")
    if fwd is not None:
        for row in ctx.tables.get("table_4_11", []):
            for orient in ("sagittal", "tangential"):
                reading = RoiReading.from_row(
                    row, orient, label=f"{row['element']} {orient}", view="forward",
                    roi=row[f"{orient}_roi"], estimator=f"{est_f} ({why})")
                parts.append(roi_panel(fwd[0], reading))
    for r, orient, sid in _radial_frames(ctx):
        loaded = ctx.frame(sid, "radial")
        assert loaded is not None
        reading = RoiReading.from_row(
            r, orient, label=f"radial {r['object_lp_per_mm']:g} lp/mm {orient}", view="radial",
            roi=r.get("roi") or _radial_roi(ctx, loaded[1]), estimator=f"{est_r} ({why})")
        parts.append(roi_panel(loaded[0], reading))
    return "".join(parts)


# -- radiometry ---------------------------------------------------------------------------------
def _radiometry_figure(ctx: ReportContext) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = ctx.tables.get("table_4_16", [])
    fig, ax = plt.subplots(figsize=(7, 4.5))
    pos = [r["position_mm"] for r in rows]
    def values(key: str) -> list[float]:  # a clipped row has no number: a gap, not a point
        return [float("nan") if r[key] is None else float(r[key]) for r in rows]

    ax.plot(pos, values("simulated_normalised"), "s--", label="simulated irradiance")
    ax.plot(pos, values("measured_normalised"), "o-", label="measured mean gray")
    ax.set_xlabel("LED field position (mm)")
    ax.set_ylabel("irradiance, mean gray (normalised to maximum)")
    ax.set_ylim(0, 1.1)
    ax.set_title("Relative radiometry (fig. 4.21)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    return caption("the measured mean gray level in the LED mask (circles) with the simulated "
                   "irradiance (squares, Table 4.16), each normalised to its largest value, at "
                   "each LED field position; a clipped position is a gap, not a point.") + \
        figure_img(fig, "radiometric fall-off")


@dataclass(frozen=True)
class MaskOverlay:
    """One radiometry position as the report draws it: the image the reading averaged (the
    measurement frame, linearised when the results were) and the mask computed on it."""

    position_mm: float
    image: npt.NDArray[Any]
    mask: npt.NDArray[np.bool_]
    linearised: bool


def radiometry_overlays(ctx: ReportContext) -> list[MaskOverlay]:
    """The mask of every Table 4.16 row, computed as the analysis computed it
    (:func:`benchlab.protocols.radiometry.reading_view`): on the linearised image when the
    results record a response calibration, else on the raw codes."""
    from benchlab.protocols.radiometry import position_step_id, reading_view
    from benchlab.protocols.runs import session_params

    params = session_params(ctx.session)
    thr = float(getattr(params, "mask_threshold_fraction", 0.5))
    linear = None
    if isinstance(ctx.summary.get("linearised"), dict):
        from benchlab.calibration import session_linearisation

        linear, _ = session_linearisation(ctx.session, float(getattr(params, "measurement_gain",
                                                                     1.0)),
                                          int(getattr(params, "bits", 8)))
    out = []
    for r in ctx.tables.get("table_4_16", []):
        sid = position_step_id(r["position_mm"])
        mask_f, meas_f = ctx.frame(sid, "mask"), ctx.frame(sid, "measurement")
        if mask_f is None or meas_f is None:
            continue
        try:
            image, mask = reading_view(mask_f[0], meas_f[0], thr, linear=linear)
        except ValueError:  # no LED in these frames: the notes above say the row was skipped
            continue
        out.append(MaskOverlay(float(r["position_mm"]), image, mask, linear is not None))
    return out


def _radiometry_frames(ctx: ReportContext) -> str:
    import cv2

    from benchlab.calibration import CalibrationError

    parts = []
    try:
        overlays = radiometry_overlays(ctx)
    except CalibrationError as exc:  # the linearised image cannot be rebuilt: no mask drawn
        return (f"<p class='note'>LED masks not drawn: the image the readings averaged "
                f"cannot be rebuilt ({esc(str(exc))}).</p>")
    for o in overlays:
        rows_idx, cols_idx = np.nonzero(o.mask)
        img_full = o.image
        if rows_idx.size:
            r0 = max(int(rows_idx.min()) - 30, 0)
            r1 = min(int(rows_idx.max()) + 31, img_full.shape[0])
            c0 = max(int(cols_idx.min()) - 30, 0)
            c1 = min(int(cols_idx.max()) + 31, img_full.shape[1])
        else:
            r0, r1, c0, c1 = 0, img_full.shape[0], 0, img_full.shape[1]
        crop = img_full[r0:r1, c0:c1]
        # the linearised image is in linear units (not codes): scaled to its own maximum
        grey = display_8bit(crop, max(float(crop.max()), 1e-12) if o.linearised else None)
        rgb: npt.NDArray[np.uint8] = np.asarray(cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR),
                                                dtype=np.uint8)
        contours, _ = cv2.findContours(o.mask[r0:r1, c0:c1].astype(np.uint8),
                                       cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(rgb, contours, -1, (0, 255, 255), 1)
        img, _ = downsample(rgb, 300)
        parts.append(annotated_image(png_data_uri(img), img.shape[1], img.shape[0],
                                     f"<text x='4' y='14' fill='#ff0' font-size='12' "
                                     f"class='roi-label'>{o.position_mm:g} mm</text>",
                                     f"LED at {o.position_mm:g} mm"))
    linearised = any(o.linearised for o in overlays)
    shown = ("Measurement frames linearised with the response calibration (the image the "
             "readings averaged; shown scaled to each crop's maximum)" if linearised else
             "Measurement frames, raw camera codes (no response calibration: the image the "
             "readings averaged)")
    return "".join(parts) + (f"<p class='note'>{shown}; the LED mask outlined, computed on "
                             "this same image as the analysis computed it.</p>")


def _radiometry_notes(ctx: ReportContext) -> str:
    """The response calibration the readings were linearised with (file, sha256, the
    session's copy) and every warning: clipped rows (no number) and skipped positions."""
    summ = ctx.summary
    cal = summ.get("linearised")
    if isinstance(cal, dict):
        rows: list[tuple[str, Any]] = [
            ("response calibration", cal.get("file")), ("sha256", cal.get("sha256")),
            ("session copy", cal.get("copy") or "- (session recorded before copies)"),
            ("curve", f"gain {cal.get('gain')}, {cal.get('bits')}-bit, version "
                      f"{cal.get('version')}")]
        out = key_value_table(rows)
    else:
        out = "<p class='note'>No response calibration: raw codes were averaged.</p>"
    warnings = [str(w) for w in summ.get("warnings") or ()]
    if warnings:
        out += ("<ul class='warnings radiometry-warnings'>"
                + "".join(f"<li>{esc(w)}</li>" for w in warnings) + "</ul>")
    return out


def _chart(ctx: ReportContext) -> str:
    frame = ctx.frame("forward", "forward")
    if frame is None:
        return ""
    from benchlab.report.chart import forward_chart_section

    mag = float(ctx.session.params.get("forward", {}).get("magnification", 16.3))
    return forward_chart_section(frame[0], mag)


def _characterise(ctx: ReportContext) -> str:
    from benchlab.report.characterise import characterise_html

    return characterise_html(ctx.tables, ctx.summary)


def _depth(ctx: ReportContext) -> str:
    from benchlab.report.depth import depth_section

    return depth_section(ctx.tables, ctx.session.meta.get("params") or {})


def _fov(ctx: ReportContext) -> str:
    from benchlab.report.fov import fov_section

    return fov_section(ctx.tables)


def _unwrapped(ctx: ReportContext) -> str:
    from benchlab.report.unwrap import render_unwrap_section  # after benchlab unwrap SESSION

    return render_unwrap_section(ctx.results_path, ctx.tables, ctx.summary)


#: The page, in order. A new kind of result: a module with a renderer, and one entry here.
SECTIONS: list[Section] = [
    Section("Session", _identity, anchor="session"),
    Section("Results", _tables, anchor="results"),
    Section("Measured vs simulated bar contrast (figs. 4.15-4.18)", _ctf, ("mtf",), "ctf"),
    Section("Table 4.15 verdict: averaged MTF against the Monte Carlo prediction", _verdict,
            ("mtf",), "verdict"),
    Section("Slanted-edge MTF vs simulated MTF and bars (ISO 12233 e-SFR)", _sfr, ("mtf",),
            "sfr"),
    Section("Frames with ROIs", _mtf_frames, ("mtf",), "frames"),
    Section("The USAF chart as found", _chart, ("mtf",), "chart"),
    Section("Evidence per ROI", _evidence, ("mtf",), "evidence"),
    Section("Radiometry: calibration and warnings", _radiometry_notes, ("radiometry",),
            "radiometry-notes"),
    Section("Radiometric fall-off (fig. 4.21)", _radiometry_figure, ("radiometry",), "falloff"),
    Section("Measurement frames with LED masks", _radiometry_frames, ("radiometry",), "masks"),
    Section("Camera characterisation (EMVA 1288)", _characterise, ("characterise",),
            "characterisation"),
    Section("Through focus: curves, DOF, field curvature", _depth, ("depth",), "depth"),
    Section("Field of view: image-height mapping and distortion", _fov, ("fov",), "fov"),
    Section("Unwrapped radial view (thesis 5.2)", _unwrapped, anchor="unwrapped"),
    Section("Parameters", _parameters, anchor="parameters"),
]


def report_context(session_path: str | Path) -> ReportContext:
    """The session at ``session_path`` and its latest results, as the sections read them."""
    session = Session.open(Path(session_path))
    results = session.latest_results()
    if results is None:
        raise ReportError(f"{session.path}: no results yet (finish the run or resume it, or "
                          "run benchlab analyze on it)")
    tables, doc = read_results(results)
    return ReportContext(session=session, results_path=results,
                         tables=_named_rows(results, tables, doc), doc=doc)


def render_report(session_path: str | Path,
                  timings: dict[str, float] | None = None) -> str:
    """The report of a session as one HTML string; ``timings`` (if given) receives the
    seconds each section took, by anchor (for ``benchlab benchmark report``)."""
    import time

    ctx = report_context(session_path)
    session, results = ctx.session, ctx.results_path
    procedure = session.meta["procedure"]
    out = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>benchlab report "
           f"{esc(session.path.name)}</title><style>{_CSS}</style></head><body>",
           f"<h1>benchlab - {esc(procedure)} session {esc(session.path.name)}</h1>"]
    for section in SECTIONS:
        if section.procedures is not None and procedure not in section.procedures:
            continue
        t0 = time.perf_counter()
        try:
            body = section.render(ctx)
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            # A value of the wrong kind in a results file (text where a number belongs, a
            # short ROI): say where, never a traceback.
            raise ReportError(f"{results}: the section {section.title!r} cannot be drawn from "
                              f"these results ({type(exc).__name__}: {exc})") from exc
        if timings is not None:
            timings[section.anchor] = time.perf_counter() - t0
        if body:
            out.append(f"<section id='{section.anchor}'><h2>{esc(section.title)}</h2>"
                       f"{body}</section>")
    out.append("</body></html>")
    return "".join(out)


def write_report(session_path: str | Path, out: str | Path | None = None, *,
                 overwrite: bool = True) -> Path:
    """Write the HTML report (default ``SESSION/report.html``) atomically; returns its path.
    ``overwrite=False``: an existing file is kept (``FileExistsError``)."""
    from benchlab.catalog.index import record_session
    from benchlab.storage import atomic_write_text

    target = Path(out) if out is not None else Path(session_path) / "report.html"
    written = atomic_write_text(target, render_report(session_path), overwrite=overwrite)
    record_session(Path(session_path))
    return written
