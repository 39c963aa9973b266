"""The UI's only door into the layers below: bench, camera, analysis, procedures, sessions.

Every function here is a thin call into the same code the command line uses; the UI keeps no
measurement logic of its own. Functions that block (device I/O, analysis, disk) are meant to
be called from thread workers.
"""

from __future__ import annotations

import errno
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from benchlab.bench import plain_target
from benchlab.drivers import errors
from benchlab.tui.widgets import Roi

if TYPE_CHECKING:
    from contextlib import AbstractContextManager

    from benchlab.acceptance.spec import Spec
    from benchlab.analysis.focus.live import ChartTracker
    from benchlab.analysis.focus.live import LiveReading as ChartLiveReading
    from benchlab.bench import Bench
    from benchlab.catalog.index import TrendPoint
    from benchlab.protocols.engine import ProgressFn, PromptFn, ResultFn, Runner, Step


def plain_error(exc: BaseException) -> str:
    """Explain ``exc`` to a technician in plain words (one or a few lines)."""
    detail = str(exc) or exc.__class__.__name__
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return (
            "The disk is full; nothing more could be saved. Free some space, then resume.\n"
            f"{detail}"
        )
    if isinstance(exc, errors.DeviceNotFoundError):
        return f"A device was not found. Check that it is plugged in and powered.\n{detail}"
    if isinstance(exc, errors.DeviceLostError):
        return f"The connection to a device was lost. Check its cable and power.\n{detail}"
    if isinstance(exc, errors.DeviceTimeoutError):
        return f"A device did not answer in time.\n{detail}"
    if isinstance(exc, errors.SafetyLimitError):
        return f"Refused: that would exceed a safety limit. Nothing was sent.\n{detail}"
    if isinstance(exc, errors.SettingOutOfRangeError):
        return f"That setting is out of range. Nothing was sent.\n{detail}"
    if isinstance(exc, errors.ProtocolError):
        return f"A device gave an unexpected reply.\n{detail}"
    if isinstance(exc, FileNotFoundError):
        return f"File not found: {exc.filename or detail}"
    if isinstance(exc, PermissionError) or (isinstance(exc, OSError)
                                            and exc.errno == errno.EROFS):
        return (f"Cannot write {exc.filename or 'there'}: the folder is read-only or you have "
                "no permission. Nothing was changed.")
    if isinstance(exc, FileExistsError):
        return f"{exc.filename or 'The file'} already exists; nothing was overwritten."
    if isinstance(exc, OSError):
        return (f"A file could not be read or written: {exc.filename or ''} "
                f"({exc.strerror or detail}).")
    if isinstance(exc, errors.BenchlabError):
        return detail
    return f"{exc.__class__.__name__}: {detail}"


@dataclass(frozen=True)
class LiveReading:
    """What the live view shows for one frame."""

    index: int
    preview: npt.NDArray[np.float32]
    frame_shape: tuple[int, int]
    roi: Roi
    preview_roi: Roi
    roi_pixels: npt.NDArray[np.generic]
    max_code: float
    dark: float | None
    bright: float | None
    modulation: float | None
    resolved: bool
    clipped_fraction: float | None
    sharpness: float | None
    exposure_ms: float
    gain: float
    note: str = ""
    #: Dark and bright peaks of the ROI histogram (marked on the histogram widget).
    peaks: tuple[float | None, float | None] = (None, None)
    #: The modulation is a lower bound (clipped bars): shown as ">= x", never as a value.
    lower_bound: bool = False


def preview_of(pixels: npt.NDArray[np.generic], max_side: int = 320) -> npt.NDArray[np.float32]:
    """A small float copy of a frame for display (area-averaged)."""
    import cv2

    rows, cols = pixels.shape[:2]
    scale = min(1.0, max_side / max(rows, cols))
    img = np.asarray(pixels, dtype=np.float32)
    if scale >= 1.0:
        return img
    size = (max(1, int(cols * scale)), max(1, int(rows * scale)))
    small: npt.NDArray[np.float32] = np.asarray(
        cv2.resize(img, size, interpolation=cv2.INTER_AREA), dtype=np.float32
    )
    return small



