"""The results tables a spec may limit: every table the procedures write, with its columns
and what each holds (docs/formats/results.md lists them in words).

A spec's ``table``, ``column``, ``where`` keys and values, ``uncertainty`` and ``ci95`` are
checked against this before anything is read or stored (:func:`benchlab.acceptance.spec.
parse_spec`): a misspelt name or a value of the wrong type is a usage error, not an
"indeterminate" verdict stored in the sessions. ``tests/acceptance/test_results_schema.py``
keeps it equal to what simulated runs of every procedure write.

Keys are the tables' file names (``forward_view_modulation``); a spec may also use the thesis
labels (``table_4_11``, :data:`benchlab.session.RESULT_FILE_STEMS`). ``None``: rows whose
columns vary with what was found (the depth chart's bar sets, the viewpoint rows) - only the
table's name is checked.
"""

from __future__ import annotations

#: What a column holds: a number (int or float; a limit's ``column`` must be one), text,
#: a boolean, or a list (an ROI, an interval).
NUMBER, TEXT, BOOL, LIST = "number", "text", "bool", "list"


def _columns(number: tuple[str, ...] = (), text: tuple[str, ...] = (),
             bool: tuple[str, ...] = (), list: tuple[str, ...] = ()  # noqa: A002
             ) -> dict[str, str]:
    kinds = {NUMBER: number, TEXT: text, BOOL: bool, LIST: list}
    return {name: kind for kind, names in kinds.items() for name in names}


#: The MTF test's target contrast and the lens's share (measured / target), each with its
#: 1-sigma uncertainty, beside each orientation's reading (Tables 4.11 and 4.12).
_LENS_SHARE = tuple(f"{o}_{k}" for o in ("sagittal", "tangential") for k in (
    "target_contrast", "target_contrast_uncertainty", "lens_share", "lens_share_uncertainty"))

