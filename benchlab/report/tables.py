"""How each results table is shown: titles, columns, number formats (text and HTML)."""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from benchlab.analysis.bars.result import format_modulation

Column = tuple[str, str, str]  # (key, header, format: "", ".3f", ...)


@dataclass(frozen=True)
class TableView:
    title: str
    columns: tuple[Column, ...]


_S_T = tuple(
    col
    for o, short in (("sagittal", "S"), ("tangential", "T"))
    for col in ((f"{o}_dark", f"{short} dark", ".1f"), (f"{o}_bright", f"{short} bright", ".1f"),
                (f"{o}_modulation", f"{short} mod.", ".3f"))
)
#: The target's own contrast and the lens's share (measured / target) with its 1 sigma.
_SHARE = tuple(
    col
    for o, short in (("sagittal", "S"), ("tangential", "T"))
    for col in ((f"{o}_target_contrast", f"{short} target", ".3f"),
                (f"{o}_lens_share", f"{short} share", ".3f"),
                (f"{o}_lens_share_uncertainty", f"{short} share +-", ".3f"))
)
#: Aliasing per orientation (Table 4.12's spokes and rings image at different frequencies).
_ALIASED = (("sagittal_aliased", "S aliased", ""), ("tangential_aliased", "T aliased", ""))

#: Depth-of-field columns shared by the measured table and the simulator's truth.
_DEPTH: tuple[Column, ...] = (
    ("field_point", "field pt", ""), ("orientation", "orient.", ""),
    ("criterion", "criterion", ""), ("best_focus_mm", "best mm", ".2f"),
    ("near_mm", "near mm", ".2f"), ("far_mm", "far mm", ".2f"),
    ("image_height_mm", "height mm", ".3f"),
)

#: The MTF test's simulator truth: each bar set's target contrast, imaged contrast, lens share.
_MTF_TRUTH: tuple[Column, ...] = (
    ("view", "view", ""), ("pattern", "pattern", ""),
    ("image_lp_per_mm", "image lp/mm", ".2f"), ("target_contrast", "target", ".3f"),
    ("modulation", "imaged", ".3f"), ("lens_share", "lens share", ".3f"),
)

