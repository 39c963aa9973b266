"""Characterisation analysis of a session's saved frames (offline, re-runnable).

Tables: ``characterisation`` (one row per gain and bit depth, the issue's keys),
``photon_transfer`` (one row per exposure step: the curves the report plots), and on the simulated
bench ``simulator_truth`` (the same keys, from the sensor truth the run used).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from benchlab.analysis.camera.photon_transfer import (
    SpatialResult,
    SweepPoint,
    fraction_at_code,
    msb_aligned,
    native_codes,
    pair_statistics,
    photon_transfer,
    response_curve,
    spatial_nonuniformity,
)
from benchlab.drivers.mightex.characteristics import SensorCharacteristics
from benchlab.protocols.characterise.params import CharacteriseParams
from benchlab.protocols.characterise.truth import truth_for
from benchlab.protocols.engine import frames_of

_SWEEP_NAME = re.compile(r"^e(\d{3})-(lit|dark)-([ab])$")
#: Journal event recording the simulated sensor truth at set-up.
TRUTH_EVENT = "simulator_truth"
#: Journal event of an LED current sweep: the controller's step and the currents set.
CURRENTS_EVENT = "sweep_currents"


def config_step_id(gain: float, bits: int) -> str:
    """Step id of one configuration's sweep, e.g. ``sweep-g1-b12``."""
    return f"sweep-g{gain:g}-b{bits}"


def sweep_statistics(
    frames: Mapping[str, npt.NDArray[Any]], metas: Mapping[str, Mapping[str, Any]], bits: int,
) -> tuple[list[SweepPoint], SpatialResult, list[float], bool]:
    """Per-step statistics of one configuration's frames (defect pixels excluded), the
    spatial result, the exposures and whether the codes were MSB-aligned."""
    aligned = msb_aligned(list(frames.values()), bits)

    def codes(name: str) -> npt.NDArray[np.float64]:
        return native_codes(frames[name], bits, aligned)

    lit = np.stack([codes(n) for n in sorted(frames) if n.startswith("stack-lit-")])
    dark = np.stack([codes(n) for n in sorted(frames) if n.startswith("stack-dark-")])
    spatial, defects = spatial_nonuniformity(lit, dark, top_code_dn=float((1 << bits) - 1))
    valid = ~defects
    steps: dict[int, set[str]] = {}
    for name in frames:
        m = _SWEEP_NAME.match(name)
        if m:
            steps.setdefault(int(m.group(1)), set()).add(name)
    points: list[SweepPoint] = []
    exposures: list[float] = []
    for i in sorted(steps):
        if len(steps[i]) != 4:
            raise ValueError(f"sweep step e{i:03d} has {len(steps[i])} of its 4 frames")
        e = f"e{i:03d}"
        meta = metas[f"{e}-lit-a"]
        t = float(meta["exposure_ms"])
        mean, var = pair_statistics(codes(f"{e}-lit-a"), codes(f"{e}-lit-b"), valid)
        dark_a, dark_b = codes(f"{e}-dark-a"), codes(f"{e}-dark-b")
        dmean, dvar = pair_statistics(dark_a, dark_b, valid)
        # Zero codes of the dark pair: a black level clipped at 0 (EMVA 1288: <= 0.5 %).
        zeros = fraction_at_code(np.stack([dark_a, dark_b]), 0.0, valid)
        points.append(SweepPoint(t, mean, var, dmean, dvar, irradiance=_current_ma(meta),
                                 dark_zero_fraction=zeros))
        exposures.append(t)
    return points, spatial, exposures, aligned


def _current_ma(meta: Mapping[str, Any]) -> float:
    """Relative irradiance of a lit frame: the LED current the simulated LED drove (bench
    state), else the one the controller reported after it was set, else the requested one."""
    state = (meta.get("bench") or {}).get("led_current_ma")
    channel = str(meta.get("led_channel", 1))
    if isinstance(state, Mapping) and state.get(channel) is not None:
        return float(state[channel])
    return float(meta.get("led_current_set_ma") or meta.get("led_current_ma") or 1.0)


def _le_columns(le: Any) -> dict[str, float | None]:
    """Linearity error min / max as separate columns (CSV readers, table views)."""
    lo, hi = le if le is not None else (None, None)
    return {"linearity_error_min_pct": lo, "linearity_error_max_pct": hi}