# -- the bench -------------------------------------------------------------------------------


class OpenedBench:
    """An open bench and the context that closes it (safe state first)."""

    def __init__(self, bench: Bench, context: AbstractContextManager[Bench]) -> None:
        self.bench = bench
        self._context = context

    def close(self) -> None:
        """Safe state (LEDs off, stage stopped), then every device closed."""
        self._context.__exit__(None, None, None)


def open_bench(config: Path | None, simulate: bool, seed: int | None = 0) -> OpenedBench:
    """Open every configured device (or the simulated bench), exactly like the CLI does."""
    from benchlab.bench import Bench, BenchConfig

    cfg = BenchConfig.load(config, simulate=simulate)
    context = Bench.open(cfg, simulate=simulate, seed=seed)
    bench = context.__enter__()
    return OpenedBench(bench, context)


def safe_state(bench: Bench) -> None:
    """Every LED channel off, stage stopped."""
    bench.safe_state()


def describe_devices(bench: Bench, live: bool = True) -> dict[str, list[tuple[str, str]]]:
    """Label/value rows per device; ``live`` also reads LED currents and the stage position.

    Read errors are shown in the rows, in plain words, instead of raising.
    """
    ids = bench.identities()
    out: dict[str, list[tuple[str, str]]] = {"camera": [], "leds": [], "stage": []}
    kind = "simulated" if ids.get("simulated") else "hardware"
    for key, name in (("camera", "camera"), ("led", "leds"), ("stage", "stage")):
        ident = ids.get(key)
        if not ident:
            out[name] = [("status", "not configured")]
            continue
        out[name] = [
            ("model", str(ident.get("model") or "?")),
            ("serial", str(ident.get("serial") or "?")),
            ("firmware", str(ident.get("firmware") or "?")),
        ]
        if ident.get("port"):  # simulated ports are pseudo-terminals: name the kind only
            port = "simulated (pty)" if kind == "simulated" else str(ident["port"])
            out[name].append(("port", port))
    if bench.camera is not None:
        settings = getattr(bench, "_camera_settings", {}) or {}
        if settings:
            out["camera"].append(("mode", f"{settings.get('width')}x{settings.get('height')} "
                                          f"{settings.get('bits')}-bit"))
    if not live:
        return out
    if bench.led is not None:
        try:
            for ch in range(1, bench.led.channel_count + 1):
                state = "ON " if bench.led.is_on(ch) else "off"
                iset = bench.led.current_ma(ch)
                ceiling = bench.config.led_ceiling_ma(ch)
                limit = f"  limit {ceiling:g}" if ceiling is not None else ""
                out["leds"].append((f"ch {ch}", f"{state} {iset:g} mA{limit}"))
        except Exception as exc:  # noqa: BLE001 - shown in the panel
            out["leds"].append(("error", plain_error(exc)))
    if bench.stage is not None:
        try:
            stage = bench.stage
            out["stage"].extend([
                ("position", f"{stage.position_mm:.3f} mm"),
                ("homed", "yes" if stage.is_homed else "no"),
                ("moving", "yes" if stage.is_moving else "no"),
            ])
            travel = bench.config.stage_travel_mm
            if travel is not None:
                out["stage"].append(("travel", f"{travel[0]:g} .. {travel[1]:g} mm"))
        except Exception as exc:  # noqa: BLE001 - shown in the panel
            out["stage"].append(("error", plain_error(exc)))
    return out


def device_action(bench: Bench, what: str, stop: threading.Event | None = None) -> str:
    """``"safe"``: LEDs off and stage stopped; ``"home"``: home the stage, stopped at once
    when ``stop`` is set meanwhile (the app quitting). Returns a message."""
    if what == "safe":
        bench.safe_state()
        return "All LEDs off, stage stopped."
    if what == "home":
        if not bench.has_stage:
            return "No stage configured."
        bench.home_stage(abort=stop)
        return "Stage homed."
    raise ValueError(f"unknown device action {what!r}")