TABLE_VIEWS: dict[str, TableView] = {
    "table_4_11": TableView(
        "Table 4.11 - forward view (USAF 1951), modulation (Eq. 2.9); by default each found set "
        "read by the chart reading (knownbars: its geometry fixed by the found chart)",
        (("element", "element", ""), ("image_lp_per_mm", "image lp/mm", ".3f"), *_S_T,
         *_SHARE, *_ALIASED),
    ),
    "table_4_12": TableView(
        "Table 4.12 - radial view, modulation (Eq. 2.9); image lp/mm by Eq. 4.1 (rings, T), "
        "S lp/mm by object / image radius (spokes)",
        (("object_lp_per_mm", "object lp/mm", "g"), ("image_lp_per_mm", "image lp/mm", ".2f"),
         ("sagittal_image_lp_per_mm", "S lp/mm", ".2f"), *_S_T, *_SHARE, *_ALIASED),
    ),
    "table_4_13": TableView(
        "Tables 4.13-4.14 - image height and nearest simulated field point",
        (("view", "view", ""), ("test", "test", ""), ("roi_centroid_row", "row", ".1f"),
         ("roi_centroid_col", "col", ".1f"), ("image_height_px", "height px", ".2f"),
         ("image_height_mm", "height mm", ".3f"), ("nearest_field_deg", "field deg", "g"),
         ("nearest_field_height_mm", "field mm", ".2f")),
    ),
    "table_4_15": TableView(
        "Table 4.15 - averaged MTF (Eq. 4.2) against the Monte Carlo prediction; the verdict "
        "places the lens share (measured / target contrast) where it is known",
        (("view", "view", ""), ("mc_freq_lp_per_mm", "MC lp/mm", "g"),
         ("sagittal_freq_lp_per_mm", "S lp/mm", ".3f"),
         ("measured_freq_lp_per_mm", "T lp/mm", ".3f"),
         ("sagittal_modulation", "S", ".3f"), ("tangential_modulation", "T", ".3f"),
         ("averaged_modulation", "avg", ".3f"), ("averaged_lens_share", "avg share", ".3f"),
         ("averaged_lens_share_uncertainty", "+-", ".3f"),
         ("p90", "90%>", ".2f"), ("p50", "50%>", ".2f"),
         ("p10", "10%>", ".2f"), ("verdict", "verdict", "")),
    ),
    "table_4_16": TableView(
        "Table 4.16 - relative radiometry",
        (("position_mm", "position mm", "g"), ("simulated_mw_per_mm2", "sim. mW/mm2", ".3f"),
         ("measured_mean_gray", "mean gray", ".2f"),
         ("simulated_normalised", "sim. norm.", ".2f"),
         ("measured_normalised", "meas. norm.", ".2f"), ("difference", "difference", "+.2f"),
         ("mask_pixels", "mask px", ""), ("clipped_pixels", "clipped px", "")),
    ),
    # Camera characterisation (benchlab run characterise): measured, and the simulator's truth.
    **{name: TableView(title, (
        ("gain", "gain", "g"), ("bits", "bits", ""), ("system_gain_dn_per_e", "K DN/e-", ".5f"),
        ("read_noise_dn", "noise DN", ".3f"), ("read_noise_e", "noise e-", ".2f"),
        ("saturation_dn", "sat. DN", ".1f"), ("saturation_e", "sat. e-", ".0f"),
        ("linearity_error_min_pct", "LE min %", "+.3f"),
        ("linearity_error_max_pct", "LE max %", "+.3f"),
        ("dark_current_e_per_s", "dark e-/s", ".1f"), ("dsnu_dn", "DSNU DN", ".3f"),
        ("prnu_pct", "PRNU %", ".3f"),
        *((*_DEPTH, *_MTF_TRUTH) if name == "simulator_truth" else ())))
        for name, title in (
        ("characterisation", "Camera characterisation (EMVA 1288 photon transfer)"),
        ("simulator_truth", "Simulator truth (same keys)"))},
    # Depth of field (benchlab run depth).
    "depth_of_field": TableView(
        "Depth of field - best focus and DOF ends per field point (slanted edge or radial ROI), "
        "orientation "
        "and criterion, 95 % intervals; verdict against Table 4.1 (forward +-40 mm, radial "
        "+-5 mm)",
        (*_DEPTH[:4], ("best_focus_mm_ci95", "95 % CI", ""), _DEPTH[4],
         ("near_mm_ci95", "95 % CI", ""), _DEPTH[5], ("far_mm_ci95", "95 % CI", ""),
         ("peak_mtf", "peak", ".3f"), ("verdict", "verdict", "")),
    ),
    "depth_astigmatism": TableView(
        "Astigmatic focal difference (S minus T best focus) per field point",
        (("field_point", "field pt", ""), ("freq_lp_per_mm", "lp/mm", "g"),
         ("s_minus_t_mm", "S-T mm", "+.3f"), ("s_minus_t_mm_ci95", "95 % CI", ""),
         ("significant", "significant", "")),
    ),
    "depth_field_curvature": TableView(
        "Field curvature: best focus = b0 + k h^2 per orientation",
        (("orientation", "orient.", ""), ("freq_lp_per_mm", "lp/mm", "g"),
         ("curvature_mm_per_mm2", "k mm/mm2", "+.3f"),
         ("curvature_mm_per_mm2_ci95", "95 % CI", ""),
         ("best_focus_on_axis_mm", "b0 mm", ".3f"),
         ("best_focus_on_axis_mm_ci95", "95 % CI", "")),
    ),
}


#: Tables the terminal prints besides :data:`TABLE_VIEWS` (the report gives these their own
#: section, :mod:`benchlab.report.sfr`): the slanted edges and their cross-check with the bars,
#: so a run or a re-analysis says at once whether bars, edges and simulation agree.
TERMINAL_VIEWS: dict[str, TableView] = {
    **TABLE_VIEWS,
    "table_sfr_edges": TableView(
        "Slanted edges (ISO 12233 e-SFR) - MTF50 and MTF at Nyquist per edge",
        (("edge", "edge", ""), ("orientation", "orient.", ""),
         ("image_height_mm", "height mm", ".3f"), ("edge_angle_deg", "angle deg", ".2f"),
         ("mtf50_lp_per_mm", "MTF50 lp/mm", ".1f"), ("mtf50_sigma_lp_per_mm", "+-", ".1f"),
         ("mtf_nyquist", "MTF(Nyq)", ".3f"), ("estimator", "estimator", ""),
         ("status", "status", "")),
    ),
    "table_sfr_vs_bars": TableView(
        "Bars vs slanted edge (the set's predicted reading, else Coltman) vs simulated MTF, "
        "below Nyquist (agree: within 0.05)",
        (("element", "set", ""), ("orientation", "orient.", ""),
         ("image_lp_per_mm", "lp/mm", ".2f"), ("bar_modulation", "bar mod.", ".3f"),
         ("bar_modulation_predicted", "predicted", ".3f"),
         ("bar_mtf", "bars->MTF", ".3f"), ("edge_mtf", "edge MTF", ".3f"),
         ("edge_mtf_sigma", "+-", ".3f"), ("simulated_mtf", "simulated", ".3f"),
         ("verdict", "verdict", "")),
    ),
}


