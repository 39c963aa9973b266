"""Every number of Tables 4.11-4.16 reproduced from its inputs (thesis chapter 4)."""

from __future__ import annotations

import math

import pytest

from benchlab.analysis import (
    FORWARD_MAGNIFICATION,
    RADIAL_MAGNIFICATION,
    averaged_mtf,
    compare_with_monte_carlo,
    eq29_modulation,
    image_frequency_lp_per_mm,
    image_height_mm,
    image_height_px,
    load_monte_carlo_table,
    nearest_field_point,
    nyquist_lp_per_mm,
    radiometry_table,
    read_table,
    thesis_fixture_path,
    usaf_frequency_lp_per_mm,
)
from benchlab.analysis.thesis_data import optional_float

FORWARD = read_table(thesis_fixture_path("table_4_11_forward"))
RADIAL = read_table(thesis_fixture_path("table_4_12_radial"))
HEIGHTS = read_table(thesis_fixture_path("table_4_13_image_height"))
MEASURED_415 = read_table(thesis_fixture_path("table_4_15_measured"))
RADIOMETRY = read_table(thesis_fixture_path("table_4_16_radiometry"))


def test_fixtures_are_complete() -> None:
    assert len(FORWARD) == 18 and len(RADIAL) == 14 and len(HEIGHTS) == 19
    assert len(MEASURED_415) == 3 and len(RADIOMETRY) == 5
    with pytest.raises(FileNotFoundError, match="table_4_11_forward.csv"):
        thesis_fixture_path("no_such_table")


@pytest.mark.parametrize("row", FORWARD, ids=[r["location"] for r in FORWARD])
def test_table_4_11_modulation_and_frequency(row: dict[str, str]) -> None:
    dark, bright = float(row["dark"]), float(row["bright"])
    assert round(eq29_modulation(dark, bright), 2) == pytest.approx(float(row["modulation"]))
    group, element = int(row["group"]), int(row["element"])
    # The thesis printed the object frequency to 2 decimals and multiplied by 16.3 (Eq. 4.1).
    obj = round(usaf_frequency_lp_per_mm(group, element), 2)
    assert obj == pytest.approx(float(row["object_lp_per_mm"]))
    image = image_frequency_lp_per_mm(obj, FORWARD_MAGNIFICATION)
    assert image == pytest.approx(float(row["image_lp_per_mm"]), abs=5e-4)


def test_table_4_11_nyquist_exclusions() -> None:
    """G2E5, G2E6 and G3E1 lie above 96.15 lp/mm: aliased, excluded (section 4.3.3)."""
    above = {
        r["location"][:4] for r in FORWARD if float(r["image_lp_per_mm"]) > nyquist_lp_per_mm()
    }
    assert above == {"G2E5", "G2E6", "G3E1"}
    assert nyquist_lp_per_mm() == pytest.approx(96.15, abs=0.01)


@pytest.mark.parametrize(
    "row", RADIAL, ids=[f"{r['direction']}{r['object_lp_per_mm']}" for r in RADIAL]
)
def test_table_4_12_modulation_and_frequency(row: dict[str, str]) -> None:
    image = image_frequency_lp_per_mm(float(row["object_lp_per_mm"]), RADIAL_MAGNIFICATION)
    assert image == pytest.approx(float(row["image_lp_per_mm"]))
    dark, bright = optional_float(row["dark"]), optional_float(row["bright"])
    if dark is None or bright is None:
        assert dark is None and bright is None  # N/A: peaks indistinguishable
        assert float(row["modulation"]) == 0.0
    else:
        assert round(eq29_modulation(dark, bright), 2) == pytest.approx(float(row["modulation"]))


def test_table_4_12_only_6_lp_per_mm_is_aliased() -> None:
    above = [float(r["object_lp_per_mm"]) for r in RADIAL if float(r["image_lp_per_mm"]) > 96.15]
    assert above == [6.0, 6.0]


# The text prints the centre as (647, 561.5); the heights of Table 4.13 need (r, c) = (561.5, 647).
THESIS_CENTRE_RC = (561.5, 647.0)


@pytest.mark.parametrize("row", HEIGHTS, ids=[r["location"] for r in HEIGHTS])
def test_table_4_13_image_heights(row: dict[str, str]) -> None:
    point = (float(row["roi_r"]), float(row["roi_c"]))
    px = image_height_px(THESIS_CENTRE_RC, point)
    mm = image_height_mm(THESIS_CENTRE_RC, point)
    if row["location"] == "G1E6T":
        # The thesis's own inconsistency: its centroid (605.5, 542) is 113.85 px from the
        # centre, not the 112.01 printed - reported, not hidden.
        assert px == pytest.approx(113.85, abs=0.01)
        return
    assert px == pytest.approx(float(row["height_px"]), abs=0.006)
    assert round(mm, 2) == pytest.approx(float(row["height_mm"]))