def grab(
    bench: Bench, exposure_ms: float, gain: float, *, fresh: bool
) -> tuple[npt.NDArray[Any], dict[str, Any]]:
    """One frame at these settings: ``(pixels, metadata)``.

    ``fresh=False`` (the live view): the camera's newest frame, without waiting for a new
    exposure - the stream runs at the camera's frame rate, not half of it. ``fresh=True``
    (a reading to act on, e.g. back-focus sharpness): a frame exposed wholly after this call,
    as a procedure's measurement frames are (``Bench.grab``).
    """
    pixels, meta = bench.grab(exposure_ms=exposure_ms, gain=gain, fresh=fresh)
    return np.asarray(pixels), dict(meta or {})


def max_code_of(pixels: npt.NDArray[Any], meta: Mapping[str, Any]) -> float:
    """Full-scale code of a frame, as every analysis judges clipping: from its bit depth
    (:func:`~benchlab.analysis.sfr.measure.full_scale_of_frame`; 65520 for 12-bit codes
    MSB-aligned in 16-bit words), else from its dtype and code grid, else its maximum."""
    from benchlab.analysis.sfr.measure import full_scale_of, full_scale_of_frame

    top = full_scale_of_frame(pixels, meta)
    if top is None:
        top = full_scale_of(pixels)
    return float(top) if top is not None else float(np.max(pixels, initial=0))


# -- analysis for the live view ---------------------------------------------------------------


def estimator_names() -> list[str]:
    from benchlab.analysis.bars.estimators import ESTIMATORS

    return list(ESTIMATORS)


def reanalysis_estimators() -> list[str]:
    """Estimators a session can be re-analysed with: ``"auto"`` (per view) and the library's."""
    return ["auto", *estimator_names()]


def default_estimator() -> str:
    try:
        from benchlab.analysis.bars.estimators import DEFAULT_ESTIMATOR
    except ImportError:  # pragma: no cover - analysis layer not installed
        return ""
    return DEFAULT_ESTIMATOR


def mount_target(bench: Bench, target: object) -> None:
    """Mount a target in the simulated world (what a manual set-up step does)."""
    bench.mount(target)


def live_reading(
    frame: tuple[npt.NDArray[Any], Mapping[str, Any]],
    roi: Roi,
    estimator: str,
    orientation: str | None,
    index: int,
    exposure_ms: float,
    gain: float,
    *,
    zoom: bool = False,
    preview_max_side: int = 320,
) -> LiveReading:
    """Everything the live view shows about one frame (runs in the acquisition thread);
    the preview's longest side is at most ``preview_max_side`` pixels."""
    from benchlab.analysis.bars.estimators import estimate_modulation
    from benchlab.analysis.bars.profilefit import narrow_roi_note
    from benchlab.analysis.focus.sharpness import sharpness

    pixels, meta = frame
    rows, cols = pixels.shape[:2]
    roi = roi.moved(0, 0, (rows, cols))
    roi_pixels = roi.slice(pixels)
    max_code = max_code_of(pixels, meta)
    shown, origin = pixels, (0, 0)
    if zoom:  # the ROI with a margin of twice its size on every side
        margin = max(16, 2 * max(roi.height, roi.width))
        r0, c0 = max(0, roi.row - margin), max(0, roi.col - margin)
        r1 = min(rows, roi.row + roi.height + margin)
        c1 = min(cols, roi.col + roi.width + margin)
        shown, origin = pixels[r0:r1, c0:c1], (r0, c0)
    preview = preview_of(shown, preview_max_side)
    sy, sx = preview.shape[0] / shown.shape[0], preview.shape[1] / shown.shape[1]
    preview_roi = Roi(
        int((roi.row - origin[0]) * sy), int((roi.col - origin[1]) * sx),
        max(1, round(roi.height * sy)), max(1, round(roi.width * sx)),
    )
    note = ""
    dark = bright = modulation = clipped = None
    resolved = lower_bound = False
    try:
        result = estimate_modulation(
            roi_pixels, estimator=estimator, orientation=orientation, max_code=max_code
        )
        modulation, resolved = result.modulation, result.resolved
        lower_bound = result.lower_bound
        clipped = result.diagnostics.clipped_fraction
        dark, bright = result.dark, result.bright
        if result.warnings:
            note = result.warnings[0]
        narrow = narrow_roi_note(roi_pixels.shape[-2:], result.diagnostics.px_per_period,
                                 result.diagnostics.bar_angle_deg, freq_given=False)
        if narrow is not None:
            note = narrow  # first: the reading cannot be honest whatever else it says
    except ValueError as exc:
        note = str(exc)
    peaks = (dark, bright) if estimator == "histogram" else histogram_peaks(roi_pixels, max_code)
    focus: float | None
    try:
        focus = sharpness(pixels, (roi.row, roi.col, roi.row + roi.height, roi.col + roi.width))
    except ValueError:
        focus = None
    if clipped is None:
        values = np.asarray(roi_pixels, dtype=np.float64)
        clipped = float(np.mean(values >= max_code)) if values.size else None
    return LiveReading(
        index=index, preview=preview, frame_shape=(rows, cols), roi=roi,
        preview_roi=preview_roi, roi_pixels=roi_pixels, max_code=max_code, dark=dark,
        bright=bright, modulation=modulation, resolved=resolved, clipped_fraction=clipped,
        sharpness=focus, exposure_ms=exposure_ms, gain=gain, note=note, peaks=peaks,
        lower_bound=lower_bound,
    )


