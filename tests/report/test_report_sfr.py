"""The report's slanted-edge section: what it states about the reference conversion comes from
the session's own table."""

from __future__ import annotations

from typing import Any

from benchlab.report.sfr import CHECK_COLUMNS, render_sfr_section


def _check(edge_mtf: float, coltman: float, element: str) -> dict[str, Any]:
    return {"element": element, "orientation": "sagittal", "image_lp_per_mm": 40.0,
            "bar_modulation": 0.5, "object_modulation": 0.8, "ctf": 0.6, "bar_mtf": edge_mtf,
            "bar_mtf_coltman": coltman, "coltman_method": "pi/4", "edge": "E0R",
            "edge_mtf": edge_mtf, "edge_mtf_sigma": 0.01, "simulated_mtf": edge_mtf,
            "verdict": "agree"}


def _tables(checks: list[dict[str, Any]]) -> dict[str, Any]:
    edge = {"edge": "E0R", "orientation": "sagittal", "image_height_mm": 0.1,
            "nearest_field_deg": 0, "edge_angle_deg": 5.0, "mtf50_lp_per_mm": 60.0,
            "mtf50_sigma_lp_per_mm": 1.0, "mtf_nyquist": 0.1, "contrast": 0.8,
            "estimator": "model-free", "status": "ok", "warnings": ""}
    return {"table_sfr_edges": [edge], "table_sfr_curves": [], "table_sfr_vs_bars": checks}


def test_nyquist_cutoff_gap_is_the_largest_in_the_table_shown() -> None:
    html = render_sfr_section(_tables([_check(0.60, 0.62, "G1E1"), _check(0.40, 0.37, "G1E2"),
                                       _check(0.30, 0.31, "G1E3")]), [])
    assert "as the table's reference column, it is up to 0.030 off the edge MTF in the table " \
           "below)" in html
    assert "0.05-0.08" not in html


def test_no_row_to_compare_states_no_number() -> None:
    html = render_sfr_section(_tables([]), [])
    assert "no row here to compare it on" in html and "0.05-0.08" not in html


def test_the_method_column_says_what_it_holds() -> None:
    headers = {key: head for key, head, _ in CHECK_COLUMNS}
    assert headers["coltman_method"] == "Nyq. method"
    html = render_sfr_section(_tables([_check(0.6, 0.62, "G1E1")]), [])
    assert ">Nyq. method<" in html


def test_predicted_reading_column_and_verdicts_with_their_basis() -> None:
    headers = {key: head for key, head, _ in CHECK_COLUMNS}
    assert headers["bar_modulation_predicted"] == "predicted"
    predicted = {**_check(0.6, 0.62, "G1E1"), "bar_modulation_predicted": 0.512,
                 "bars_vs_edge_basis": "predicted reading",
                 "verdict": "agree (predicted reading)"}
    off = {**_check(0.6, 0.62, "G1E2"), "bar_modulation_predicted": 0.43,
           "bars_vs_edge_basis": "predicted reading",
           "verdict": "DISAGREE: bars vs edge (predicted reading) +0.070"}
    old = _check(0.5, 0.52, "G1E3")  # a session analysed before the prediction: no column
    html = render_sfr_section(_tables([predicted, off, old]), [])
    assert ">predicted<" in html and ">0.512<" in html and ">N/A<" in html
    assert "3 bar readings compared, 1 DISAGREE" in html
    assert "2 of 3 rows predicted" in html