def cell(value: Any, fmt: str) -> str:
    """One table cell as text; missing numbers are shown as N/A, never as NaN."""
    if value is None:
        return "N/A"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if fmt and isinstance(value, int | float):
        return format(value, fmt)
    if isinstance(value, list):  # an interval: [low, high], N/A where an end is not known
        if all(v is None for v in value):
            return "N/A"
        return "[" + ", ".join("N/A" if v is None else f"{v:g}" if isinstance(v, float)
                               else str(v) for v in value) + "]"
    return str(value)


def is_lower_bound(row: Mapping[str, Any], key: str) -> bool:
    """Whether the row's ``key`` (``modulation``, ``<orient>_modulation`` or
    ``averaged_modulation``) was stored as a lower bound (a clipped reading): its flag is the
    key with ``_lower_bound`` for ``_modulation`` (``lower_bound`` alone for ``modulation``),
    or, for Table 4.15's average, ``averaged_modulation_lower_bound``."""
    if key == "modulation":
        return row.get("lower_bound") is True
    if key == "averaged_modulation":
        return row.get("averaged_modulation_lower_bound") is True
    if key.endswith("_modulation"):
        return row.get(key.removesuffix("_modulation") + "_lower_bound") is True
    return False


#: A bar-set cell with no reading (modulation None, not resolved): the ROI could not give one
#: (less than one bar period, a set the chart finder rejected, ...); its warnings say why.
NOT_MEASURABLE = "not measurable"


#: Characterisation figures that can be flagged as not resolved: key -> the row's
#: ``<quantity>_unresolved`` reason (clipped black level, quantisation, saturated stack).
_CHARACTERISE_QUANTITY = {"read_noise_dn": "read_noise", "read_noise_e": "read_noise",
                          "dark_current_e_per_s": "dark_current", "dsnu_dn": "dsnu",
                          "prnu_pct": "prnu"}


def row_cell(row: Mapping[str, Any], key: str, fmt: str) -> str:
    """One cell of a row: a modulation whose reading is aliased, not resolved or not
    measurable is said so, never shown as the 0 stored for it; a characterisation figure the
    frames do not resolve reads ``n/a (unresolved: why)``."""
    quantity = _CHARACTERISE_QUANTITY.get(key)
    if quantity is not None and row.get(f"{quantity}_unresolved"):
        return f"n/a (unresolved: {row[f'{quantity}_unresolved']})"
    if key.endswith("_aliased") and key not in row:  # older rows: one flag per row
        return cell(row.get("aliased"), fmt)
    if key.endswith("_modulation"):
        orient = key.removesuffix("_modulation")
        # Rows say it per orientation (older Table 4.11 rows once: ``aliased``).
        if row.get(f"{orient}_aliased", row.get("aliased")) is True:
            return "aliased"
        if row.get(f"{orient}_resolved") is False:
            return NOT_MEASURABLE if row.get(key) is None else "not resolved"
    if is_lower_bound(row, key) and isinstance(row.get(key), int | float):
        return format_modulation(float(row[key]), lower_bound=True, fmt=fmt or ".3f")
    if row.get(key) is None and row.get("clipped_pixels"):
        return "clipped"  # a radiometry row whose mean is only a lower bound: no number
    return cell(row.get(key), fmt)


def _shown(rows: Sequence[Mapping[str, Any]], key: str) -> bool:
    """False for a column no row has and :func:`row_cell` cannot derive (all N/A): one view
    serves tables of several procedures with different keys (``simulator_truth``)."""
    if not rows or any(key in r for r in rows):
        return True
    derived = {"aliased", "clipped_pixels"}
    quantity = _CHARACTERISE_QUANTITY.get(key)
    if quantity is not None:
        derived.add(f"{quantity}_unresolved")
    if key.endswith("_modulation"):
        orient = key.removesuffix("_modulation")
        derived |= {f"{orient}_aliased", f"{orient}_resolved"}
    return any(k in r for r in rows for k in derived)


def format_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[Column],
                 width: int | None = None) -> str:
    """A plain-text table with aligned columns (columns no row has are left out), one line
    per row; with ``width`` (a terminal's, :func:`~benchlab.report.text_table.terminal_width`)
    folded to fit it: repeated reasons as footnotes, blocks of columns led by the row's name
    (:func:`~benchlab.report.text_table.fit_table`)."""
    from benchlab.report.text_table import fit_table, one_line_table

    columns = [c for c in columns if _shown(rows, c[0])]
    header = [h for _, h, _ in columns]
    body = [[row_cell(r, k, f) for k, _, f in columns] for r in rows]
    if width is None:
        return one_line_table(header, body)
    return fit_table(header, body, width=width)


def html_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[Column]) -> str:
    """An HTML table (escaped; columns no row has are left out)."""
    columns = [c for c in columns if _shown(rows, c[0])]
    head = "".join(f"<th>{html.escape(h)}</th>" for _, h, _ in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(row_cell(r, k, f))}</td>" for k, _, f in columns)
        + "</tr>"
        for r in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