def histogram_peaks(
    roi_pixels: npt.NDArray[Any], max_code: float
) -> tuple[float | None, float | None]:
    """Dark and bright histogram peaks of the ROI (the histogram estimator's reading)."""
    from benchlab.analysis.bars.estimators import estimate_modulation

    try:
        result = estimate_modulation(roi_pixels, estimator="histogram", max_code=max_code)
    except ValueError:
        return None, None
    return result.dark, result.bright


# -- the live focus aid (whole chart on every frame) -----------------------------------------


def focus_tracker(estimator: str = "histogram") -> ChartTracker:
    """A :class:`~benchlab.analysis.focus.live.ChartTracker` (the pose tracked between frames)."""
    from benchlab.analysis.focus.live import ChartTracker

    return ChartTracker(estimator=estimator)


def read_focus(tracker: ChartTracker, pixels: npt.NDArray[Any]
               ) -> tuple[ChartLiveReading | None, float | None, str]:
    """One frame's whole-chart reading: ``(reading, mean edge MTF50, "")``, or ``(None, None,
    why)`` when the chart is not found, or nothing could be read where it was tracked (it left
    the view between two finds); the tracker then looks for it again on the next frame."""
    from benchlab.analysis.chart.finder import ChartNotFoundError
    from benchlab.analysis.focus.live import mean_edge_mtf50, nothing_read

    try:
        reading = tracker.read(pixels)
    except ChartNotFoundError as exc:
        tracker.reset()
        detail = str(exc).split(":", 1)[-1].strip()
        return None, None, f"chart not found: {detail}" if detail else "chart not found"
    if nothing_read(reading):
        tracker.reset()
        return None, None, "chart not found: nothing read where it was; looking again"
    return reading, mean_edge_mtf50(reading), ""


# -- procedures ------------------------------------------------------------------------------


def procedure_checklist(procedure: str, params_file: Path | None) -> list[Step]:
    """The steps a run of ``procedure`` would take with these parameters (validated)."""
    from benchlab.protocols import load_params
    from benchlab.protocols.runs import make_procedure

    params = load_params(procedure, params_file)
    return list(make_procedure(params).steps())