#: table file name -> column -> kind (None: the columns vary; only the name is checked).
RESULTS_SCHEMA: dict[str, dict[str, str] | None] = {
    "forward_view_modulation": _columns(
        number=("object_lp_per_mm", "image_lp_per_mm", "sagittal_dark",
            "sagittal_bright", "sagittal_modulation", "sagittal_uncertainty",
            "sagittal_image_lp_per_mm", "tangential_dark", "tangential_bright",
            "tangential_modulation", "tangential_uncertainty",
            "tangential_image_lp_per_mm", *_LENS_SHARE),
        text=("element", "sagittal_warnings", "sagittal_estimator",
            "tangential_warnings", "tangential_estimator", "target_contrast_source"),
        bool=("aliased", "sagittal_resolved", "sagittal_aliased", "tangential_resolved",
            "tangential_aliased"),
        list=("sagittal_roi", "tangential_roi"),
    ),
    "radial_view_modulation": _columns(
        number=("object_lp_per_mm", "image_lp_per_mm", "sagittal_image_lp_per_mm",
            "tangential_image_lp_per_mm", "sagittal_dark", "sagittal_bright",
            "sagittal_modulation", "sagittal_uncertainty", "tangential_dark",
            "tangential_bright", "tangential_modulation", "tangential_uncertainty",
            *_LENS_SHARE),
        text=("sagittal_warnings", "tangential_warnings", "target_contrast_source"),
        bool=("aliased", "sagittal_aliased", "tangential_aliased", "sagittal_resolved",
            "tangential_resolved"),
    ),
    "image_heights_field_points": _columns(
        number=("roi_centroid_row", "roi_centroid_col", "image_height_px",
            "image_height_mm", "nearest_field_deg", "nearest_field_height_mm"),
        text=("view", "test"),
    ),
    "averaged_mtf_vs_monte_carlo": _columns(
        number=("mc_freq_lp_per_mm", "measured_freq_lp_per_mm", "sagittal_modulation",
            "tangential_modulation", "averaged_modulation", "p90", "p80", "p50", "p20",
            "p10", "sagittal_freq_lp_per_mm", "tangential_freq_lp_per_mm",
            "sagittal_lens_share", "tangential_lens_share", "averaged_lens_share",
            "averaged_lens_share_uncertainty"),
        text=("view", "verdict", "verdict_basis"),
        bool=("sagittal_resolved", "tangential_resolved"),
    ),
    "table_sfr_edges": _columns(
        number=("image_height_mm", "nearest_field_deg", "edge_angle_deg",
            "mtf50_cycles_per_px", "mtf50_lp_per_mm", "mtf50_sigma_lp_per_mm",
            "mtf_nyquist", "dark", "bright", "contrast"),
        text=("edge", "orientation", "status", "estimator", "warnings"),
        list=("roi",),
    ),
    "table_sfr_curves": _columns(
        number=("freq_lp_per_mm", "freq_cycles_per_px", "mtf", "mtf_sigma"),
        text=("edge", "orientation"),
    ),
    "table_sfr_vs_bars": _columns(
        number=("image_lp_per_mm", "image_height_mm", "bar_modulation",
            "bar_modulation_predicted", "object_modulation", "ctf", "bar_mtf",
            "bar_mtf_coltman", "edge_mtf", "edge_mtf_sigma", "simulated_mtf"),
        text=("element", "orientation", "bars_vs_edge_basis", "contrast_from_edge",
            "coltman_method", "edge", "verdict"),
    ),
    "relative_radiometry": _columns(
        number=("position_mm", "simulated_mw_per_mm2", "measured_mean_gray",
            "simulated_normalised", "measured_normalised", "difference", "mask_pixels",
            "clipped_pixels"),
        text=("note",),
    ),
    "characterisation": _columns(
        number=("gain", "bits", "system_gain_dn_per_e",
            "system_gain_uncertainty_dn_per_e", "read_noise_dn", "read_noise_e",
            "saturation_dn", "saturation_e", "dark_current_e_per_s", "dsnu_dn",
            "prnu_pct", "dark_current_uncertainty_e_per_s", "dsnu_all_pixels_dn",
            "defect_pixels", "black_level_dn", "dark_zero_pct",
            "linearity_error_min_pct", "linearity_error_max_pct"),
        text=("read_noise_unresolved", "dark_current_unresolved", "dsnu_unresolved",
            "prnu_unresolved", "warnings"),
        bool=("read_noise_resolved", "saturation_reached", "dark_level_clipped",
            "dark_current_resolved", "dsnu_resolved", "prnu_resolved", "msb_aligned"),
        list=("linearity_error_pct",),
    ),
    "photon_transfer": _columns(
        number=("gain", "bits", "exposure_ms", "mean_dn", "dark_mean_dn",
            "variance_dn2", "dark_variance_dn2", "signal_dn", "signal_variance_dn2",
            "linearity_deviation_pct"),
        bool=("in_k_fit", "in_linearity_range", "saturation_step"),
    ),
    "simulator_truth": _columns(
        number=("gain", "bits", "system_gain_dn_per_e", "read_noise_e", "read_noise_dn",
            "saturation_dn", "saturation_e", "saturation_clip_dn",
            "dark_current_e_per_s", "dsnu_dn", "prnu_pct", "hot_pixels",
            "linearity_error_min_pct", "linearity_error_max_pct", "freq_lp_per_mm",
            "threshold", "image_height_mm", "best_focus_mm", "near_mm", "far_mm",
            "dof_mm", "value"),
        text=("view", "field_point", "orientation", "criterion", "pattern", "table", "key"),
        list=("linearity_error_pct",),
    ),
    "depth_of_field": _columns(
        number=("freq_lp_per_mm", "threshold", "image_height_mm", "best_focus_mm",
            "near_mm", "far_mm", "dof_mm", "peak_mtf", "n_points", "reading_threshold",
            "target_contrast", "target_contrast_uncertainty", "peak_lens_share"),
        text=("view", "field_point", "orientation", "criterion", "verdict", "note",
            "pattern", "threshold_on", "target_contrast_source"),
        list=("best_focus_mm_ci95", "near_mm_ci95", "far_mm_ci95"),
    ),
    "depth_curves": _columns(
        number=("distance_mm", "segment", "freq_lp_per_mm", "mtf", "mtf_sigma",
            "mtf50_lp_per_mm", "modulation", "fundamental", "modulation_sigma", "lens_share"),
        text=("edge", "orientation", "status", "pattern", "field_point"),
    ),
    "depth_field_curvature": _columns(
        number=("freq_lp_per_mm", "curvature_mm_per_mm2", "best_focus_on_axis_mm",
            "field_points"),
        text=("view", "orientation", "pattern"),
        list=("curvature_mm_per_mm2_ci95", "best_focus_on_axis_mm_ci95"),
    ),
    "depth_astigmatism": _columns(
        number=("freq_lp_per_mm", "s_minus_t_mm", "image_height_mm"),
        text=("view", "field_point"),
        bool=("significant",),
        list=("s_minus_t_mm_ci95",),
    ),
    "depth_overlap": _columns(
        number=("distance_mm", "freq_lp_per_mm", "segment_a", "mtf_a", "segment_b",
            "mtf_b", "difference", "z_score"),
        text=("edge",),
    ),
    "depth_chart": None,
    "field_of_view": _columns(
        number=("value",),
        text=("quantity", "unit", "design", "verdict"),
        list=("value_ci95",),
    ),
    "image_height_mapping": _columns(
        number=("field_angle_deg", "axial_position_mm", "image_height_mm",
            "design_image_height_mm", "difference_mm"),
        text=("view", "verdict"),
        list=("image_height_mm_ci95",),
    ),
    "distortion": _columns(
        number=("field_angle_deg", "image_height_mm", "rectilinear_pct", "equidistant_pct"),
        list=("rectilinear_pct_ci95", "equidistant_pct_ci95"),
    ),
    "fov_dots": _columns(
        number=("distance_mm", "dots_found", "dots_identified", "rms_px"),
        text=("note",),
    ),
    "radial_rings": _columns(
        number=("position_mm", "rings_found", "rings_used", "rms_um"),
        text=("note",),
    ),
    "unwrap": _columns(
        number=("rows", "cols", "valid_fraction"),
        text=("step_id", "frame", "file"),
    ),
    "viewpoint": None,
}

#: The MTF test's simulator truth (simulated bench only): per bar set, the target's own
#: contrast, the noise-free imaged contrast and the lens's share (kept apart from the other
#: procedures' truth columns above).
_mtf_truth = RESULTS_SCHEMA["simulator_truth"]
assert _mtf_truth is not None
_mtf_truth.update(_columns(number=("image_lp_per_mm", "target_contrast", "modulation",
                                   "lens_share")))