def test_table_4_14_nearest_field_points() -> None:
    radial = nearest_field_point("radial", 2.48)
    assert (radial.field_angle_deg, radial.image_height_mm) == (-30.0, 2.49)
    # Forward tests at 0.38-0.58 mm: the thesis compares with the 0 and 12 deg curves.
    for h in (0.22, 0.38, 0.58, 0.69):
        assert nearest_field_point("forward", h).field_angle_deg in (0.0, 12.0)
    assert nearest_field_point("forward", 0.0).field_angle_deg == 0.0
    assert nearest_field_point("forward", 1.3).field_angle_deg == 25.0
    with pytest.raises(ValueError, match="view"):
        nearest_field_point("sideways", 1.0)
    with pytest.raises(ValueError, match="image height"):
        nearest_field_point("radial", math.nan)


@pytest.mark.parametrize("row", MEASURED_415, ids=[r["freq_lp_per_mm"] for r in MEASURED_415])
def test_table_4_15_averaged_mtf(row: dict[str, str]) -> None:
    avg = averaged_mtf(float(row["sagittal"]), float(row["tangential"]))
    assert avg.average == pytest.approx(float(row["average"]))
    assert avg.sagittal == float(row["sagittal"]) and avg.tangential == float(row["tangential"])


def test_table_4_15_measured_rows_come_from_tables_4_11_and_4_12() -> None:
    g2e2 = {r["direction"]: float(r["modulation"]) for r in FORWARD if r["location"][:4] == "G2E2"}
    assert averaged_mtf(g2e2["S"], g2e2["T"]).average == pytest.approx(0.725)
    rad = {(r["direction"], float(r["image_lp_per_mm"])): r for r in RADIAL}
    r35 = averaged_mtf(float(rad["S", 35.0]["modulation"]), float(rad["T", 35.0]["modulation"]))
    assert r35.average == pytest.approx(0.42)
    # N/A tangential at 52.5 lp/mm counts as 0: (0.60 + 0) / 2.
    r52 = averaged_mtf(float(rad["S", 52.5]["modulation"]), optional_float(rad["T", 52.5]["dark"]))
    assert r52.average == pytest.approx(0.30)
    assert r52.difference == pytest.approx(0.60)  # the gap the average hid


def test_table_4_15_monte_carlo_comparison() -> None:
    table = load_monte_carlo_table(thesis_fixture_path("table_4_15_monte_carlo"))
    assert len(table) == 3
    fwd = compare_with_monte_carlo("forward", 73.187, 0.76, 0.69, table)
    assert fwd.row is not None and fwd.row.freq_lp_per_mm == 70.0
    assert fwd.row.thresholds == {0.9: 0.46, 0.8: 0.49, 0.5: 0.53, 0.2: 0.61, 0.1: 0.62}
    assert fwd.exceeded == (0.9, 0.8, 0.5, 0.2, 0.1)  # 0.725 beats every prediction
    r35 = compare_with_monte_carlo("radial", 35.0, 0.66, 0.18, table)
    assert r35.row is not None and r35.row.freq_lp_per_mm == 30.0
    assert r35.exceeded == ()  # 0.42 < 0.45: below the 90 % line
    assert "below the 90%" in r35.percentile_band
    r52 = compare_with_monte_carlo("radial", 52.5, 0.60, None, table)
    assert r52.row is not None and r52.row.freq_lp_per_mm == 60.0
    assert r52.exceeded == (0.9, 0.8)  # 0.30 > 0.21, 0.27 but < 0.45
    assert r52.averaged.tangential == 0.0 and r52.averaged.sagittal == 0.60
    aliased = compare_with_monte_carlo("radial", 105.0, 0.46, 0.0, table)
    assert aliased.excluded and aliased.row is None


def test_table_4_16_radiometry() -> None:
    rows = radiometry_table(
        [float(r["field_position_mm"]) for r in RADIOMETRY],
        [float(r["simulated_mw_per_mm2"]) for r in RADIOMETRY],
        [float(r["measured_mean_gray"]) for r in RADIOMETRY],
    )
    for got, want in zip(rows, RADIOMETRY, strict=True):
        assert got.field_position_mm == float(want["field_position_mm"])
        assert round(got.simulated_normalised, 2) == pytest.approx(
            float(want["simulated_normalised"])
        )
        assert round(got.measured_normalised, 2) == pytest.approx(
            float(want["measured_normalised"])
        )
    assert rows[1].measured_normalised == 1.0 and rows[0].simulated_normalised == 1.0