def make_runner(
    *,
    procedure: str,
    resume: Path | None,
    bench: Bench,
    params: Path | None,
    root: Path,
    prompt: PromptFn,
    progress: ProgressFn,
    abort: threading.Event,
    on_result: ResultFn,
    estimator: str | None = None,
    operator: str = "",
    sample: str = "",
    lot: str = "",
) -> Runner:
    """A runner for a fresh run, or for resuming the session at ``resume``; ``sample`` and
    ``lot``: the unit's serial number and lot, stored in session.json."""
    from benchlab.procedures import procedure_name
    from benchlab.protocols import load_params, resume_run, start_run
    from benchlab.protocols.runs import check_estimator

    if resume is not None:
        return resume_run(
            resume, bench=bench, prompt=prompt, progress=progress, abort=abort,
            on_result=on_result,
        )
    return start_run(
        procedure_name(procedure), bench=bench, params=load_params(procedure, params),
        root=root, operator=operator, prompt=prompt, progress=progress, abort=abort,
        on_result=on_result, estimator=check_estimator(estimator), sample=sample, lot=lot,
    )


def check_spec(path: Path) -> Spec:
    """The checked spec file (:class:`~benchlab.acceptance.spec.SpecError` lists every
    problem), before a run starts."""
    from benchlab.acceptance.spec import load_spec

    return load_spec(path)


def verify_run(session_path: Path, spec_path: Path) -> dict[str, Any]:
    """Verify a finished session (with the other sessions of its unit) against a spec,
    store the verdict as a new version in each, update the catalogue; the stored record."""
    from benchlab import __version__
    from benchlab.acceptance.spec import load_spec
    from benchlab.acceptance.store import record_of, store_verdict
    from benchlab.acceptance.verify import read_session, verify_unit
    from benchlab.catalog.index import record_session

    results = read_session(session_path)
    unit = verify_unit([results], load_spec(spec_path))
    record = record_of(unit, __version__)
    for s in unit.sessions:
        _, record["version"], _ = store_verdict(s.path, record)
        record_session(s.path)
    return record


def verdict_rows(record: Mapping[str, Any]) -> list[dict[str, Any]]:
    """A stored verdict as short rows for the results panel (limit, row, reading, interval,
    limit, verdict)."""
    def num(v: Any) -> str:
        return "-" if v is None else f"{v:.4g}"

    out = []
    for r in record["rows"]:
        lo, hi = r.get("min"), r.get("max")
        limit = (f"{lo:g}..{hi:g}" if lo is not None and hi is not None
                 else f">={lo:g}" if lo is not None else f"<={hi:g}")
        verdict = r["verdict"] + ("*" if str(r.get("decided_by", "")).startswith("reading")
                                  else "")
        out.append({"limit": r["limit_id"], "row": r.get("row") or "-",
                    "reading": num(r.get("reading")),
                    "interval": f"{num(r.get('low'))}..{num(r.get('high'))}",
                    "spec": limit, "verdict": verdict})
    return out


def run_ending(exc: BaseException) -> str:
    """``"aborted"``, ``"failed"`` (a step failed: retry it) or ``"error"``."""
    from benchlab.protocols import RunAborted, StepFailed

    if isinstance(exc, RunAborted):
        return "aborted"
    if isinstance(exc, StepFailed):
        return "failed"
    return "error"


def procedure_frame(bench: Bench, runner: Runner) -> npt.NDArray[Any]:
    """A fresh frame at the procedure's camera settings (a live figure in a prompt)."""
    params = getattr(getattr(runner, "procedure", None), "params", None)
    exposure = float(getattr(params, "exposure_ms", 300.0))
    gain = float(getattr(params, "gain", 1.0))
    pixels, _ = grab(bench, exposure, gain, fresh=True)
    return pixels


def focus_sharpness(bench: Bench, runner: Runner) -> float:
    """Sharpness of a fresh frame at the procedure's camera settings (back-focus step)."""
    from benchlab.analysis.focus.sharpness import sharpness

    return sharpness(procedure_frame(bench, runner))


# -- sessions --------------------------------------------------------------------------------