def _frame_metas(session: Any, step_id: str) -> dict[str, dict[str, Any]]:
    """Per-frame acquisition metadata (exposure) from the TIFF descriptions."""
    from benchlab.storage import load_frame_tiff

    return {name: load_frame_tiff(path)[1] for name, path in session.step_frames(step_id).items()
            if name.startswith("e") and name.endswith("-lit-a")}


def simulator_truth_record(session: Any) -> Mapping[str, Any] | None:
    """The sensor truth journalled at set-up on the simulated bench (None on the real bench)."""
    found = None
    for ev in session.events():
        if ev.get("kind") == TRUTH_EVENT:
            found = ev
    return found


def analyze_characterise(
    session: Any, params: CharacteriseParams
) -> tuple[dict[str, list[dict[str, Any]]], dict[str, Any]]:
    """Tables and summary of a characterisation session (see the module docstring)."""
    sim = simulator_truth_record(session)
    truth = SensorCharacteristics.from_mapping(sim["truth"]) if sim is not None else None
    currents = {ev.get("step"): ev for ev in session.events()
                if ev.get("kind") == CURRENTS_EVENT}  # the last per step (a resume repeats it)
    rows: list[dict[str, Any]] = []
    curve_rows: list[dict[str, Any]] = []
    truth_rows: list[dict[str, Any]] = []
    per_config: list[dict[str, Any]] = []
    curves: list[dict[str, Any]] = []
    for gain, bits in params.configs:
        sid = config_step_id(gain, bits)
        frames = frames_of(session, [sid])[sid]
        metas = _frame_metas(session, sid)
        points, spatial, exposures, aligned = sweep_statistics(frames, metas, bits)
        result = photon_transfer(points, spatial=spatial)
        measured = {**result.measured(), "msb_aligned": aligned,
                    **_le_columns(result.linearity_error_pct)}
        row = {"gain": gain, "bits": bits, **measured,
               "warnings": "; ".join(result.warnings)}
        rows.append(row)
        entry: dict[str, Any] = {"gain": gain, "bits": bits, "measured": measured,
                                 "warnings": list(result.warnings)}
        if sid in currents:  # an LED current sweep: the currents the controller was set to
            entry["current_step_ma"] = currents[sid]["current_step_ma"]
            entry["currents_set_ma"] = currents[sid]["currents_ma"]
        for i, pt in enumerate(sorted(points, key=lambda q: q.exposure_quantity)):
            curve_rows.append({
                "gain": gain, "bits": bits, "exposure_ms": pt.exposure_ms,
                "mean_dn": pt.mean_dn, "dark_mean_dn": pt.dark_mean_dn,
                "variance_dn2": pt.variance_dn2, "dark_variance_dn2": pt.dark_variance_dn2,
                "signal_dn": pt.signal_dn, "signal_variance_dn2": pt.signal_variance_dn2,
                "in_k_fit": i in result.k_fit_indices,
                "in_linearity_range": i in result.linearity_indices,
                "linearity_deviation_pct": result.deviation_pct[i],
                "saturation_step": i == result.saturation_index,
            })
        try:
            curve = response_curve(points, result, gain=gain, bits=bits,
                                   reference_range=params.reference_range)
            curves.append({"gain": gain, "bits": bits, "black_level_dn": curve.black_level_dn,
                           "measured_dn": list(curve.measured_dn),
                           "linear_dn": list(curve.linear_dn)})
        except ValueError as exc:
            entry["warnings"].append(f"no response curve: {exc}")
        if truth is not None and sim is not None:
            per_ma = float(sim.get("flat_e_per_ms_per_ma", 0.0))
            t_row = truth_for(truth, gain=gain, bits=bits, width=params.width,
                              height=params.height, exposures_ms=exposures,
                              light_e=[per_ma * p.exposure_quantity for p in points])
            t_row.update(_le_columns(t_row["linearity_error_pct"]))
            truth_rows.append({"gain": gain, "bits": bits, **t_row})
            entry["simulator_truth"] = t_row
        per_config.append(entry)
    tables: dict[str, list[dict[str, Any]]] = {"characterisation": rows,
                                               "photon_transfer": curve_rows}
    summary: dict[str, Any] = {
        "procedure": "characterise", "configs": per_config, "response_curves": curves,
        "width": params.width, "height": params.height,
        "led_current_ma": params.led_current_ma,
    }
    if truth_rows:
        tables["simulator_truth"] = truth_rows
        summary["simulator"] = {"truth": truth.to_dict() if truth else None,
                                "flat_e_per_ms_per_ma": sim.get("flat_e_per_ms_per_ma")
                                if sim else None}
    return tables, summary
