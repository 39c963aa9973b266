"""``benchlab benchmark viewsynth``: view synthesis against the flat truth of simulated scenes.

The card and bar scenes of the simulated bench are imaged through the shipped ray-trace table,
exposed like the camera does (Poisson + read noise, 8-bit), unwrapped, and measured:
straightness and spacing of the card's printed grid, the period of 0.5 lp/mm bars in both roll
directions, the table's viewpoint spread, map-building and remap times and the ring
self-calibration's distance from the table.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.views.calibrate import calibrate_from_rings, compare_tables
from benchlab.analysis.views.metrics import (
    LineFit,
    dominant_period_px,
    find_line,
    scale_error,
)
from benchlab.analysis.views.raytrace import (
    REFERENCE_OBJECT_RADIUS_MM,
    RayTraceTable,
    read_raytrace_table,
)
from benchlab.analysis.views.synthesis import (
    ViewMaps,
    apply_maps,
    fov_centre_of_frame,
    perspective_maps,
    unwrap_maps,
    viewpoint,
)
from benchlab.drivers.sensor import DN12_PER_E, READ_NOISE_E, AcquisitionState

PX_PER_MM = 20.0
H, W = 1024, 1280


@dataclass(frozen=True)
class Figure:
    """One line of the benchmark table."""

    name: str
    value: float
    unit: str
    target: str
    ok: bool | None


def expose_dn8(rate: npt.NDArray[np.float64], seed: int, exposure_ms: float = 300.0,
               gain: float = 1.0) -> npt.NDArray[np.uint8]:
    """An 8-bit frame of an electron-rate image: Poisson shot noise, read noise, clipping."""
    rng = np.random.default_rng(seed)
    electrons = rng.poisson(np.asarray(rate) * exposure_ms) + rng.normal(0, READ_NOISE_E,
                                                                         rate.shape)
    dn8 = electrons * DN12_PER_E * gain / 16.0
    return np.asarray(np.clip(np.round(dn8), 0, 255), dtype=np.uint8)


def _render(scene: Any) -> npt.NDArray[np.float64]:
    return np.asarray(scene(AcquisitionState(300.0, 1.0, 8, W, H, 0.0, 0, {})))


def card_figures(table: RayTraceTable, object_radius_mm: float = REFERENCE_OBJECT_RADIUS_MM,
                 seed: int = 3) -> tuple[list[LineFit], list[LineFit], dict[str, float]]:
    """Unwrap the simulated card at its own depth; find its grid lines (both directions)."""
    from benchlab.scenes.card import CardScene

    card = CardScene(table=table, object_radius_mm=object_radius_mm)
    frame = expose_dn8(_render(card), seed)
    centre, _ = fov_centre_of_frame(frame)
    maps = unwrap_maps(table, frame.shape, centre, object_radius_mm=card.object_radius_mm,
                       px_per_mm=PX_PER_MM)
    view = apply_maps(frame, maps)
    r = card.object_radius_mm
    xs, ys = card.grid_lines_mm()
    phi, _ = card.card_to_object(xs, np.zeros_like(xs))
    cols = np.mod(phi, 2 * np.pi) * r * PX_PER_MM
    _, z = card.card_to_object(np.zeros_like(ys), ys)
    rows = (maps.meta["z_top_mm"] - z) * PX_PER_MM
    # Leave out the samples where a crossing line (within 1 mm) darkens the window.
    row_idx, col_idx = np.arange(maps.shape[0]), np.arange(maps.shape[1])
    near_rows = np.asarray((np.abs(row_idx[:, None] - rows[None, :]) <= PX_PER_MM).any(axis=1))
    near_cols = np.asarray((np.abs(col_idx[:, None] - cols[None, :]) <= PX_PER_MM).any(axis=1))
    half = 0.5 * PX_PER_MM
    along = [find_line(view, maps.valid, c, axis=1, half_window_px=half, skip=near_rows)
             for c in cols]
    around = [find_line(view, maps.valid, rw, axis=0, half_window_px=half, skip=near_cols)
              for rw in rows]
    centre_err = math.hypot(centre[0] - card.circles.centre_rc[0],
                            centre[1] - card.circles.centre_rc[1])
    return ([ln for ln in along if ln is not None], [ln for ln in around if ln is not None],
            {"centre_error_px": centre_err})


def bar_period_px(table: RayTraceTable, orientation: str, seed: int) -> float:
    """Period of the unwrapped 0.5 lp/mm pattern at 20 px/mm (truth: 40 px)."""
    from benchlab.scenes.radial import RadialScene

    scene = RadialScene(0.5, orientation, table=table)  # type: ignore[arg-type]
    frame = expose_dn8(_render(scene), seed)
    centre, _ = fov_centre_of_frame(frame)
    ref = math.degrees(scene._theta_ref())
    maps = unwrap_maps(table, frame.shape, centre, object_radius_mm=scene.object_radius_mm,
                       azimuth_deg=(ref - 60.0, ref + 60.0), px_per_mm=PX_PER_MM)
    view = apply_maps(frame, maps).astype(np.float64)
    # The rows wholly inside the frame and the lit annulus (smoothed over two periods, so
    # the dark bars do not count as unlit), less 1 mm off the soft annulus edges.
    from scipy import ndimage

    level = ndimage.uniform_filter1d(view.mean(axis=1), size=int(4 * PX_PER_MM))
    ok = np.flatnonzero(maps.valid.all(axis=1) & (level > 0.5 * level.max()))
    body = np.arange(ok.min() + int(PX_PER_MM), ok.max() - int(PX_PER_MM))
    if orientation == "sagittal":
        return dominant_period_px(view[body].mean(axis=0))
    return dominant_period_px(view[body].mean(axis=1))


def _timed(fn: Any, repeats: int) -> tuple[float, float]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), statistics.median(times)


def run_benchmark(quick: bool = False) -> tuple[list[Figure], dict[str, Any]]:
    """Every figure of the issue, with its target; also the raw numbers for ``--json``."""
    table = read_raytrace_table(None)
    figs: list[Figure] = []
    vp = viewpoint(table)
    outside = vp.spread_um[(vp.rho_mm < vp.operational_mm[0]) | (vp.rho_mm > vp.operational_mm[1])]
    figs += [
        Figure("effective viewpoint z", vp.effective_viewpoint_z_mm, "mm", "thesis -6.4", None),
        Figure("SVP spread, operational radii", vp.svp_spread_um, "um", "<= 20 (thesis)",
               vp.svp_spread_um <= 20.0),
        Figure("viewpoint spread, outside them (max)",
               float(outside.max()) if outside.size else float("nan"), "um", "reported", None),
    ]
    for radius in (REFERENCE_OBJECT_RADIUS_MM, 16.88):
        along, around, extra = card_figures(table, radius)
        rms_all = [ln.rms_px for ln in along + around]
        tag = f"card at {radius:g} mm"
        figs += [
            Figure(f"{tag}: lines found along the axis", float(len(along)), "", "in view", None),
            Figure(f"{tag}: lines found around the axis", float(len(around)), "", "in view", None),
            Figure(f"{tag}: straightness, worst line RMS", max(rms_all), "px", "<= 0.5",
                   max(rms_all) <= 0.5),
            Figure(f"{tag}: straightness, median line RMS", statistics.median(rms_all), "px",
                   "", None),
            Figure(f"{tag}: scale error around (arc)", 100 * scale_error(along), "%",
                   "|.| <= 1", abs(scale_error(along)) <= 0.01),
            Figure(f"{tag}: scale error along the axis", 100 * scale_error(around), "%",
                   "|.| <= 1", abs(scale_error(around)) <= 0.01),
            Figure(f"{tag}: centre from FOV mask, error", extra["centre_error_px"], "px", "",
                   None),
        ]
    for k, orient in enumerate(("sagittal", "tangential")):
        p = bar_period_px(table, orient, seed=10 + k)
        figs.append(Figure(f"0.5 lp/mm {orient}: period at 20 px/mm", p, "px", "40 +- 2 %",
                           abs(p / 40.0 - 1.0) <= 0.02))
    shape = (H, W)
    centre = (560.5, 646.0)
    repeats = 3 if quick else 7
    build = _timed(lambda: unwrap_maps(table, shape, centre,
                                       object_radius_mm=REFERENCE_OBJECT_RADIUS_MM,
                                       px_per_mm=PX_PER_MM), repeats)
    maps: ViewMaps = unwrap_maps(table, shape, centre, object_radius_mm=REFERENCE_OBJECT_RADIUS_MM,
                                 px_per_mm=PX_PER_MM)
    frame = np.random.default_rng(0).integers(0, 255, shape, dtype=np.uint8)
    apply_maps(frame, maps)  # warm-up
    remap = _timed(lambda: apply_maps(frame, maps), 5 * repeats)
    persp = _timed(lambda: perspective_maps(table, shape, centre,
                                            object_radius_mm=REFERENCE_OBJECT_RADIUS_MM,
                                            yaw_deg=-40, pitch_deg=45, fov_deg=90,
                                            size_wh=(640, 480)), repeats)
    figs += [
        Figure(f"build unwrap maps {maps.shape[1]}x{maps.shape[0]} (min)", build[0], "s",
               "<= 1", build[0] <= 1.0),
        Figure("build unwrap maps (median)", build[1], "s", "", None),
        Figure("remap full circle, bilinear (min)", 1e3 * remap[0], "ms", "<= 10",
               1e3 * remap[0] <= 10.0),
        Figure("remap full circle, bilinear (median)", 1e3 * remap[1], "ms", "", None),
        Figure("build perspective maps 640x480 (min)", persp[0], "s", "<= 1", persp[0] <= 1.0),
    ]
    from benchlab.scenes.radial import RadialScene

    rings = expose_dn8(_render(RadialScene(1.0, "tangential", table=table)), seed=20)
    ring_centre, _ = fov_centre_of_frame(rings)
    cal = calibrate_from_rings(rings, object_lp_per_mm=1.0,
                               object_radius_mm=REFERENCE_OBJECT_RADIUS_MM, centre_rc=ring_centre)
    cmp = compare_tables(cal.table, table, REFERENCE_OBJECT_RADIUS_MM)
    figs += [
        Figure("self-calibration (1 lp/mm rings): rings", float(cal.ring_radius_mm.size), "",
               "", None),
        Figure("self-calibration vs table, RMS axial", cmp["rms_axial_um"], "um", "reported",
               None),
        Figure("self-calibration vs table, RMS image radius", cmp["rms_image_radius_um"], "um",
               "reported", None),
        Figure("self-calibration magnification error", cmp["magnification_error_pct"], "%",
               "reported", None),
    ]
    raw = {"viewpoint": {"effective_z_mm": vp.effective_viewpoint_z_mm,
                         "svp_spread_um": vp.svp_spread_um},
           "calibration": cmp}
    return figs, raw


def format_figures(figs: list[Figure]) -> str:
    """The benchmark as a fixed-width table."""
    lines = [f"{'figure':<48} {'value':>10} {'unit':<5} {'target':<16} ok"]
    for f in figs:
        ok = "" if f.ok is None else ("yes" if f.ok else "NO")
        lines.append(f"{f.name:<48} {f.value:>10.5g} {f.unit:<5} {f.target:<16} {ok}")
    return "\n".join(lines)