@dataclass(frozen=True)
class SessionSummary:
    """One line of the sessions browser."""

    path: Path
    procedure: str
    status: str
    started_at: str
    operator: str
    steps_done: int
    result_versions: int
    error: str = ""
    sample: str = ""
    #: The newest results version, when it cannot be read (the catalogue's listing).
    unreadable_version: int | None = None


def list_sessions(root: Path) -> list[SessionSummary]:
    """Every session folder under ``root``, newest first; unreadable ones say why."""
    if not root.is_dir():
        return []
    return list_sessions_of(sorted(root.iterdir(), reverse=True))


def list_sessions_of(folders: list[Path]) -> list[SessionSummary]:
    """The given session folders read from disk (the truth); non-sessions are left out."""
    from benchlab.session import Session

    out: list[SessionSummary] = []
    for folder in folders:
        if not (folder / "session.json").exists():
            continue
        try:
            s = Session.open(folder)
            meta = s.meta
            out.append(SessionSummary(
                path=folder, procedure=s.procedure, status=s.status,
                started_at=str(meta.get("started_at", ""))[:19].replace("T", " "),
                operator=str(meta.get("operator", "")),
                steps_done=len(s.completed_steps()), result_versions=len(s.result_versions()),
                sample=str(meta.get("sample") or ""),
            ))
        except Exception as exc:  # noqa: BLE001 - a damaged session is listed, not fatal
            out.append(SessionSummary(folder, "?", "unreadable", "", "", 0, 0, plain_error(exc)))
    return out


