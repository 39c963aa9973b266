"""The ray-trace table: the shipped modelled file, the thesis facts in it, the reader checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchlab.analysis.views.raytrace import (
    DEFAULT_TABLE_PATH,
    RayTraceError,
    modelled_table_csv,
    parse_raytrace_csv,
    read_raytrace_table,
)
from benchlab.analysis.views.synthesis import cylinder_map, viewpoint

GOOD = """# a comment
depth_mm,object_radius_mm,object_z_mm,image_radius_mm
2,15.88,10.0,2.6
2,15.88,12.0,2.4
2,15.88,14.0,2.2
2,15.88,16.0,2.0
3,16.88,10.5,2.6
3,16.88,12.6,2.4
3,16.88,14.7,2.2
3,16.88,16.8,2.0
"""


def test_shipped_table_is_the_documented_model() -> None:
    text = DEFAULT_TABLE_PATH.read_text(encoding="utf-8")
    assert text == modelled_table_csv()  # regenerated, never hand-edited
    assert "MODELLED, NOT A ZEMAX TRACE" in text.splitlines()[0]


def test_shipped_table_holds_the_thesis_facts() -> None:
    table = read_raytrace_table()
    assert list(table.depths_mm) == list(range(2, 12))
    assert np.allclose(table.object_radius_mm, 13.88 + table.depths_mm)
    assert all(z.size == 36 for z in table.object_z_mm)
    rows = [ln.split(",") for ln in DEFAULT_TABLE_PATH.read_text().splitlines()
            if ln and not ln.startswith("#")][1:]
    fields = sorted({float(r[1]) for r in rows})
    assert fields[0] == -60.0 and fields[-1] == -20.0 and len(fields) == 36
    # Eq. 4.1 near the operational field: 17.5 at the radial ROI on the 19.88 mm cylinder
    cyl = cylinder_map(table, 19.88)
    assert cyl.axial_magnification(477.43 * 5.2e-3) == pytest.approx(17.5, rel=2e-3)
    # the image radii cover the simulated annulus (300-545 px)
    lo, hi = table.image_radius_range_mm
    assert lo < 300 * 5.2e-3 and hi > 545 * 5.2e-3
    vp = viewpoint(table)
    assert vp.effective_viewpoint_z_mm == pytest.approx(-6.4, abs=0.005)
    assert vp.svp_spread_um < 20.0  # thesis: within 20 um over the operational field
    assert vp.spread_um.max() > 100.0  # rays outside the design field are not SVP
    assert vp.curved.any() and not vp.curved[(vp.rho_mm > 1.8) & (vp.rho_mm < 2.6)].any()


def test_resampling_reproduces_the_traced_points() -> None:
    table = read_raytrace_table()
    res = table.resampled
    assert np.allclose(np.diff(res.rho_mm), res.rho_mm[1] - res.rho_mm[0])
    for i in (0, 4, 9):
        inside = (table.image_radius_mm[i] >= res.rho_mm[0]) & (
            table.image_radius_mm[i] <= res.rho_mm[-1])
        z = np.interp(table.image_radius_mm[i][inside], res.rho_mm, res.z_mm[i])
        assert np.allclose(z, table.object_z_mm[i][inside], atol=2e-5)


def test_a_good_file_parses_and_hash_ignores_comments() -> None:
    a = parse_raytrace_csv(GOOD, "a.csv")
    b = parse_raytrace_csv(GOOD.replace("# a comment", "# another"), "b.csv")
    assert a.n_depths == 2 and a.sha256 == b.sha256
    assert list(a.image_radius_mm[0]) == [2.0, 2.2, 2.4, 2.6]  # sorted by image radius
    changed = parse_raytrace_csv(GOOD.replace("16.8,2.0", "16.9,2.0"), "c.csv")
    assert changed.sha256 != a.sha256


@pytest.mark.parametrize(
    "text,match",
    [
        (GOOD.replace("object_z_mm", "z"), r"x\.csv:2: missing column\(s\) object_z_mm"),
        (GOOD.replace("12.0,2.4", "twelve,2.4"), r"x\.csv:4: column 'object_z_mm' is not a num"),
        (GOOD.replace("14.0,2.2", "14.0,2.7"), r"x\.csv:5: image_radius_mm is not strictly mono"),
        (GOOD.replace("16.0,2.0", "16.0,2.2"), r"x\.csv:6: image_radius_mm is not strictly mono"),
        (GOOD.replace("3,16.88,16.8,2.0\n", ""), r"x\.csv:7: depth 3 mm has 3 point"),
        (GOOD.replace("3,16.88,14.7", "3,16.9,14.7"), r"x\.csv:9: object radius 16.9 mm differs"),
        (GOOD.replace("2,15.88,12.0", "2,15.88,9.0"),
         r"x\.csv:5: object_z_mm is not strictly monotonic within depth 2 mm \(9 then 14\)"),
        (GOOD.replace("2,15.88,10.0,2.6", "2,15.88,10.0"), r"x\.csv:3: 3 cells"),
        ("# nothing\n", r"x\.csv: no header line"),
        ("depth_mm,object_radius_mm,object_z_mm,image_radius_mm\n", r"header but no rows"),
    ],
)
def test_bad_tables_are_refused_naming_the_line(text: str, match: str) -> None:
    with pytest.raises(RayTraceError, match=match):
        parse_raytrace_csv(text, "x.csv")


def test_unreadable_file_names_it(tmp_path: Path) -> None:
    with pytest.raises(RayTraceError, match="missing.csv: cannot read"):
        read_raytrace_table(tmp_path / "missing.csv")