def session_tables(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The latest results version of a session: ``(tables, summary)`` (empty if none)."""
    from benchlab.session import Session, read_results

    latest = Session.open(path).latest_results()
    if latest is None:
        return {}, {}
    return read_results(latest)


def table_rows(data: Any) -> tuple[list[str], list[Mapping[str, Any]]]:
    """Columns and rows of a results table (``{"columns", "rows"}`` or a list of rows)."""
    if isinstance(data, Mapping):
        rows = [r for r in data.get("rows") or [] if isinstance(r, Mapping)]
        columns = [str(c) for c in data.get("columns") or []]
    elif isinstance(data, list):
        rows = [r for r in data if isinstance(r, Mapping)]
        columns = []
    else:
        rows, columns = [], []
    if not columns:
        for row in rows:
            columns.extend(str(k) for k in row if str(k) not in columns)
    return columns, rows


def reanalyse(path: Path, estimator: str | None) -> Path:
    """A new results version from the saved frames (frames are never modified)."""
    from benchlab.protocols import reanalyze
    from benchlab.protocols.runs import check_estimator

    return Path(reanalyze(path, estimator=check_estimator(estimator)))


def write_report(path: Path) -> Path:
    """The session's HTML report (same as ``benchlab report SESSION``)."""
    from benchlab.report.render import write_report as _write

    return Path(_write(path))


CtfBands = dict[str, list[tuple[list[float], list[float]]]]


def simulated_ctf_bands(points: int = 120) -> tuple[CtfBands, float]:
    """Best and worst simulated CTF over the field points and both directions, per view (the
    band the Run screen's plot draws), and the Nyquist frequency (lp/mm)."""
    from benchlab.analysis.mtf.frequency import nyquist_lp_per_mm
    from benchlab.protocols.mtf.curves import load_curves
    from benchlab.report.mtf import simulated_ctf

    nyq = nyquist_lp_per_mm()
    grid = np.linspace(0.0, 1.15 * nyq, points)
    bands: CtfBands = {}
    by_view: dict[str, list[npt.NDArray[np.float64]]] = {}
    for curve in load_curves(None):
        by_view.setdefault(curve.view, []).append(simulated_ctf(curve, grid))
    for view, ctfs in by_view.items():
        stack = np.vstack(ctfs)
        bands[view] = [(grid.tolist(), stack.max(axis=0).tolist()),
                       (grid.tolist(), stack.min(axis=0).tolist())]
    return bands, nyq


def target_words(target: object) -> str:
    """A mounted simulated target in words (for the operator, never a Python list)."""
    t = plain_target(target)
    if isinstance(t, list) and t and t[0] == "radial":
        freq = f"{float(t[1]):g}" if len(t) > 1 else "?"
        roll = f", {t[2]}" if len(t) > 2 else ""
        return f"radial bars {freq} lp/mm{roll}"
    return {"usaf": "USAF 1951 chart", "led": "radiometry LED", "dark": "dark (lens capped)",
            "bars": "bar target", "flat": "flat field", None: "nothing"}.get(
        t if isinstance(t, str) or t is None else "", str(t))


def display_table(name: str, data: Any) -> tuple[str, list[str], list[list[str]]]:
    """A results table as (title, headers, cells) for a narrow terminal: the known tables use
    the report's headers and number formats, with the modulation columns right after the
    first so that 80 columns show them; unknown tables show every column as stored."""
    from benchlab.report.tables import TABLE_VIEWS, cell, row_cell

    columns, rows = table_rows(data)
    if name == "table_4_15":  # "not resolved", never an average built on a stored 0
        from benchlab.table_4_15 import verdict_rows

        rows = [r for r in verdict_rows(rows)]  # as Mapping rows (typing)
    view = TABLE_VIEWS.get(name)
    if view is None:
        return name, columns, [[cell(r.get(c), ".4g") for c in columns] for r in rows]
    cols = list(view.columns)
    first, rest = cols[:1], cols[1:]
    mods = [c for c in rest if c[0].endswith("_modulation")]
    ordered = first + mods + [c for c in rest if c not in mods]
    title = view.title.split(" - ")[0]
    return (title, [h for _, h, _ in ordered],
            [[row_cell(r, k, f) for k, _, f in ordered] for r in rows])


# -- session catalogue ---------------------------------------------------------------------

#: Sort orders of the catalogue listing: (column, newest/largest first).
CATALOG_SORTS = (("started_at", True), ("sample", False), ("status", False),
                 ("procedure", False), ("results_version", True), ("id", False))


def catalog_sessions(root: Path, text: str = "", sort: str = "started_at",
                     descending: bool = True) -> list[SessionSummary]:
    """Sessions from the catalogue (rebuilt from the folders if missing), those whose id,
    sample, procedure, status or operator contain ``text`` (any case)."""
    from benchlab.catalog.index import Catalog, session_folder

    if not root.is_dir():
        return []
    with Catalog.open(root) as catalog:
        rows = catalog.sessions(sort=sort, descending=descending)
    needle = text.strip().lower()
    keys = ("id", "sample", "procedure", "status", "operator")
    return [
        SessionSummary(
            path=session_folder(str(root / r["id"])), procedure=r["procedure"],
            status=r["status"],
            started_at=str(r["started_at"])[:19].replace("T", " "), operator=r["operator"],
            steps_done=-1, result_versions=r["results_version"] or 0, error=r["error"],
            sample=r["sample"], unreadable_version=r.get("unreadable_version"),
        )
        for r in rows
        if not needle or needle in " ".join(str(r[k]) for k in keys).lower()
    ]


def catalog_reindex(root: Path) -> int:
    """Rebuild the catalogue from the session folders; returns the number of sessions."""
    from benchlab.catalog.index import Catalog

    with Catalog.open(root) as catalog:
        return catalog.reindex()


def catalog_figures(root: Path) -> list[tuple[str, str, str, str]]:
    """Figures a trend can follow: ``(view, element, orientation, quantity)``."""
    from benchlab.catalog.index import Catalog

    if not root.is_dir():
        return []
    with Catalog.open(root) as catalog:
        return [k for k in catalog.figure_keys() if k[1]]


def catalog_trend(root: Path, figure: tuple[str, str, str, str]) -> list[TrendPoint]:
    """The figure across sessions, oldest first (:class:`benchlab.catalog.index.TrendPoint`)."""
    from benchlab.catalog.index import Catalog

    view, element, orientation, quantity = figure
    with Catalog.open(root) as catalog:
        return list(catalog.trend(view=view, element=element, orientation=orientation,
                                  quantity=quantity))
